//! `assemble` in the server: particles pushed into a pattern through the control loop, each move
//! a push judged by the scan after it, the rest planned again after each; `plan_only`, `stop`, a
//! late joiner's `state`, the lease holder leaving, bad inputs, and the record. On the quick test
//! scene with particles 1 and 2 side by side in its full frame (16 µm about (40, 32) µm, 64
//! pixels), two sites 2 µm from them.

use std::time::Instant;

use serde_json::{Value, json};

use crate::util::{Server, Ws, http_get, is, is_reply, ok, operator, reply, runtime, send, start_scene, until, welcomed};

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
        assert_eq!(planned[0]["plan"]["moves"].as_array().unwrap().len(), 2);
        let started = of_type(&seen, "assembly_move_started");
        let ended = of_type(&seen, "assembly_move_ended");
        assert!(started.len() >= 2 && started.len() == ended.len(), "{seen:#?}");
        assert_eq!((started[0]["number"].as_u64(), started[0]["of"].as_u64()), (Some(1), Some(2)));
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
            assert!(s["error"].as_f64().unwrap() <= s["tolerance"].as_f64().unwrap() + 1e-9, "truly within: {s}");
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
    eprintln!("assembly of two sites: {:.1} s of wall time", t0.elapsed().as_secs_f64());
}

#[test]
fn plan_only_sends_the_plan_and_moves_nothing() {
    let srv = assembly_server("assemble-plan");
    runtime().block_on(async {
        let mut op = operator(&srv.addr, "tip").await;
        let (_, before) = welcomed(&srv.addr, None).await;
        let _ = before;
        ok(&mut op, json!({"type": "assemble", "id": 3, "sites": two_sites(), "plan_only": true})).await;
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
        let p1 = st["particles"].as_array().unwrap().iter().find(|p| p["id"] == 1).unwrap().clone();
        assert!((p1["x"].as_f64().unwrap() - 40e-6).abs() < 1e-12, "{p1}");
        // And the instrument is free.
        send(&mut op, json!({"type": "assemble", "id": 4, "sites": two_sites(), "plan_only": true})).await;
        let r = until(&mut op, 10.0, |m| is_reply(m, 4)).await;
        assert_eq!(r["type"], "ok", "{r}");
        let _ = reply;
    });
}
