//! The audit trail. Every command that changes the instrument, with who sent it, from where, and
//! what became of it, is in `audit/audit.jsonl` of the data directory, and still there, whole,
//! after the server is killed with SIGKILL; each record names who made it. A flood of refused
//! commands does not keep the operator's off the disk, and a push that ends before the loop
//! runs it has its end in the log too.

use std::time::{Duration, Instant};

use futures_util::StreamExt;
use serde_json::{Value, json};

use crate::serve_access::{named_server, try_ws};
use crate::util::{TOKEN, connect, is, ok, reply, runtime, send, start, until, welcomed};

/// The audit log's lines (each must be whole JSON).
fn audit_lines(records: &std::path::Path) -> Vec<Value> {
    let text = std::fs::read_to_string(records.join("audit/audit.jsonl")).unwrap_or_default();
    assert!(text.is_empty() || text.ends_with('\n'), "a partial last line: {text:?}");
    text.lines()
        .map(|l| serde_json::from_str(l).unwrap_or_else(|e| panic!("not a whole JSON line ({e}): {l}")))
        .collect()
}

/// Alice (operator) takes the lease, scans, pushes, stops, asks for haptic engagement (refused:
/// no haptic link) and gives the lease back; Bob (viewer) tries to take it. The log has each of
/// these in order with the person, the address, the arguments and the outcome (refusals with
/// their code), and the push's end under Alice's name; the push and scan records name Alice.
/// Then the server is killed with SIGKILL: every line is still there, whole.
#[test]
fn every_command_is_audited_with_its_person_and_survives_sigkill() {
    let (mut srv, tokens) = named_server(
        "audit",
        &[("alice", "operator"), ("bob", "viewer")],
        &["--scan-line-hz", "400", "--allow-cpu-halt"],
    );
    let records = srv.dir.join("records");
    runtime().block_on(async {
        let (mut a, _) = try_ws(&srv.addr, Some(&tokens[0]), &[]).await.unwrap();
        let (mut b, _) = try_ws(&srv.addr, Some(&tokens[1]), &[]).await.unwrap();
        send(&mut a, json!({"type": "subscribe", "id": 1, "streams": ["scan"]})).await;
        ok(&mut a, json!({"type": "take_lease", "id": 2})).await;
        ok(&mut a, json!({"type": "scan", "id": 3, "pixels": 16})).await;
        let scan = until(&mut a, 30.0, |m| is(m, "scan_done")).await;
        let gsf = scan["record"].as_str().expect("a scan record").to_string();
        ok(
            &mut a,
            json!({"type": "push", "id": 4, "particle": 1, "distance_um": 1.0, "direction_deg": 0.0}),
        )
        .await;
        let done = until(&mut a, 60.0, |m| is(m, "run_done")).await;
        let push = done["record"].as_str().expect("a push record").to_string();
        ok(&mut a, json!({"type": "stop", "id": 5})).await;
        send(&mut a, json!({"type": "haptic", "id": 6, "action": "engage"})).await;
        let engage = reply(&mut a, 6).await;
        assert_eq!(engage["type"], "error", "no haptic link: {engage}");
        ok(&mut a, json!({"type": "release_lease", "id": 7})).await;
        send(&mut b, json!({"type": "take_lease", "id": 8})).await;
        assert_eq!(reply(&mut b, 8).await["code"], "forbidden");

        let summary: Value = serde_json::from_slice(&std::fs::read(records.join(&push)).unwrap()).unwrap();
        assert_eq!(
            summary["person"], "alice",
            "the push record names its person: {summary}"
        );
        let scan_json = records.join(gsf.replace(".gsf", ".json"));
        let summary: Value = serde_json::from_slice(&std::fs::read(scan_json).unwrap()).unwrap();
        assert_eq!(
            summary["person"], "alice",
            "the scan record names its person: {summary}"
        );
        let expected = engage["code"].clone();

        // The writer appends in the background: wait for the 8 lines (not timed: a bound).
        let deadline = Instant::now() + Duration::from_secs(20);
        while audit_lines(&records).len() < 8 {
            assert!(Instant::now() < deadline, "the audit log: {:?}", audit_lines(&records));
            tokio::time::sleep(Duration::from_millis(20)).await;
        }
        srv.child.kill().unwrap();
        srv.child.wait().unwrap();
        let lines = audit_lines(&records);
        let row = |l: &Value| {
            (
                l["person"].as_str().unwrap_or("").to_string(),
                l["command"].as_str().unwrap_or("").to_string(),
                l["outcome"].as_str().unwrap_or("").to_string(),
            )
        };
        let rows: Vec<(String, String, String)> = lines.iter().map(row).collect();
        let want = [
            ("alice", "take_lease", "ok"),
            ("alice", "scan", "ok"),
            ("alice", "push", "ok"),
            ("alice", "run_done", "ok"),
            ("alice", "stop", "ok"),
            ("alice", "haptic", "refused"),
            ("alice", "release_lease", "ok"),
            ("bob", "take_lease", "refused"),
        ];
        let got: Vec<(&str, &str, &str)> = rows
            .iter()
            .map(|(p, c, o)| (p.as_str(), c.as_str(), o.as_str()))
            .collect();
        assert_eq!(&got[..want.len()], &want[..], "{lines:#?}");
        let push_line = &lines[2];
        assert_eq!(push_line["address"], "127.0.0.1");
        assert_eq!(push_line["role"], "operator");
        assert_eq!(push_line["args"]["particle"], 1, "{push_line}");
        assert_eq!(push_line["args"]["distance_um"], 1.0, "{push_line}");
        assert!(push_line["time"].as_str().unwrap().ends_with('Z'), "{push_line}");
        assert_eq!(lines[3]["args"]["record"], push, "{}", lines[3]);
        assert_eq!(lines[5]["code"], expected, "{}", lines[5]);
        assert_eq!(lines[7]["code"], "forbidden");
        assert_eq!(lines[7]["role"], "viewer");
    });
}

