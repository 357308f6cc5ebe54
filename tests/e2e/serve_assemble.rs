//! `assemble` in the server: particles pushed into a pattern through the control loop, each move
//! a push judged by the scan after it, the rest planned again after each; `plan_only`, `stop`, a
//! late joiner's `state`, the lease holder leaving, bad inputs, and the record. On the quick test
//! scene with particles 1 and 2 side by side in its full frame (16 µm about (40, 32) µm, 64
//! pixels), two sites 2 µm from them.

use std::time::Instant;

use serde_json::{Value, json};

use crate::util::{
    Server, Ws, http_get, is, is_reply, ok, operator, reply, runtime, send, start_scene, until, welcomed,
};

/// The quick scene with particle 2 moved beside particle 1 (at (40, 30) µm) into the full frame,
/// which gets 64 pixels (250 nm: four across a particle).
fn assembly_server(tag: &str) -> Server {
    start_scene(
        tag,
        &[
            ("x_um = 55.0\ny_um = 62.0", "x_um = 44.0\ny_um = 34.0"),
            ("pixels = 32", "pixels = 64"),
        ],
    )
}

/// Two sites 2 µm from particles 1 and 2.
fn two_sites() -> Value {
    json!([{"x_um": 42.0, "y_um": 30.0}, {"x_um": 44.0, "y_um": 32.0}])
}

/// Every message of the assembly from now until its `assembly_done` (within `secs`), in order.
async fn until_done(ws: &mut Ws, secs: f64) -> Vec<Value> {
    let mut seen = Vec::new();
    loop {
        let m = until(ws, secs, |m| {
            m["type"].as_str().is_some_and(|t| t.starts_with("assembly_")) || is(m, "push_started") || is(m, "run_done")
        })
        .await;
        let done = is(&m, "assembly_done");
        seen.push(m);
        if done {
            return seen;
        }
    }
}

fn of_type<'a>(seen: &'a [Value], ty: &str) -> Vec<&'a Value> {
    seen.iter().filter(|m| is(m, ty)).collect()
}

/// A record's JSON.
fn record(addr: &str, name: &str) -> Value {
    let (status, body) = http_get(addr, &format!("/api/records/{name}"));
    assert_eq!(status, 200, "{name}");
    serde_json::from_slice(&body).unwrap()
}

#[test]
fn an_assembly_fills_two_sites_and_writes_its_record() {
    let srv = assembly_server("assemble-fill");
    let t0 = Instant::now();
    runtime().block_on(async {
        let mut op = operator(&srv.addr, "tip").await;
        ok(&mut op, json!({"type": "assemble", "id": 3, "sites": two_sites()})).await;
        let seen = until_done(&mut op, 120.0).await;
        let done = seen.last().unwrap();
        assert_eq!(done["outcome"], "filled", "{seen:#?}");
        let planned = of_type(&seen, "assembly_planned");
        assert_eq!(planned.len(), 1, "{seen:#?}");
        assert_eq!(planned[0]["plan"]["sites"][0]["state"], "planned");
        // The full frame it was planned on, as a scan record the page opens.
        let frame = planned[0]["frame"].as_str().expect("the first frame's record");
        assert!(frame.starts_with("scan-") && frame.ends_with(".gsf"), "{frame}");
        assert_eq!(planned[0]["plan"]["moves"].as_array().unwrap().len(), 2);
        let started = of_type(&seen, "assembly_move_started");
        let ended = of_type(&seen, "assembly_move_ended");
        assert!(started.len() >= 2 && started.len() == ended.len(), "{seen:#?}");
        assert_eq!(
            (started[0]["number"].as_u64(), started[0]["of"].as_u64()),
            (Some(1), Some(2))
        );
        assert_eq!(of_type(&seen, "assembly_replanned").len(), ended.len());
        let mut filled: Vec<u64> = of_type(&seen, "assembly_site_filled")
            .iter()
            .map(|m| m["site"].as_u64().unwrap())
            .collect();
        filled.sort_unstable();
        assert_eq!(filled, [0, 1]);
        // Each move is a push as the operator's: its push_started and its run_done.
        assert!(of_type(&seen, "push_started").len() >= 2);
        assert_eq!(of_type(&seen, "run_done").len(), ended.len());
        let summary = &done["summary"];
        for s in summary["sites"].as_array().unwrap() {
            assert_eq!(s["status"], "filled", "{summary:#}");
            assert!(
                s["error"].as_f64().unwrap() <= s["tolerance"].as_f64().unwrap() + 1e-9,
                "truly within: {s}"
            );
        }
        let name = done["record"].as_str().expect("a record");
        let rec = record(&srv.addr, name);
        assert_eq!(rec["schema"], "assembly-record");
        assert_eq!(rec["summary"], *summary);
        assert_eq!(rec["first_plan"], planned[0]["plan"]);
        let last = rec["final_frame"]["record"].as_str().expect("the final frame's record");
        assert!(last.ends_with(".gsf"), "{rec:#}");
        assert_eq!(http_get(&srv.addr, &format!("/api/records/{last}")).0, 200);
        assert!(!rec["runs"].as_array().unwrap().is_empty());
        // The instrument is free again: a plain scan is taken.
        ok(&mut op, json!({"type": "scan", "id": 4, "size_um": 4.0, "pixels": 8})).await;
    });
    eprintln!(
        "assembly of two sites: {:.1} s of wall time",
        t0.elapsed().as_secs_f64()
    );
}

