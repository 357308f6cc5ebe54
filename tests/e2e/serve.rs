//! `nanopush serve` end to end: the real binary on a free port, driven over WebSockets with
//! tokio-tungstenite — telemetry, a push that moves a particle, roles, the lease, bad input, the
//! metrics exposition, and a SIGTERM in the middle of a push.

use std::io::{Read, Write};
use std::net::TcpStream;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use futures_util::{SinkExt, StreamExt};
use serde_json::{Value, json};
use tokio_tungstenite::tungstenite::Message;
use tokio_tungstenite::tungstenite::client::IntoClientRequest;

use crate::util::{TOKEN, Ws, http_get, is, ok, operator, reply, runtime, send, start, until, wait_ticks, welcomed};

#[test]
fn a_viewer_receives_telemetry_and_cannot_command() {
    let srv = start("viewer", &[]);
    runtime().block_on(async {
        let (mut v, w) = welcomed(&srv.addr, None).await;
        assert_eq!(w["role"], "viewer");
        assert_eq!(w["tick_hz"], 1000.0);
        ok(&mut v, json!({"type": "subscribe", "id": 1, "streams": ["tip"]})).await;
        // 60 Hz, read on the server's clock (each frame's `t`), not the test's: the median
        // interval between 31 frames is 1/60 s within one 1 ms tick of the loop, whatever the
        // machine does to the test's own scheduling. (30 Hz or 120 Hz decimation fails.)
        let mut t = Vec::new();
        while t.len() < 31 {
            let m = until(&mut v, 5.0, |m| is(m, "telemetry")).await;
            assert!(m["volts"].as_f64().unwrap().is_finite());
            assert_eq!(m["stage"].as_array().unwrap().len(), 3);
            t.push(m["t"].as_f64().unwrap());
        }
        let mut gaps: Vec<f64> = t.windows(2).map(|w| w[1] - w[0]).collect();
        assert!(gaps.iter().all(|&g| g > 0.0), "server times must increase: {t:?}");
        gaps.sort_by(f64::total_cmp);
        let median = gaps[gaps.len() / 2];
        assert!(
            (median - 1.0 / 60.0).abs() <= 1.0e-3,
            "median telemetry interval {median} s, not 1/60 s: {gaps:?}"
        );
        for (id, cmd) in [
            (2, json!({"type": "take_lease", "id": 2})),
            (
                3,
                json!({"type": "push", "id": 3, "particle": 1, "distance_um": 1.0, "direction_deg": 0.0}),
            ),
        ] {
            send(&mut v, cmd).await;
            let r = reply(&mut v, id).await;
            assert_eq!(r["code"], "forbidden", "{r}");
        }
    });
}

#[test]
fn an_operator_pushes_a_particle_and_sees_it_move() {
    let srv = start("push", &[]);
    runtime().block_on(async {
        let mut op = operator(&srv.addr, "tip").await;
        ok(
            &mut op,
            json!({"type": "push", "id": 3, "particle": 1, "distance_um": 1.0, "direction_deg": 0.0}),
        )
        .await;
        // While it runs the telemetry shows the strategy's phases and the estimate.
        let pushing = until(&mut op, 20.0, |m| is(m, "telemetry") && m["phase"] == "push").await;
        assert!(pushing["estimate"].is_array());
        let done = until(&mut op, 30.0, |m| is(m, "run_done")).await;
        assert_eq!(done["outcome"], "ok", "{done}");
        let est = done["estimate"].as_array().unwrap();
        assert!((est[0].as_f64().unwrap() - 41e-6).abs() < 50e-9, "{done}");
        // The record: the trace and the summary, with the particle's true displacement.
        let name = done["record"].as_str().expect("a record").to_string();
        let (status, body) = http_get(&srv.addr, &format!("/api/records/{name}"));
        assert_eq!(status, 200);
        let summary: Value = serde_json::from_slice(&body).unwrap();
        let truth = summary["truth"].as_array().unwrap();
        let moved = truth[0].as_f64().unwrap() - 40e-6;
        assert!((moved - 1e-6).abs() < 30e-9, "moved {moved:e} m");
        let (status, body) = http_get(
            &srv.addr,
            &format!("/api/records/{}", summary["trace"].as_str().unwrap()),
        );
        assert_eq!(status, 200);
        let csv = String::from_utf8(body).unwrap();
        assert!(
            csv.lines().count() as u64 > 1000 && csv.lines().count() as u64 == summary["rows"].as_u64().unwrap() + 1
        );
        let (_, list) = http_get(&srv.addr, "/api/records");
        let list: Value = serde_json::from_slice(&list).unwrap();
        assert_eq!(list.as_array().unwrap().len(), 2, "{list}");
    });
}