/// A viewer's refused commands (each one logged) do not queue ahead of the operator's: refusals
/// are capped in flight and lines go in group commits, so the operator's lines are on disk
/// within 5 s of their `ok` (milliseconds, unloaded), and whole after a kill -9. (From an
/// unbounded queue, a line and a sync at a time, 30,000 lines from 60 viewer sockets of one
/// address would take ~40 s to drain, and a kill -9 meanwhile would lose the operator's.)
#[test]
fn an_operators_accepted_command_is_audited_despite_a_viewer_flood() {
    let mut srv = start("audit-flood", &["--max-rate", "10000"]);
    let addr = srv.addr.clone();
    runtime().block_on(async move {
        let (mut op, _) = welcomed(&addr, Some(TOKEN)).await;
        let mut viewers = Vec::new();
        for _ in 0..40 {
            viewers.push(connect(&addr, None).await);
        }
        // Each viewer asks for the lease 300 times (refused, and logged each time), and reads
        // its replies.
        let floods = viewers.into_iter().map(|mut v| async move {
            for _ in 0..300 {
                send(&mut v, json!({"type": "take_lease"})).await;
            }
            let mut refused = 0;
            while refused < 300 {
                match tokio::time::timeout(Duration::from_secs(30), v.next()).await {
                    Ok(Some(Ok(m))) if m.to_text().is_ok_and(|t| t.contains("forbidden")) => refused += 1,
                    Ok(Some(Ok(_))) => {}
                    _ => break,
                }
            }
            v
        });
        let _viewers = futures_util::future::join_all(floods).await;
        ok(&mut op, json!({"type": "take_lease", "id": 41})).await;
        ok(&mut op, json!({"type": "stop", "id": 42})).await;
    });
    // The operator's take_lease and stop, answered ok.
    let ours = |l: &str| {
        l.contains("\"person\":\"operator\"")
            && l.contains("\"outcome\":\"ok\"")
            && (l.contains("\"command\":\"take_lease\"") || l.contains("\"command\":\"stop\""))
    };
    // Answered: once both lines are in the file (at most 5 s), the server dies.
    let path = srv.dir.join("records/audit/audit.jsonl");
    let deadline = Instant::now() + Duration::from_secs(5);
    while Instant::now() < deadline
        && std::fs::read_to_string(&path)
            .unwrap_or_default()
            .lines()
            .filter(|l| ours(l))
            .count()
            < 2
    {
        std::thread::sleep(Duration::from_millis(20));
    }
    srv.child.kill().unwrap();
    let _ = srv.child.wait();
    let log = std::fs::read_to_string(srv.dir.join("records/audit/audit.jsonl")).unwrap();
    let lines = log.lines().count();
    let n = log.lines().filter(|l| ours(l)).count();
    assert_eq!(
        n, 2,
        "the operator's take_lease and stop were answered ok; the log holds {n} of them \
         ({lines} lines, 12,000 viewer refusals were queued first)"
    );
    // Every line whole (the kill came after the writes).
    assert!(
        log.lines()
            .all(|l| serde_json::from_str::<serde_json::Value>(l).is_ok())
    );
}