#[test]
fn plan_only_sends_the_plan_and_moves_nothing() {
    let srv = assembly_server("assemble-plan");
    runtime().block_on(async {
        let mut op = operator(&srv.addr, "tip").await;
        let (_, before) = welcomed(&srv.addr, None).await;
        let _ = before;
        ok(
            &mut op,
            json!({"type": "assemble", "id": 3, "sites": two_sites(), "plan_only": true}),
        )
        .await;
        let seen = until_done(&mut op, 30.0).await;
        let done = seen.last().unwrap();
        assert_eq!(done["outcome"], "planned", "{seen:#?}");
        assert!(done["record"].is_null() && done["summary"].is_null(), "{done}");
        let planned = of_type(&seen, "assembly_planned");
        assert_eq!(planned.len(), 1);
        assert_eq!(planned[0]["plan_only"], true);
        let moves = planned[0]["plan"]["moves"].as_array().unwrap();
        assert_eq!(moves.len(), 2, "{:#}", planned[0]);
        for m in moves {
            assert_eq!(m["purpose"], "fill");
            assert!(m["path"].as_array().unwrap().len() >= 2, "{m}");
        }
        assert!(of_type(&seen, "push_started").is_empty() && of_type(&seen, "assembly_move_started").is_empty());
        // Nothing moved: the particles are where the scene put them.
        let (_, st) = http_get(&srv.addr, "/api/status");
        let st: Value = serde_json::from_slice(&st).unwrap();
        let p1 = st["particles"]
            .as_array()
            .unwrap()
            .iter()
            .find(|p| p["id"] == 1)
            .unwrap()
            .clone();
        assert!((p1["x"].as_f64().unwrap() - 40e-6).abs() < 1e-12, "{p1}");
        // And the instrument is free.
        send(
            &mut op,
            json!({"type": "assemble", "id": 4, "sites": two_sites(), "plan_only": true}),
        )
        .await;
        let r = until(&mut op, 10.0, |m| is_reply(m, 4)).await;
        assert_eq!(r["type"], "ok", "{r}");
        let _ = reply;
    });
}

/// Starts an assembly of the two sites and waits until its first push runs (telemetry's phase
/// is the strategy's `push`).
async fn assembling(op: &mut Ws) {
    ok(op, json!({"type": "assemble", "id": 3, "sites": two_sites()})).await;
    until(op, 60.0, |m| is(m, "telemetry") && m["phase"] == "push").await;
}

