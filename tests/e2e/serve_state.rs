//! `nanopush serve` for the page: a late joiner gets the instrument's state, a push
//! stops when its lease holder leaves, static files are compressed.

use serde_json::json;

use crate::util::{TOKEN, http, http_get, is, ok, runtime, send, start, until, welcomed};

/// A client that connects after a scan and a push gets, right after
/// `welcome`, the instrument as it is: the moved particle, the lease, the phase, the latest scan
/// (marked stale once a push ran since) and, while a push runs, its path.
#[test]
fn a_late_joiner_gets_the_current_state_after_welcome() {
    let srv = start("late", &["--scan-line-hz", "400"]);
    runtime().block_on(async {
        let (mut op, w) = welcomed(&srv.addr, Some(TOKEN)).await;
        let me = w["client"].as_u64().unwrap();
        let first = until(&mut op, 5.0, |_| true).await;
        assert_eq!(first["type"], "state", "the message after welcome: {first}");
        assert!(first["scan"].is_null() && first["push"].is_null(), "{first}");
        assert_eq!(first["particles"][0]["x"], 40e-6);
        send(&mut op, json!({"type": "subscribe", "id": 1, "streams": ["scan"]})).await;
        ok(&mut op, json!({"type": "take_lease", "id": 2})).await;
        ok(&mut op, json!({"type": "scan", "id": 3, "pixels": 16})).await;
        let done = until(&mut op, 20.0, |m| is(m, "scan_done")).await;
        let scan_record = done["record"].as_str().expect("a scan record").to_string();

        ok(
            &mut op,
            json!({"type": "push", "id": 4, "particle": 1, "distance_um": 1.0, "direction_deg": 0.0}),
        )
        .await;
        // Everyone hears the push start, with its planned path.
        let started = until(&mut op, 20.0, |m| is(m, "push_started")).await;
        assert_eq!(started["particle"], 1);
        assert_eq!(started["by"], me);
        assert_eq!(started["run"], 1, "its run number, as its record will say: {started}");
        let path = started["path"].as_array().unwrap();
        assert_eq!(path.len(), 2, "{started}");
        assert!((path[1][0].as_f64().unwrap() - 41e-6).abs() < 50e-9, "{started}");
        // A viewer joining during the push sees its path.
        let (mut during, _) = welcomed(&srv.addr, None).await;
        let s = until(&mut during, 5.0, |_| true).await;
        assert_eq!(s["type"], "state");
        assert_eq!(s["push"]["particle"], 1, "{s}");
        assert_eq!(s["push"]["run"], 1, "{s}");
        assert_eq!(s["lease"], me);
        let run = until(&mut op, 30.0, |m| is(m, "run_done")).await;
        assert_eq!(run["outcome"], "ok", "{run}");

        let (mut late, _) = welcomed(&srv.addr, None).await;
        let s = until(&mut late, 5.0, |_| true).await;
        assert_eq!(s["type"], "state", "{s}");
        assert!(s["push"].is_null(), "{s}");
        assert_eq!(s["lease"], me);
        assert_eq!(s["phase"], "idle");
        let p1 = s["particles"]
            .as_array()
            .unwrap()
            .iter()
            .find(|p| p["id"] == 1)
            .unwrap()
            .clone();
        assert_eq!(p1["x"], run["estimate"][0], "{s}");
        assert!((p1["radius"].as_f64().unwrap() - 500e-9).abs() < 1e-15, "{p1}");
        assert_eq!(s["scan"]["record"], scan_record.as_str());
        assert_eq!(s["scan"]["done"], true);
        assert_eq!(s["scan"]["xres"], 16);
        assert_eq!(s["scan"]["stale"], true, "a push ran since the scan: {s}");
        let (status, _) = http_get(&srv.addr, &format!("/api/records/{scan_record}"));
        assert_eq!(status, 200);
        // The server's run (a page tells a restart from a network blip by it) and the
        // run history read from the records on disk.
        let instance = w["instance"].as_str().expect("welcome names the instance");
        assert!(!instance.is_empty(), "{w}");
        let st = crate::util::status(&srv.addr);
        assert_eq!(st["instance"], instance, "{st}");
        assert_eq!(st["started_unix_ms"], w["started_unix_ms"], "{st}");
        assert!(
            w["started_unix_ms"].as_u64().is_some_and(|ms| ms > 1_700_000_000_000),
            "{w}"
        );
        let (code, body) = http_get(&srv.addr, "/api/runs");
        assert_eq!(code, 200);
        let runs: serde_json::Value = serde_json::from_slice(&body).unwrap();
        assert_eq!(runs[0]["outcome"], "ok", "{runs}");
        assert_eq!(runs[0]["particle"], 1, "{runs}");
        assert_eq!(runs[0]["estimate"], run["estimate"], "{runs}");
        // Its record names the server run and run number push_started gave (so a page that lost
        // sight of a push does not read an earlier push of the particle as its outcome).
        assert_eq!(runs[0]["instance"], instance, "{runs}");
        assert_eq!(runs[0]["run"], 1, "{runs}");
    });
}

/// When the lease holder's connection closes during a push, the push is
/// stopped (nobody watches it), recorded, and everyone is told why the lease went.
#[test]
fn a_push_stops_when_its_lease_holder_disconnects() {
    let srv = start("holder-gone", &[]);
    runtime().block_on(async {
        let (mut watcher, _) = welcomed(&srv.addr, None).await;
        let (mut op, welcome) = welcomed(&srv.addr, Some(TOKEN)).await;
        let me = welcome["client"].as_u64().unwrap();
        ok(&mut op, json!({"type": "take_lease", "id": 1})).await;
        ok(
            &mut op,
            json!({"type": "push", "id": 2, "particle": 1, "distance_um": 5.0, "direction_deg": 0.0}),
        )
        .await;
        until(&mut watcher, 20.0, |m| is(m, "push_started")).await;
        drop(op);
        let lease = until(&mut watcher, 10.0, |m| is(m, "lease")).await;
        assert!(lease["holder"].is_null(), "{lease}");
        let why = lease["reason"].as_str().expect("a reason");
        assert!(
            why.contains(&format!("client {me}")) && why.contains("push was stopped"),
            "{why}"
        );
        let run = until(&mut watcher, 20.0, |m| is(m, "run_done")).await;
        assert_eq!(run["outcome"], "stopped", "{run}");
        // A disconnect is not the operator's Stop: the record does not say "stop requested by the
        // operator".
        assert_eq!(run["failure"], "stopped: the lease holder disconnected", "{run}");
        assert!(run["record"].is_string(), "the stopped push is recorded: {run}");
    });
}

/// Page weight: static files are gzip-compressed for a browser that accepts it.
#[test]
fn static_files_are_compressed() {
    let srv = start("gzip", &[]);
    let gzip = ["Accept-Encoding: gzip".to_string()];
    let (_, head, _) = http(&srv.addr, "GET", "/src/session.js", &gzip);
    assert!(head.starts_with("http/1.1 200"), "{head}");
    assert!(head.contains("content-encoding: gzip"), "{head}");
    // Without Accept-Encoding: plain.
    let (status, body) = http_get(&srv.addr, "/src/session.js");
    assert_eq!(status, 200);
    assert!(String::from_utf8_lossy(&body).contains("export class Session"));
}
