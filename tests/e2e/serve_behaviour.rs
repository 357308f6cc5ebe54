//! `nanopush serve` behaviours: a second command while a push runs
//! gets `busy`, a stop during a scan cancels it (no record, and a new scan may start), and on
//! SIGTERM every client gets `shutdown` and then a close frame (1001, "server shutting down").
//! Each waits on conditions with a time-out, never a fixed sleep.

use std::cell::RefCell;
use std::time::Duration;

use futures_util::StreamExt;
use serde_json::{Value, json};
use tokio_tungstenite::tungstenite::Message;

use crate::util::{
    TOKEN, Ws, connect, http_get, is, ok, operator, reply, runtime, send, start, start_scene, status, until, wait_exit,
    wait_ticks, welcomed,
};

#[test]
fn a_command_while_a_push_runs_is_busy_and_stop_ends_the_push() {
    let srv = start_scene("busy", &[]);
    runtime().block_on(async {
        let mut op = operator(&srv.addr, "tip").await;
        ok(
            &mut op,
            json!({"type": "push", "id": 3, "particle": 1, "distance_um": 5.0, "direction_deg": 0.0}),
        )
        .await;
        until(&mut op, 20.0, |m| is(m, "telemetry") && m["phase"] != "idle").await;
        // A second push, and a scan, while it runs.
        send(
            &mut op,
            json!({"type": "push", "id": 4, "particle": 2, "distance_um": 1.0, "direction_deg": 0.0}),
        )
        .await;
        let e = reply(&mut op, 4).await;
        assert_eq!(
            (e["type"].as_str(), e["code"].as_str()),
            (Some("error"), Some("busy")),
            "{e}"
        );
        assert!(e["message"].as_str().unwrap().contains("send stop first"), "{e}");
        send(
            &mut op,
            json!({"type": "scan", "id": 5, "centre_x_um": 40.0, "centre_y_um": 30.0, "size_um": 4.0, "pixels": 16}),
        )
        .await;
        assert_eq!(reply(&mut op, 5).await["code"], "busy");
        ok(&mut op, json!({"type": "stop", "id": 6})).await;
        let done = until(&mut op, 30.0, |m| is(m, "run_done")).await;
        assert_eq!(done["outcome"], "stopped", "{done}");
        // No longer busy: a new command is accepted.
        ok(
            &mut op,
            json!({"type": "push", "id": 7, "particle": 1, "distance_um": 0.5, "direction_deg": 0.0}),
        )
        .await;
    });
}

/// The reply to command `id` and the first message `ty`, in whichever order they come (a scan's
/// `scan_start` may overtake the command's reply).
async fn reply_and(ws: &mut Ws, id: u32, ty: &str) -> (Value, Value) {
    let (mut r, mut m) = (None, None);
    while r.is_none() || m.is_none() {
        let v = until(ws, 10.0, |v| v["id"] == id || is(v, ty)).await;
        if is(&v, ty) {
            m = Some(v);
        } else {
            r = Some(v);
        }
    }
    (r.unwrap(), m.unwrap())
}

#[test]
fn a_stop_during_a_scan_cancels_it_without_a_record() {
    let srv = start_scene("scan-stop", &[]);
    runtime().block_on(async {
        let mut op = operator(&srv.addr, "scan").await;
        // 64 lines at the default 1 line/s: a minute, unless stopped.
        let scan =
            json!({"type": "scan", "id": 3, "centre_x_um": 40.0, "centre_y_um": 30.0, "size_um": 4.0, "pixels": 64});
        send(&mut op, scan.clone()).await;
        let (r, start) = reply_and(&mut op, 3, "scan_start").await;
        assert_eq!(r["type"], "ok", "{r}");
        send(&mut op, json!({"type": "stop", "id": 4})).await;
        let (r, done) = reply_and(&mut op, 4, "scan_done").await;
        assert_eq!(r["type"], "ok", "{r}");
        assert_eq!(done["scan"], start["scan"]);
        assert!(
            done["record"].is_null() && done["record_error"].is_null(),
            "cancelled: {done}"
        );
        // The scan is over: another may start.
        let mut again = scan;
        again["id"] = json!(5);
        send(&mut op, again).await;
        let (r, next) = reply_and(&mut op, 5, "scan_start").await;
        assert_eq!(r["type"], "ok", "{r}");
        assert_ne!(next["scan"], start["scan"]);
    });
}