#[test]
fn bad_messages_get_typed_errors_and_the_server_lives_on() {
    let srv = start("bad", &["--max-message-bytes", "1024"]);
    runtime().block_on(async {
        let (mut op, _) = welcomed(&srv.addr, Some(TOKEN)).await;
        malformed_and_oversized_messages_get_typed_errors(&mut op).await;
        ok(&mut op, json!({"type": "take_lease", "id": 1})).await;
        commands_out_of_range_name_the_field_and_the_range(&mut op).await;
        // The whole stage in one scan, about its centre, is allowed (a unit round trip's rounding
        // would refuse it).
        ok(
            &mut op,
            json!({"type": "scan", "id": 12, "centre_x_um": 50.0, "centre_y_um": 50.0, "size_um": 100.0, "pixels": 8}),
        )
        .await;
        ok(&mut op, json!({"type": "stop", "id": 13})).await;
        a_burst_is_rate_limited_and_served_again_as_the_bucket_refills(&mut op).await;
    });
    // The loop ran on through all of it.
    wait_ticks(&srv.addr, 100);
}

/// Messages that are not one JSON command, or are larger than the server's `--max-message-bytes`
/// (1024 here), each get an `error` with the right code; a push without the lease, `no_lease`.
async fn malformed_and_oversized_messages_get_typed_errors(op: &mut Ws) {
    let cases: Vec<(String, &str)> = vec![
        ("{not json".into(), "malformed"),
        (r#"{"type":"fly"}"#.into(), "malformed"),
        // An array is not a command (serde would read it as a push: `no_lease`), nor are two
        // values in one message.
        (r#"["push",13,1,0.2,0]"#.into(), "malformed"),
        (r#"{"type":"ping","id":1} {"type":"ping","id":2}"#.into(), "malformed"),
        (r#"{"type":"push","particle":1,"distance_um":NaN}"#.into(), "malformed"),
        (
            format!(r#"{{"type":"ping","pad":"{}"}}"#, "x".repeat(2000)),
            "too_large",
        ),
        (
            r#"{"type":"push","id":9,"particle":1,"distance_um":1.0,"direction_deg":0.0}"#.into(),
            "no_lease",
        ),
    ];
    for (text, code) in cases {
        op.send(Message::Text(text.clone().into())).await.unwrap();
        let e = until(op, 5.0, |m| is(m, "error")).await;
        assert_eq!(e["code"], code, "{text:.60}: {e}");
    }
    op.send(Message::Binary(vec![1, 2, 3].into())).await.unwrap();
    assert_eq!(until(op, 5.0, |m| is(m, "error")).await["code"], "malformed");
}

/// Commands of the lease holder with a value out of range, or fields that do not go together,
/// get `out_of_range` / `unknown_particle` / `invalid` naming the field and the allowed range.
async fn commands_out_of_range_name_the_field_and_the_range(op: &mut Ws) {
    for (id, cmd, code, words) in [
        (
            2,
            json!({"type": "push", "id": 2, "particle": 1, "distance_um": 500.0, "direction_deg": 0}),
            "out_of_range",
            "allowed: (0, 100] µm",
        ),
        (
            3,
            json!({"type": "push", "id": 3, "particle": 1, "distance_um": 1e308, "direction_deg": 0}),
            "out_of_range",
            "distance_um",
        ),
        (
            4,
            json!({"type": "push", "id": 4, "particle": 1, "distance_um": 1.0, "direction_deg": 1e3}),
            "out_of_range",
            "[-360, 360]",
        ),
        (
            5,
            json!({"type": "push", "id": 5, "particle": 77, "distance_um": 1.0, "direction_deg": 0}),
            "unknown_particle",
            "ids: 1, 2, 3",
        ),
        (
            6,
            json!({"type": "push", "id": 6, "particle": 1, "distance_um": 1.0, "to_x_um": 3.0, "to_y_um": 3.0}),
            "invalid",
            "either",
        ),
        (
            7,
            json!({"type": "push", "id": 7, "particle": 1, "to_x_um": -1.0, "to_y_um": 3.0}),
            "out_of_range",
            "to_x_um",
        ),
        (
            8,
            json!({"type": "scan", "id": 8, "pixels": 4}),
            "out_of_range",
            "pixels",
        ),
        (
            9,
            json!({"type": "scan", "id": 9, "centre_x_um": 1.0, "size_um": 10.0}),
            "out_of_range",
            "within the stage",
        ),
        // A side of 5e-324 µm would write a GSF with XReal = 0; a target on the stage's edge
        // would run ~200 s into a time-out.
        (
            10,
            json!({"type": "scan", "id": 10, "size_um": 5e-324}),
            "out_of_range",
            "size_um",
        ),
        (
            11,
            json!({"type": "push", "id": 11, "particle": 1, "to_x_um": 100.0, "to_y_um": 50.0}),
            "out_of_range",
            "allowed: [0.500, 99.500] µm",
        ),
        // A distance without its direction is not pushed along +x.
        (
            12,
            json!({"type": "push", "id": 12, "particle": 1, "distance_um": 1.0}),
            "invalid",
            "distance_um goes with direction_deg (degrees from +x, in [-360, 360]): give both",
        ),
    ] {
        send(op, cmd).await;
        let r = reply(op, id).await;
        assert_eq!(r["code"], code, "{r}");
        assert!(r["message"].as_str().unwrap().contains(words), "{r}");
    }
}

/// Rate limit: 50 messages per second, burst 50; a burst of 80 pings: each gets exactly one
/// reply, `ok` with its id or `rate_limited` (which cannot name it), and at least 20 are refused
/// (the bucket holds at most 50 and refills at 50/s).
async fn a_burst_is_rate_limited_and_served_again_as_the_bucket_refills(op: &mut Ws) {
    let is_reply = |m: &Value| is(m, "ok") || (is(m, "error") && m["code"] == "rate_limited");
    for k in 0..80 {
        send(op, json!({"type": "ping", "id": 1000 + k})).await;
    }
    let (mut answered, mut refused) = (0, 0);
    for _ in 0..80 {
        let m = until(op, 5.0, is_reply).await;
        if is(&m, "ok") {
            answered += 1;
        } else {
            assert!(m["message"].as_str().unwrap().contains("50"), "{m}");
            refused += 1;
        }
    }
    assert!(
        refused >= 20 && answered + refused == 80,
        "{answered} answered, {refused} refused"
    );
    // The connection stays, and is served again as the bucket refills (retried until then).
    let deadline = Instant::now() + Duration::from_secs(5);
    loop {
        send(op, json!({"type": "ping", "id": 99})).await;
        let m = until(op, 5.0, is_reply).await;
        if is(&m, "ok") {
            assert_eq!(m["id"], 99);
            break;
        }
        assert!(Instant::now() < deadline, "still rate limited after 5 s");
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
}

#[test]
fn two_operators_contend_and_exactly_one_holds_the_lease() {
    let srv = start("lease", &[]);
    runtime().block_on(async {
        let (mut a, welcome) = welcomed(&srv.addr, Some(TOKEN)).await;
        let ida = welcome["client"].as_u64().unwrap();
        let (mut b, _) = welcomed(&srv.addr, Some(TOKEN)).await;
        send(&mut a, json!({"type": "take_lease", "id": 1})).await;
        let ra = reply(&mut a, 1).await;
        assert_eq!(ra["type"], "ok");
        // Everyone sees who holds it.
        let seen = until(&mut b, 5.0, |m| is(m, "lease")).await;
        assert_eq!(seen["holder"].as_u64(), Some(ida));
        send(&mut b, json!({"type": "take_lease", "id": 1})).await;
        let rb = reply(&mut b, 1).await;
        assert_eq!(rb["code"], "lease_held", "{rb}");
        // B cannot release what it does not hold, nor push.
        send(&mut b, json!({"type": "release_lease", "id": 2})).await;
        assert_eq!(reply(&mut b, 2).await["code"], "no_lease");
        send(
            &mut b,
            json!({"type": "push", "id": 4, "particle": 1, "distance_um": 1.0, "direction_deg": 0.0}),
        )
        .await;
        assert_eq!(reply(&mut b, 4).await["code"], "no_lease");
        // A leaves: the lease is free, and B takes it.
        a.close(None).await.unwrap();
        drop(a);
        let freed = until(&mut b, 5.0, |m| is(m, "lease") && m["holder"].is_null()).await;
        assert!(freed["holder"].is_null());
        ok(&mut b, json!({"type": "take_lease", "id": 3})).await;
    });
}

#[test]
fn origins_and_tokens_are_checked_at_the_upgrade() {
    let srv = start("origin", &["--viewer-token", "viewer-secret"]);
    runtime().block_on(async {
        let url = format!("ws://{}/ws?token={TOKEN}", srv.addr);
        let mut req = url.clone().into_client_request().unwrap();
        req.headers_mut()
            .insert("Origin", "http://evil.example".parse().unwrap());
        let e = tokio_tungstenite::connect_async(req).await.unwrap_err();
        assert!(e.to_string().contains("403"), "{e}");
        let mut req = url.into_client_request().unwrap();
        let own = format!("http://{}", srv.addr);
        req.headers_mut().insert("Origin", own.parse().unwrap());
        assert!(tokio_tungstenite::connect_async(req).await.is_ok());
        // With a viewer token set, a viewer without it (or with a wrong one) is refused.
        for url in [
            format!("ws://{}/ws", srv.addr),
            format!("ws://{}/ws?token=nope", srv.addr),
        ] {
            let e = tokio_tungstenite::connect_async(url).await.unwrap_err();
            assert!(e.to_string().contains("401"), "{e}");
        }
        let (_v, welcome) = welcomed(&srv.addr, Some("viewer-secret")).await;
        assert_eq!(welcome["role"], "viewer");
    });
    // The JSON API needs the token too, and a foreign Host name is refused (DNS rebinding).
    assert_eq!(http_get(&srv.addr, "/api/records").0, 401);
    assert_eq!(http_get(&srv.addr, "/api/records?token=viewer-secret").0, 200);
    let mut s = TcpStream::connect(&srv.addr).unwrap();
    write!(
        s,
        "GET /api/status?token=viewer-secret HTTP/1.1\r\nHost: evil.example:80\r\nConnection: close\r\n\r\n"
    )
    .unwrap();
    let mut buf = String::new();
    s.read_to_string(&mut buf).unwrap();
    assert!(buf.starts_with("HTTP/1.1 421"), "{buf:.40}");
}

#[test]
fn metrics_pass_promtool() {
    let srv = start("metrics", &[]);
    // Some ticks first, so that the histograms have counts.
    wait_ticks(&srv.addr, 100);
    let (status, body) = http_get(&srv.addr, "/metrics");
    assert_eq!(status, 200);
    let text = String::from_utf8(body).unwrap();
    for family in [
        "nanopush_loop_period_error_seconds_bucket",
        "nanopush_loop_compute_seconds_bucket{phase=\"physics\"",
        "nanopush_loop_overruns_total",
        "nanopush_haptic_link_age_seconds",
        "nanopush_clients",
        "nanopush_dropped_frames_total",
    ] {
        assert!(text.contains(family), "missing {family}");
    }
    let mut child = Command::new("promtool")
        .args(["check", "metrics"])
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("promtool (Debian package prometheus; `make test` installs it)");
    child.stdin.take().unwrap().write_all(text.as_bytes()).unwrap();
    let out = child.wait_with_output().unwrap();
    assert!(
        out.status.success(),
        "promtool: {}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
}

#[test]
fn sigterm_mid_push_retracts_the_tip_and_completes_every_record() {
    let mut srv = start("sigterm", &[]);
    let records = srv.dir.join("records");
    runtime().block_on(async {
        let mut op = operator(&srv.addr, "tip").await;
        ok(
            &mut op,
            json!({"type": "push", "id": 3, "particle": 1, "distance_um": 5.0, "direction_deg": 0.0}),
        )
        .await;
        until(&mut op, 20.0, |m| is(m, "telemetry") && m["phase"] == "push").await;
        nanopush_e2e::sigterm(&srv.child);
        let done = until(&mut op, 20.0, |m| is(m, "run_done")).await;
        assert_eq!(done["outcome"], "stopped", "{done}");
        until(&mut op, 20.0, |m| is(m, "shutdown")).await;
    });
    let status = srv.child.wait().unwrap();
    assert!(status.success(), "exit {status:?}");
    let names: Vec<String> = std::fs::read_dir(&records)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    assert!(names.iter().all(|n| !n.ends_with(".partial")), "{names:?}");
    let json_name = names.iter().find(|n| n.ends_with(".json")).expect("a summary");
    let summary: Value = serde_json::from_slice(&std::fs::read(records.join(json_name)).unwrap()).unwrap();
    assert_eq!(summary["outcome"], "stopped");
    let csv = std::fs::read_to_string(records.join(summary["trace"].as_str().unwrap())).unwrap();
    assert_eq!(csv.lines().count() as u64, summary["rows"].as_u64().unwrap() + 1);
    // The tip ended retracted: the last row, the final tick, is back at the start height above
    // the substrate that parking detected (the level substrate: where it started).
    let z = |line: &str| line.split(',').nth(5).unwrap().parse::<f64>().unwrap();
    let rows: Vec<&str> = csv.lines().skip(1).collect();
    let start_z = z(rows[0]);
    let end_z = z(rows.last().unwrap());
    let last_phase = rows.last().unwrap().split(',').nth(2).unwrap();
    assert_eq!(last_phase, "done", "the record ends with the final tick");
    assert!((end_z - start_z).abs() < 20e-9, "start z {start_z:e}, end z {end_z:e}");
}

#[test]
fn a_scan_streams_its_lines_and_records_a_complete_gsf() {
    let srv = start("scan", &["--scan-line-hz", "200"]);
    runtime().block_on(async {
        let mut op = operator(&srv.addr, "scan").await;
        send(
            &mut op,
            json!({"type": "scan", "id": 3, "centre_x_um": 40.0, "centre_y_um": 30.0, "size_um": 4.0, "pixels": 16}),
        )
        .await;
        let start = until(&mut op, 10.0, |m| is(m, "scan_start")).await;
        assert_eq!(start["xres"], 16);
        // Sixteen binary lines, in order, each 32 + 16·4 bytes, then scan_done.
        let mut lines = 0u32;
        let mut top = f32::MIN;
        let done = loop {
            let msg = tokio::time::timeout(Duration::from_secs(10), op.next())
                .await
                .unwrap()
                .unwrap()
                .unwrap();
            match msg {
                Message::Binary(b) => {
                    assert_eq!(&b[..4], b"NPSL");
                    assert_eq!(b.len(), 32 + 16 * 4);
                    assert_eq!(u32::from_le_bytes(b[12..16].try_into().unwrap()), lines);
                    for c in b[32..].chunks_exact(4) {
                        top = top.max(f32::from_le_bytes(c.try_into().unwrap()));
                    }
                    lines += 1;
                }
                Message::Text(t) => {
                    let v: Value = serde_json::from_str(&t).unwrap();
                    if is(&v, "scan_done") {
                        break v;
                    }
                }
                _ => {}
            }
        };
        assert_eq!(lines, 16);
        // The 0.5 µm particle appears 1 µm high (within the pixel grid's sampling of its top).
        assert!((0.9e-6..1.05e-6).contains(&(top as f64)), "top {top}");
        let name = done["record"].as_str().expect("a record").to_string();
        let (status, gsf) = http_get(&srv.addr, &format!("/api/records/{name}"));
        assert_eq!(status, 200);
        let nul = gsf.iter().position(|&c| c == 0).unwrap();
        let header = String::from_utf8_lossy(&gsf[..nul]).to_string();
        assert!(header.contains("XRes = 16") && header.contains("YRes = 16"), "{header}");
        let data = gsf.len() - gsf[nul..].iter().position(|&c| c != 0).map_or(gsf.len() - nul, |k| k) - nul;
        assert_eq!(data, 16 * 16 * 4, "data bytes after the header");
        // A stop during a scan cancels it; the lease holder may scan again afterwards.
        ok(&mut op, json!({"type": "ping", "id": 4})).await;
    });
}

#[test]
fn clients_beyond_the_cap_are_refused_and_a_place_frees_when_one_leaves() {
    let srv = start("cap", &["--max-clients", "2"]);
    runtime().block_on(async {
        let (mut a, _) = welcomed(&srv.addr, None).await;
        let (_b, _) = welcomed(&srv.addr, None).await;
        let e = tokio_tungstenite::connect_async(format!("ws://{}/ws", srv.addr))
            .await
            .unwrap_err();
        assert!(e.to_string().contains("503"), "{e}");
        a.close(None).await.unwrap();
        drop(a);
        // The place frees once the session has ended.
        let deadline = Instant::now() + Duration::from_secs(5);
        loop {
            match tokio_tungstenite::connect_async(format!("ws://{}/ws", srv.addr)).await {
                Ok((mut c, _)) => {
                    until(&mut c, 5.0, |m| is(m, "welcome")).await;
                    break;
                }
                Err(e) if Instant::now() < deadline => {
                    assert!(e.to_string().contains("503"), "{e}");
                    tokio::time::sleep(Duration::from_millis(50)).await;
                }
                Err(e) => panic!("no place freed: {e}"),
            }
        }
    });
}