/// The trace of a push record: the tip's z at its first and last rows, and the last row's phase.
fn trace_ends(addr: &str, push_json: &str) -> (f64, f64, String) {
    let summary = record(addr, push_json);
    let (status, csv) = http_get(addr, &format!("/api/records/{}", summary["trace"].as_str().unwrap()));
    assert_eq!(status, 200);
    let csv = String::from_utf8(csv).unwrap();
    let rows: Vec<&str> = csv.lines().skip(1).collect();
    let z = |line: &str| line.split(',').nth(5).unwrap().parse::<f64>().unwrap();
    let phase = rows.last().unwrap().split(',').nth(2).unwrap().to_string();
    (z(rows[0]), z(rows.last().unwrap()), phase)
}

#[test]
fn stop_mid_assembly_retracts_the_tip_and_completes_the_record() {
    let srv = assembly_server("assemble-stop");
    runtime().block_on(async {
        let mut op = operator(&srv.addr, "tip").await;
        assembling(&mut op).await;
        ok(&mut op, json!({"type": "stop", "id": 5})).await;
        // A second stop changes nothing and is not refused.
        ok(&mut op, json!({"type": "stop", "id": 6})).await;
        let seen = until_done(&mut op, 30.0).await;
        let done = seen.last().unwrap();
        assert_eq!(done["outcome"], "stopped", "{done}");
        assert_eq!(done["reason"], "stopped: stop requested by the operator");
        let pushed = of_type(&seen, "run_done");
        assert_eq!(pushed.len(), 1, "{seen:#?}");
        assert_eq!(pushed[0]["outcome"], "stopped", "{}", pushed[0]);
        // The record is complete: the summary, the final frame, the stopped push.
        let rec = record(&srv.addr, done["record"].as_str().expect("a record"));
        assert_eq!(rec["summary"]["outcome"], "stopped");
        assert_eq!(rec["summary"]["sites"].as_array().unwrap().len(), 2);
        assert!(rec["final_frame"]["record"].is_string(), "{rec:#}");
        let last_push = rec["push_records"]
            .as_array()
            .unwrap()
            .last()
            .unwrap()
            .as_str()
            .unwrap();
        // The tip ended retracted: the push's last row is back at the height it started from.
        let (start_z, end_z, phase) = trace_ends(&srv.addr, last_push);
        assert_eq!(phase, "done");
        assert!((end_z - start_z).abs() < 20e-9, "start z {start_z:e}, end z {end_z:e}");
        let m = until(&mut op, 5.0, |m| is(m, "telemetry")).await;
        assert_eq!(m["phase"], "idle", "{m}");
    });
}

/// A server killed with SIGKILL after an assembly's first move leaves its record, `running`,
/// with the move made and the first frame's record.
#[test]
fn a_killed_server_leaves_the_assembly_record_running() {
    let mut srv = assembly_server("assemble-kill");
    let records = srv.dir.join("records");
    runtime().block_on(async {
        let mut op = operator(&srv.addr, "tip").await;
        ok(&mut op, json!({"type": "assemble", "id": 3, "sites": two_sites()})).await;
        until(&mut op, 120.0, |m| is(m, "assembly_replanned")).await;
    });
    srv.child.kill().unwrap();
    srv.child.wait().unwrap();
    let name = std::fs::read_dir(&records)
        .unwrap()
        .filter_map(|e| e.ok().map(|e| e.file_name().to_string_lossy().into_owned()))
        .find(|n| n.starts_with("assembly-") && n.ends_with(".json"))
        .expect("an assembly record");
    let rec: Value = serde_json::from_slice(&std::fs::read(records.join(&name)).unwrap()).unwrap();
    assert_eq!(rec["summary"]["outcome"], "running", "{rec:#}");
    assert!(!rec["summary"]["moves"].as_array().unwrap().is_empty(), "{rec:#}");
    assert!(rec["first_frame"]["record"].is_string(), "{rec:#}");
    assert!(!rec["push_records"].as_array().unwrap().is_empty(), "{rec:#}");
}