/// A push accepted (`ok`, logged) and stopped while it is still being located and planned ends
/// in a `run_done` to everyone ("stopped before the push began") and in the audit log, which
/// says how it ended as well as that it was accepted. (So do the other ends before the loop
/// runs it: a plan refused, already there, a full queue: `push/launch.rs` `run_done_failed` and
/// `push/judge.rs` `already_there`.)
#[test]
fn a_push_stopped_before_it_began_has_its_end_in_the_audit_log() {
    let srv = start("audit-stopped-early", &[]);
    let addr = srv.addr.clone();
    let done = runtime().block_on(async move {
        let (mut op, _) = welcomed(&addr, Some(TOKEN)).await;
        ok(&mut op, json!({"type": "take_lease", "id": 1})).await;
        ok(
            &mut op,
            json!({"type": "push", "id": 2, "particle": 1, "distance_um": 1.0, "direction_deg": 0.0}),
        )
        .await;
        ok(&mut op, json!({"type": "stop", "id": 3})).await;
        until(&mut op, 30.0, |m| is(m, "run_done")).await
    });
    let path = srv.dir.join("records/audit/audit.jsonl");
    let deadline = Instant::now() + Duration::from_secs(5);
    loop {
        let log = std::fs::read_to_string(&path).unwrap_or_default();
        if log.lines().any(|l| l.contains("\"command\":\"run_done\"")) {
            break;
        }
        assert!(
            Instant::now() < deadline,
            "the push ended ({done}) and the audit log has no run_done:\n{log}"
        );
        std::thread::sleep(Duration::from_millis(100));
    }
}

/// Alice pushes and her connection closes at once, while the push is still being located and
/// planned: the push is stopped, and its `run_done` in the audit log still names Alice (not the
/// number of a session that is gone).
#[test]
fn a_push_whose_holder_left_ends_in_the_log_under_her_name() {
    let (srv, tokens) = named_server("audit-holder-left", &[("alice", "operator")], &[]);
    let records = srv.dir.join("records");
    runtime().block_on(async {
        let (mut a, _) = try_ws(&srv.addr, Some(&tokens[0]), &[]).await.unwrap();
        ok(&mut a, json!({"type": "take_lease", "id": 1})).await;
        ok(
            &mut a,
            json!({"type": "push", "id": 2, "particle": 1, "distance_um": 1.0, "direction_deg": 0.0}),
        )
        .await;
        drop(a);
    });
    let deadline = Instant::now() + Duration::from_secs(60);
    let done = loop {
        if let Some(d) = audit_lines(&records).into_iter().find(|l| l["command"] == "run_done") {
            break d;
        }
        assert!(Instant::now() < deadline, "no run_done in the audit log within 60 s");
        std::thread::sleep(Duration::from_millis(100));
    };
    assert_eq!(done["person"], "alice", "{done}");
}