#[test]
fn on_sigterm_every_client_gets_shutdown_then_a_close_frame() {
    let mut srv = start_scene("close-frame", &[]);
    runtime().block_on(async {
        let (mut op, _) = welcomed(&srv.addr, Some(TOKEN)).await;
        let (mut viewer, _) = welcomed(&srv.addr, None).await;
        nanopush_e2e::sigterm(&srv.child);
        for ws in [&mut op, &mut viewer] {
            let mut saw_shutdown = false;
            let close = loop {
                let msg = tokio::time::timeout(Duration::from_secs(20), ws.next())
                    .await
                    .expect("the server closes within 20 s");
                match msg {
                    Some(Ok(Message::Text(t))) => {
                        let v: Value = serde_json::from_str(&t).unwrap();
                        saw_shutdown |= is(&v, "shutdown");
                    }
                    Some(Ok(Message::Close(frame))) => break frame,
                    Some(Ok(_)) => {}
                    other => panic!("the connection ended without a close frame: {other:?}"),
                }
            };
            assert!(saw_shutdown, "a shutdown message before the close");
            let frame = close.expect("a close frame with a code");
            assert_eq!(u16::from(frame.code), 1001);
            assert_eq!(frame.reason.as_str(), "server shutting down");
        }
    });
    assert!(srv.child.wait().unwrap().success());
}

/// `telemetry_sent` and `dropped_frames` from `/api/status`.
fn frames(addr: &str) -> (u64, u64) {
    let s = status(addr);
    (
        s["telemetry_sent"].as_u64().unwrap(),
        s["dropped_frames"].as_u64().unwrap(),
    )
}

/// A subscriber that stops reading is not disconnected at once, and never slows anyone: its
/// frames wait in its socket, the broadcast moves on without it, and when it reads again it is
/// told how many it missed (`lagged {skipped}`, counted in `dropped_frames`) and telemetry goes
/// on. Without the `lagged` message the client could not know that its trace has a hole.
#[test]
fn a_reader_that_falls_behind_is_told_how_many_frames_it_skipped() {
    let srv = start("lagged", &["--telemetry-hz", "1000"]);
    runtime().block_on(async {
        // A small receive window, so that the server's socket to it fills within seconds.
        let sock = tokio::net::TcpSocket::new_v4().unwrap();
        sock.set_recv_buffer_size(4096).unwrap();
        let tcp = sock.connect(srv.addr.parse().unwrap()).await.unwrap();
        let (mut ws, _): (Ws, _) = tokio_tungstenite::client_async(
            format!("ws://{}/ws", srv.addr),
            tokio_tungstenite::MaybeTlsStream::Plain(tcp),
        )
        .await
        .expect("upgrade");
        until(&mut ws, 5.0, |m| is(m, "welcome")).await;
        ok(&mut ws, json!({"type": "subscribe", "id": 1, "streams": ["tip"]})).await;
        assert_eq!(frames(&srv.addr).1, 0);
        // Stop reading. The session's sender stalls once the socket is full: it is the only
        // subscriber, so the server's count of frames taken for sending stops while telemetry
        // is produced at 1 kHz. Wait for that (500 ms unchanged: ~500 frames, beyond the 64 the
        // broadcast holds), well inside the 5 s a frame may wait before the reader is dropped.
        let deadline = std::time::Instant::now() + Duration::from_secs(60);
        let (mut last, mut still) = (frames(&srv.addr).0, 0);
        while still < 5 {
            assert!(std::time::Instant::now() < deadline, "the sends never stalled");
            std::thread::sleep(Duration::from_millis(100));
            let now = frames(&srv.addr).0;
            still = if now == last { still + 1 } else { 0 };
            last = now;
        }
        // Reading again: the frames already in the socket, then `lagged` with the count skipped.
        let lagged = until(&mut ws, 10.0, |m| is(m, "lagged")).await;
        let skipped = lagged["skipped"].as_u64().expect("a count");
        assert!(skipped > 0, "{lagged}");
        assert!(frames(&srv.addr).1 >= skipped, "counted in dropped_frames");
        let t = until(&mut ws, 5.0, |m| is(m, "telemetry")).await;
        assert!(t["t"].as_f64().unwrap() > 0.0);
        ok(&mut ws, json!({"type": "ping", "id": 2})).await;
    });
}