#[test]
fn a_late_joiner_is_told_the_running_assembly() {
    let srv = assembly_server("assemble-late");
    runtime().block_on(async {
        let mut op = operator(&srv.addr, "tip").await;
        assembling(&mut op).await;
        let (mut late, _) = welcomed(&srv.addr, None).await;
        let state = until(&mut late, 5.0, |m| is(m, "state")).await;
        let a = &state["assembly"];
        assert_eq!(a["phase"], "moving", "{state:#}");
        assert_eq!(a["moving"][0], 1, "{a:#}");
        assert_eq!(a["sites"].as_array().unwrap().len(), 2);
        assert_eq!(a["plan"]["moves"].as_array().unwrap().len(), 2, "{a:#}");
        assert_eq!(a["plan"]["map"].as_array().unwrap().len(), 2, "{a:#}");
        assert!(state["push"].is_object(), "the move's push: {state:#}");
        assert_eq!(state["phase"], "push");
        ok(&mut op, json!({"type": "stop", "id": 5})).await;
        let done = until(&mut late, 30.0, |m| is(m, "assembly_done")).await;
        assert_eq!(done["assembly"], a["assembly"]);
        // Once it has ended, a joiner is told none.
        let (mut later, _) = welcomed(&srv.addr, None).await;
        let state = until(&mut later, 5.0, |m| is(m, "state")).await;
        assert!(state["assembly"].is_null(), "{state:#}");
    });
}

#[test]
fn the_lease_holder_leaving_stops_its_assembly() {
    let srv = assembly_server("assemble-leave");
    runtime().block_on(async {
        let (mut viewer, _) = welcomed(&srv.addr, None).await;
        let mut op = operator(&srv.addr, "tip").await;
        assembling(&mut op).await;
        drop(op);
        let lease = until(&mut viewer, 10.0, |m| is(m, "lease") && m["holder"].is_null()).await;
        assert!(
            lease["reason"].as_str().unwrap().ends_with("its assembly was stopped"),
            "{lease}"
        );
        let done = until(&mut viewer, 30.0, |m| is(m, "assembly_done")).await;
        assert_eq!(done["outcome"], "stopped", "{done}");
        assert_eq!(done["reason"], "stopped: the lease holder disconnected");
        assert!(done["record"].is_string(), "{done}");
    });
}

/// Sends `assemble` with the fields of `cmd` as command `id`, which must be refused: the code and
/// the message.
async fn refused(ws: &mut Ws, id: u32, mut cmd: Value) -> (String, String) {
    cmd["type"] = "assemble".into();
    cmd["id"] = id.into();
    send(ws, cmd).await;
    let r = reply(ws, id).await;
    assert_eq!(r["type"], "error", "{r}");
    (
        r["code"].as_str().unwrap().to_string(),
        r["message"].as_str().unwrap().to_string(),
    )
}