/// The refusals of one client in the log: the lines of `person` from `address` for `command`,
/// refused one by one, and those a summary counts.
fn refusals_accounted(lines: &[Value], command: &str) -> (usize, u64, Vec<Value>) {
    let ours: Vec<&Value> = lines
        .iter()
        .filter(|l| l["command"] == command && l["person"] == "anonymous")
        .collect();
    let single = ours.iter().filter(|l| l["outcome"] == "refused").count();
    let summaries: Vec<Value> = ours
        .iter()
        .filter(|l| l["outcome"] == "refused_summary")
        .map(|l| (*l).clone())
        .collect();
    let summed = summaries.iter().map(|s| s["args"]["refused"].as_u64().unwrap()).sum();
    (single, summed, summaries)
}

/// 30 anonymous viewer connections from one address, each sending 45 `take_lease` a second for
/// 3 s (4,050 refusals; `NANOPUSH_FLOOD_S` sets the seconds): the log grows by at most 20 lines,
/// the first refusals one by one and then a summary ("… 4,040 refused take_lease in 3 s …"), and
/// the lines and the summaries account for every refusal (one line each, 1.3 GB an hour, before).
#[test]
fn a_refusal_flood_is_logged_as_a_few_lines_and_a_summary() {
    let secs: u64 = std::env::var("NANOPUSH_FLOOD_S")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(3);
    let srv = start("audit-refusal-flood", &["--max-rate", "10000"]);
    let records = srv.dir.join("records");
    let per_viewer = 45 * secs as usize;
    let sent = 30 * per_viewer as u64;
    let addr = srv.addr.clone();
    runtime().block_on(async move {
        let mut viewers = Vec::new();
        for _ in 0..30 {
            viewers.push(connect(&addr, None).await);
        }
        let t0 = tokio::time::Instant::now();
        let floods = viewers.into_iter().map(|ws| async move {
            let (mut tx, mut rx) = ws.split();
            let reader = async move {
                let mut refused = 0;
                while refused < per_viewer {
                    match tokio::time::timeout(Duration::from_secs(30), rx.next()).await {
                        Ok(Some(Ok(m))) if m.to_text().is_ok_and(|t| t.contains("forbidden")) => refused += 1,
                        Ok(Some(Ok(_))) => {}
                        _ => break,
                    }
                }
                refused
            };
            let writer = async move {
                for k in 0..per_viewer {
                    tokio::time::sleep_until(t0 + Duration::from_secs(1) * k as u32 / 45).await;
                    let m = json!({"type": "take_lease"}).to_string();
                    futures_util::SinkExt::send(&mut tx, tokio_tungstenite::tungstenite::Message::Text(m.into()))
                        .await
                        .unwrap();
                }
                tx
            };
            let (refused, tx) = tokio::join!(reader, writer);
            drop(tx);
            refused
        });
        let refused: usize = futures_util::future::join_all(floods).await.into_iter().sum();
        assert_eq!(refused as u64, sent, "every take_lease was refused");
    });
    // The summaries come once the client has been quiet for 2 s.
    let deadline = Instant::now() + Duration::from_secs(10);
    let (lines, single, summed, summaries) = loop {
        let lines = audit_lines(&records);
        let (single, summed, summaries) = refusals_accounted(&lines, "take_lease");
        if single as u64 + summed >= sent || Instant::now() > deadline {
            break (lines, single, summed, summaries);
        }
        std::thread::sleep(Duration::from_millis(100));
    };
    let bytes = std::fs::metadata(records.join("audit/audit.jsonl")).map_or(0, |m| m.len());
    eprintln!(
        "{sent} refusals in {secs} s: {} lines, {bytes} bytes ({:.1} KB/s); {single} logged one by one, {summed} in {} summaries",
        lines.len(),
        bytes as f64 / 1e3 / secs as f64,
        summaries.len()
    );
    assert!(
        lines.len() <= 20 + 2 * secs as usize / 60,
        "the flood of {sent} refusals took {} lines ({bytes} bytes) of the audit log",
        lines.len()
    );
    assert_eq!(
        single as u64 + summed,
        sent,
        "each refusal is a line or counted in a summary"
    );
    let said = summaries[0]["message"].as_str().unwrap();
    assert!(
        said.starts_with("viewer anonymous from 127.0.0.1: ") && said.contains(" refused take_lease in "),
        "{said}"
    );
    assert_eq!(summaries[0]["code"], "forbidden");
}