/// The CPUs a thread may run on, from `Cpus_allowed_list` ("0", "0-1", "0,2-3").
fn allowed_cpus(status: &str) -> Vec<usize> {
    let list = status
        .lines()
        .find_map(|l| l.strip_prefix("Cpus_allowed_list:"))
        .expect("Cpus_allowed_list")
        .trim();
    list.split(',')
        .flat_map(|r| match r.split_once('-') {
            Some((a, b)) => (a.parse().unwrap()..=b.parse().unwrap()).collect::<Vec<usize>>(),
            None => vec![r.parse().unwrap()],
        })
        .collect()
}

/// With realtime granted the control loop is pinned to the last core and every other thread of
/// the server stays off it, the main thread too (the accept loop runs there, in `block_on`): on
/// the loop's core their socket and file work would run with preemption off, and the loop
/// would overrun more under client load than idle (the soak, docs/benchmarks.md).
#[test]
fn only_the_control_loop_runs_on_its_core() {
    let ncpu = std::thread::available_parallelism().map_or(1, |n| n.get());
    if ncpu < 2 {
        eprintln!("one CPU: nothing to keep apart");
        return;
    }
    let srv = start("cores", &[]);
    // A connection and a scan start the threads that come later (the blocking pool, the scan).
    runtime().block_on(async {
        let mut op = operator(&srv.addr, "scan").await;
        ok(
            &mut op,
            json!({"type": "scan", "id": 2, "centre_x_um": 40.0, "centre_y_um": 30.0, "size_um": 4.0, "pixels": 16}),
        )
        .await;
        until(&mut op, 30.0, |m| is(m, "scan_done")).await;
    });
    let pid = srv.child.id();
    let mut seen = Vec::new();
    for task in std::fs::read_dir(format!("/proc/{pid}/task")).unwrap() {
        let task = task.unwrap().path();
        // A thread that ended meanwhile (a blocking-pool thread idle too long) is skipped.
        let (Ok(name), Ok(status)) = (
            std::fs::read_to_string(task.join("comm")),
            std::fs::read_to_string(task.join("status")),
        ) else {
            continue;
        };
        let name = name.trim().to_string();
        seen.push((name, allowed_cpus(&status)));
    }
    let last = ncpu - 1;
    let (lp, others): (Vec<_>, Vec<_>) = seen.iter().partition(|(n, _)| n == "control-loop");
    assert_eq!(lp.len(), 1, "{seen:?}");
    assert_eq!(lp[0].1, vec![last], "the loop is pinned to the last core: {seen:?}");
    for name in ["nanopush", "tokio-rt-worker", "recorder"] {
        assert!(others.iter().any(|(n, _)| n == name), "no {name} thread: {seen:?}");
    }
    for (name, cpus) in others {
        assert!(
            !cpus.contains(&last),
            "{name} may run on the loop's core {last}: {seen:?}"
        );
        assert!(!cpus.is_empty(), "{name}: {seen:?}");
    }
}