#[test]
fn bad_assemble_commands_get_clear_errors_and_the_server_lives_on() {
    let srv = assembly_server("assemble-bad");
    runtime().block_on(async {
        let (mut viewer, _) = welcomed(&srv.addr, None).await;
        let (mut other, _) = welcomed(&srv.addr, Some(crate::util::TOKEN)).await;
        let mut op = operator(&srv.addr, "tip").await;
        let (code, _) = refused(&mut viewer, 10, json!({"sites": two_sites()})).await;
        assert_eq!(code, "forbidden");
        let (code, msg) = refused(&mut other, 11, json!({"sites": two_sites()})).await;
        assert_eq!(code, "no_lease", "{msg}");
        let (code, msg) = refused(
            &mut op,
            12,
            json!({"sites": two_sites(), "generator": "ring:n=3,radius_um=3"}),
        )
        .await;
        assert_eq!(
            (code.as_str(), msg.as_str()),
            ("invalid", "assemble takes either sites or generator, not both")
        );
        let (code, msg) = refused(&mut op, 13, json!({})).await;
        assert_eq!(code, "invalid", "{msg}");
        let (code, msg) = refused(&mut op, 14, json!({"sites": [{"x_um": 42.0, "y_um": 130.0}]})).await;
        assert_eq!(
            (code.as_str(), msg.as_str()),
            (
                "out_of_range",
                "sites[0].y_um = 130 is out of range; allowed: [0, 100] µm"
            )
        );
        let (code, msg) = refused(&mut op, 15, json!({"sites": []})).await;
        assert_eq!(
            (code.as_str(), msg.as_str()),
            ("out_of_range", "sites has 0 entries; allowed: 1 to 400")
        );
        let (code, msg) = refused(&mut op, 16, json!({"generator": "hexagon:n=6"})).await;
        assert_eq!(code, "invalid");
        assert!(
            msg.contains("unknown shape \\\"hexagon\\\"") || msg.contains("allowed: line, grid, ring, text"),
            "{msg}"
        );
        let (code, msg) = refused(&mut op, 17, json!({"generator": "ring:n=2,radius_um=3"})).await;
        assert_eq!(code, "invalid");
        assert!(msg.contains("n = 2 is out of range"), "{msg}");
        let (code, msg) = refused(
            &mut op,
            18,
            json!({"sites": [{"x_um": 42.0, "y_um": 30.0, "tolerance_nm": 0.1}]}),
        )
        .await;
        assert_eq!(
            (code.as_str(), msg.as_str()),
            (
                "out_of_range",
                "sites[0].tolerance_nm = 0.1 is out of range; allowed: [1, 100000] nm"
            )
        );
        let (code, msg) = refused(
            &mut op,
            19,
            json!({"sites": two_sites(), "at_x_um": 3.0, "at_y_um": 3.0}),
        )
        .await;
        assert_eq!(code, "invalid", "{msg}");
        let (code, msg) = refused(
            &mut op,
            20,
            json!({"generator": "line:n=3,spacing_um=3", "at_x_um": 50.0}),
        )
        .await;
        assert_eq!(
            (code.as_str(), msg.as_str()),
            ("invalid", "at_x_um and at_y_um go together")
        );
        let (code, msg) = refused(&mut op, 21, json!({"generator": "x".repeat(201)})).await;
        assert_eq!(
            (code.as_str(), msg.as_str()),
            ("out_of_range", "generator is 201 characters long; allowed: at most 200")
        );
        // A pattern of the page's largest size with its long decimals fits in a message: the
        // count is what is refused, not the message's size.
        let many: Vec<Value> = (0..401)
            .map(|k| json!({"x_um": 10.123456 + f64::from(k % 20) * 4.0, "y_um": 10.654321 + f64::from(k / 20) * 4.0, "tolerance_nm": 25.0}))
            .collect();
        let (code, msg) = refused(&mut op, 24, json!({"sites": many})).await;
        assert_eq!(
            (code.as_str(), msg.as_str()),
            ("out_of_range", "sites has 401 entries; allowed: 1 to 400")
        );
        // A pattern the stage cannot hold is refused before anything moves, saying why.
        ok(
            &mut op,
            json!({"type": "assemble", "id": 22, "sites": [{"x_um": 0.0, "y_um": 0.0}]}),
        )
        .await;
        let done = until(&mut op, 30.0, |m| is(m, "assembly_done")).await;
        assert_eq!(done["outcome"], "refused", "{done}");
        assert!(!done["reason"].as_str().unwrap().is_empty(), "{done}");
        // The server lives on.
        ok(&mut op, json!({"type": "ping", "id": 23})).await;
    });
}