/// With `--audit-max-bytes 131072`, 2,000 accepted commands (about 330 KB of lines) leave the
/// log's files (`audit.jsonl` and the older parts `.1` to `.3`) at most 131,072 bytes in all,
/// the newest lines kept and the oldest deleted, as `/metrics` says
/// (`nanopush_audit_rotations_total`, `nanopush_audit_deleted_bytes_total`, `nanopush_audit_log_bytes`).
#[test]
fn the_audit_log_rotates_within_its_cap_keeping_the_newest_lines() {
    let srv = start("audit-cap", &["--max-rate", "10000", "--audit-max-bytes", "131072"]);
    let records = srv.dir.join("records");
    let addr = srv.addr.clone();
    runtime().block_on(async move {
        let (mut op, _) = welcomed(&addr, Some(TOKEN)).await;
        for chunk in 0..40u32 {
            for k in 0..50 {
                send(&mut op, json!({"type": "take_lease", "id": 1000 + chunk * 50 + k})).await;
            }
            for k in 0..50 {
                assert_eq!(reply(&mut op, 1000 + chunk * 50 + k).await["type"], "ok");
            }
        }
    });
    let dir = records.join("audit");
    let metric = |name: &str| crate::serve_access::metric(&srv.addr, name);
    let deadline = Instant::now() + Duration::from_secs(10);
    // 2,000 take_lease and the lease_lost of the operator's connection, closed.
    while metric("nanopush_audit_entries_total") < 2001.0 {
        assert!(Instant::now() < deadline, "the lines were not written within 10 s");
        std::thread::sleep(Duration::from_millis(50));
    }
    let parts: Vec<(String, u64)> = [
        "audit.jsonl",
        "audit.jsonl.1",
        "audit.jsonl.2",
        "audit.jsonl.3",
        "audit.jsonl.4",
    ]
    .iter()
    .filter_map(|n| std::fs::metadata(dir.join(n)).ok().map(|m| (n.to_string(), m.len())))
    .collect();
    let total: u64 = parts.iter().map(|p| p.1).sum();
    assert!(total <= 131_072, "the log's files hold {total} bytes: {parts:?}");
    assert_eq!(parts.len(), 4, "audit.jsonl and three older parts: {parts:?}");
    assert_eq!(metric("nanopush_audit_log_bytes"), total as f64);
    assert!(metric("nanopush_audit_rotations_total") >= 3.0);
    assert!(metric("nanopush_audit_deleted_bytes_total") > 100_000.0);
    // The newest line is the last command; the parts read oldest first are in order.
    let mut ids = Vec::new();
    for name in ["audit.jsonl.3", "audit.jsonl.2", "audit.jsonl.1", "audit.jsonl"] {
        for l in std::fs::read_to_string(dir.join(name)).unwrap().lines() {
            let v: Value = serde_json::from_str(l).unwrap();
            if v["command"] == "take_lease" {
                ids.push(v["args"]["id"].as_u64().unwrap());
            }
        }
    }
    assert_eq!(ids.last(), Some(&2999), "the newest line is kept");
    assert!(
        ids.windows(2).all(|w| w[1] == w[0] + 1),
        "the kept lines are the newest, in order"
    );
}