/// The loop's core (the last one), its PM QoS resume latency, and the server's record of it
/// (`server/src/no_halt.rs`).
fn loop_core() -> (String, String) {
    let last = std::thread::available_parallelism().map_or(1, |n| n.get()) - 1;
    (
        nanopush_e2e::pm_qos_setting(last),
        format!("/run/nanopush/no-halt-cpu{last}"),
    )
}

fn holders(record: &str) -> Vec<u32> {
    std::fs::read_to_string(record)
        .unwrap_or_default()
        .lines()
        .filter_map(|l| l.strip_prefix("holder ")?.parse().ok())
        .collect()
}

/// Traced with ftrace on the loop's core, most overruns under load are a tick whose core halted
/// while the loop slept and whose timer the hypervisor delivered 1-12 ms late. With realtime the
/// server keeps the loop's core polling while it runs (its PM QoS
/// resume latency `n/a`, 0 µs), reported as `no_halt` in the status and `nanopush_loop_no_halt`
/// in the metrics, and records itself as a holder; `--allow-cpu-halt` leaves the core alone. A
/// holder killed with SIGKILL cannot give the core back: the next server drops it from the record
/// (the last holder then restores the value from before: `no_halt::tests`).
#[test]
fn the_loops_core_polls_while_the_server_runs_unless_it_may_halt() {
    let (setting, record) = loop_core();
    if std::fs::OpenOptions::new().write(true).open(&setting).is_err() {
        eprintln!("{setting} is not writable here (not root, or no cpuidle): nothing to check");
        return;
    }
    let mut polling = start("no-halt", &[]);
    let halting = start("halt", &["--allow-cpu-halt"]);
    for srv in [&polling, &halting] {
        wait_ticks(&srv.addr, 10);
    }
    let s = status(&polling.addr);
    assert_eq!(s["loop"]["no_halt"], true, "{s}");
    assert_eq!(std::fs::read_to_string(&setting).unwrap().trim(), "n/a");
    assert!(holders(&record).contains(&polling.child.id()), "{record}");
    let (_, metrics) = http_get(&polling.addr, "/metrics");
    assert!(String::from_utf8_lossy(&metrics).contains("\nnanopush_loop_no_halt 1\n"));

    let s = status(&halting.addr);
    assert_eq!(s["loop"]["no_halt"], false, "{s}");
    assert!(!holders(&record).contains(&halting.child.id()));
    let (_, metrics) = http_get(&halting.addr, "/metrics");
    assert!(String::from_utf8_lossy(&metrics).contains("\nnanopush_loop_no_halt 0\n"));

    // Killed: it stays in the record until another server looks.
    let killed = polling.child.id();
    polling.child.kill().unwrap();
    polling.child.wait().unwrap();
    assert!(holders(&record).contains(&killed));
    let next = start("no-halt-next", &[]);
    wait_ticks(&next.addr, 10);
    let h = holders(&record);
    assert!(!h.contains(&killed) && h.contains(&next.child.id()), "{h:?}");

    // A server that cannot start (its port in use) never takes the core: it binds first (else it
    // would start its loop, record itself and exit with the core still polling).
    let port = next.addr.rsplit_once(':').unwrap().1;
    let data = std::env::temp_dir().join(format!("nanopush-port-in-use-{}", std::process::id()));
    let failed = std::process::Command::new(nanopush_e2e::bin("nanopush"))
        .args(["serve", "--haptic", "none", "--port", port, "--data-dir"])
        .arg(&data)
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let pid = failed.id();
    let out = failed.wait_with_output().unwrap();
    let why = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && why.contains("binding"), "{why}");
    let h = holders(&record);
    assert!(!h.contains(&pid) && h.contains(&next.child.id()), "{h:?}");

    // SIGHUP (its terminal closed) ends a server as SIGTERM does: it gives the core back.
    let mut next = next;
    let hung_up = next.child.id();
    // SAFETY: kill(2) on the pid of our own child, not yet reaped (so not reused).
    unsafe { libc::kill(hung_up as libc::pid_t, libc::SIGHUP) };
    let exit = wait_exit(&mut next.child, 20.0);
    assert!(exit.success(), "{exit:?}");
    assert!(!holders(&record).contains(&hung_up));
}

