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