/// The telemetry frames' numbers (`seq`) one client received, and the losses announced to it.
#[derive(Default)]
struct Tally {
    seq: Vec<u64>,
    lost: u64,
}

impl Tally {
    fn record(&mut self, m: &Value) {
        if is(m, "telemetry") {
            self.seq.push(m["seq"].as_u64().expect("a frame's number"));
        } else if is(m, "lagged") {
            self.lost += m["skipped"].as_u64().unwrap();
        }
    }

    /// Each number once, in increasing order, and every number passed over announced.
    fn check(&self, who: &str) {
        assert!(
            self.seq.windows(2).all(|w| w[0] < w[1]),
            "{who}: the frames' numbers, each once in order: {:?}",
            self.seq
        );
        let passed_over: u64 = self.seq.windows(2).map(|w| w[1] - w[0] - 1).sum();
        assert_eq!(
            passed_over, self.lost,
            "{who}: frames lost without a `lagged`: {:?}",
            self.seq
        );
    }
}

/// Reads `ws` until `pred`, recording every message in `tally`.
async fn tally_until(ws: &mut Ws, tally: &RefCell<Tally>, pred: impl Fn(&Value) -> bool) -> Value {
    until(ws, 10.0, |m| {
        tally.borrow_mut().record(m);
        pred(m)
    })
    .await
}

/// The lease holder's telemetry comes on a channel of its own, woken before the viewers' (in the
/// soak its frame could come last of 500, and its gaps' p99 was +6 ms beyond the period); a
/// session reads both and sends each frame once (`server/src/frames.rs`). As the lease is given up
/// and taken again 30 times, every message is read: the holder's and a viewer's frames come
/// each once, in order, and none is lost without a `lagged`.
#[test]
fn telemetry_frames_come_once_in_order_as_the_lease_changes_hands() {
    let srv = start("lease-telemetry", &[]);
    runtime().block_on(async {
        let mut op = operator(&srv.addr, "tip").await;
        let mut viewer = connect(&srv.addr, None).await;
        send(&mut viewer, json!({"type": "subscribe", "id": 1, "streams": ["tip"]})).await;
        let (ops, views) = (RefCell::new(Tally::default()), RefCell::new(Tally::default()));
        tally_until(&mut viewer, &views, |m| is(m, "ok")).await;
        let frames = |t: &RefCell<Tally>| t.borrow().seq.len();
        for i in 0..60u32 {
            let lease = if i % 2 == 0 { "release_lease" } else { "take_lease" };
            send(&mut op, json!({"type": lease, "id": 10 + i})).await;
            let r = tally_until(&mut op, &ops, |m| (is(m, "ok") || is(m, "error")) && m["id"] == 10 + i).await;
            assert_eq!(r["type"], "ok", "{r}");
            // Two frames more under the new role.
            let n = frames(&ops);
            tally_until(&mut op, &ops, |_| frames(&ops) >= n + 2).await;
        }
        assert!(!status(&srv.addr)["lease"].is_null(), "the lease taken again");
        let last = *ops.borrow().seq.last().unwrap();
        tally_until(&mut viewer, &views, |m| {
            is(m, "telemetry") && m["seq"].as_u64() >= Some(last)
        })
        .await;
        ops.borrow().check("the operator");
        views.borrow().check("the viewer");
        assert!(
            frames(&ops) >= 120 && frames(&views) >= 120,
            "{} and {} frames",
            frames(&ops),
            frames(&views)
        );
    });
}
