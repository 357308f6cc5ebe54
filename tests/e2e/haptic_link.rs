//! Haptic z-control end to end: `nanopush serve` and `nanopush-haptic` as separate processes on
//! the iceoryx2 link, driven as the lease holder drives them from the browser.
//!
//! Each test gets its own link namespace (`NANOPUSH_HAPTIC_NAMESPACE`), so links never cross;
//! the tests run one at a time (each has a real-time loop and a real-time device loop, and the
//! machine has two cores).

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::{Duration, Instant};

use futures_util::StreamExt;
use nanopush_e2e::{Proc, bin, workspace};
use serde_json::{Value, json};

use crate::util::{
    TOKEN, http_get, is, reply, runtime, send, spawn_serve, status, tmp, until, wait_exit, wait_status, welcomed,
};

/// One haptic test at a time.
static ONE_AT_A_TIME: Mutex<()> = Mutex::new(());

/// Holds the haptic tests' turn until dropped (taken over from a test that failed holding it).
pub(crate) fn one_at_a_time() -> MutexGuard<'static, ()> {
    ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner())
}

/// A test's directory and link namespace.
struct Bench {
    dir: PathBuf,
    namespace: String,
}

impl Bench {
    fn new(tag: &str) -> Bench {
        let dir = tmp(&format!("haptic-{tag}"));
        // The paper's scene with the tip starting 2.2 µm above bare substrate at (20, 20) µm, away
        // from its particle at (50, 50) µm (the server starts the tip at the [scan] centre).
        let text = std::fs::read_to_string(workspace().join("scenes/paper-default.toml")).unwrap();
        let extra = "[scan]\ncentre_x_um = 20.0\ncentre_y_um = 20.0\nsize_um = 10.0\n";
        std::fs::write(
            dir.join("scene.toml"),
            format!(
                "{}\n{extra}",
                nanopush_e2e::with_strategy(&text, &[("start_height_um", "2.2")])
            ),
        )
        .unwrap();
        Bench {
            dir,
            namespace: format!("e2e{tag}{}", std::process::id()),
        }
    }
}

impl Drop for Bench {
    fn drop(&mut self) {
        // What processes killed with SIGKILL left in shared memory on this test's link, and the
        // link's own management segment (every process on it has ended by now).
        nanopush_proto::haptic::cleanup_dead_nodes_in(&self.namespace);
        let prefix = format!("nanopush_{}_", self.namespace);
        if let Ok(dir) = std::fs::read_dir("/dev/shm") {
            for e in dir.flatten() {
                if e.file_name().to_string_lossy().starts_with(&prefix) {
                    let _ = std::fs::remove_file(e.path());
                }
            }
        }
        if std::thread::panicking() {
            for log in ["server.log", "server2.log", "bridge.log"] {
                if let Ok(t) = std::fs::read_to_string(self.dir.join(log)) {
                    eprintln!("--- {log} ---\n{t}");
                }
            }
        }
        if std::env::var_os("NANOPUSH_E2E_KEEP").is_none() {
            let _ = std::fs::remove_dir_all(&self.dir);
        }
    }
}

/// `nanopush serve --haptic MODE` on a free port; its address. The log goes to `log`.
fn serve(b: &Bench, mode: &str, log: &str) -> (Proc, String) {
    serve_with(b, mode, log, &[])
}

/// [`serve`] with `extra` arguments.
fn serve_with(b: &Bench, mode: &str, log: &str, extra: &[&str]) -> (Proc, String) {
    let (child, addr) = spawn_serve(&b.dir.join(log), |c| {
        c.env("NANOPUSH_HAPTIC_NAMESPACE", &b.namespace)
            .args(["--haptic", mode, "--operator-token", TOKEN])
            .args(extra)
            .arg("--scene")
            .arg(b.dir.join("scene.toml"))
            .arg("--data-dir")
            .arg(b.dir.join("records"));
    });
    (Proc(child), addr)
}

/// `nanopush-haptic --device sim` with `args`; its stderr lines are collected.
fn bridge(b: &Bench, args: &[&str]) -> (Proc, Arc<Mutex<Vec<String>>>) {
    bridge_on(b, "sim", args)
}

/// `nanopush-haptic --device DEVICE` with `args`; its stderr lines are collected.
fn bridge_on(b: &Bench, device: &str, args: &[&str]) -> (Proc, Arc<Mutex<Vec<String>>>) {
    let mut child = Command::new(bin("nanopush-haptic"))
        .current_dir(workspace())
        .env("NANOPUSH_HAPTIC_NAMESPACE", &b.namespace)
        .args(["--device", device])
        .args(args)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("starting nanopush-haptic");
    let lines = Arc::new(Mutex::new(Vec::new()));
    let sink = lines.clone();
    let err = child.stderr.take().unwrap();
    let log = b.dir.join("bridge.log");
    std::thread::spawn(move || {
        for line in BufReader::new(err).lines().map_while(Result::ok) {
            let _ = std::fs::OpenOptions::new()
                .create(true)
                .append(true)
                .open(&log)
                .and_then(|mut f| std::io::Write::write_all(&mut f, format!("{line}\n").as_bytes()));
            sink.lock().unwrap().push(line);
        }
    });
    (Proc(child), lines)
}

/// Waits until a line containing `text` appears, within `secs`; returns it.
fn wait_line(lines: &Mutex<Vec<String>>, secs: f64, text: &str) -> String {
    wait_line_after(lines, 0, secs, text)
}

/// [`wait_line`] among the lines after the first `skip`.
fn wait_line_after(lines: &Mutex<Vec<String>>, skip: usize, secs: f64, text: &str) -> String {
    let deadline = Instant::now() + Duration::from_secs_f64(secs);
    loop {
        if let Some(l) = lines.lock().unwrap().iter().skip(skip).find(|l| l.contains(text)) {
            return l.clone();
        }
        assert!(Instant::now() < deadline, "no line with {text:?} within {secs} s");
        std::thread::sleep(Duration::from_millis(10));
    }
}

/// As the lease holder: take the lease and send `haptic {action}`; the reply. When it is `ok`
/// the holder stays connected, on a thread of its own that reads what the server sends, until
/// the server closes: haptic z-control ends when the lease is freed.
fn haptic(addr: &str, action: &str) -> Value {
    let (tx, rx) = std::sync::mpsc::channel();
    let (addr, action) = (addr.to_string(), action.to_string());
    std::thread::spawn(move || {
        runtime().block_on(async move {
            let (mut ws, _) = welcomed(&addr, Some(TOKEN)).await;
            send(&mut ws, json!({"type": "take_lease", "id": 1})).await;
            assert_eq!(reply(&mut ws, 1).await["type"], "ok");
            send(&mut ws, json!({"type": "haptic", "id": 2, "action": action})).await;
            let r = reply(&mut ws, 2).await;
            let holds = r["type"] == "ok";
            let _ = tx.send(r);
            while holds && matches!(ws.next().await, Some(Ok(_))) {}
        })
    });
    rx.recv_timeout(Duration::from_secs(30))
        .expect("the lease holder's reply")
}

/// Haptic z-control ends with the lease. The holder engages, then its connection drops (or it
/// gives the lease back): z-control goes off, never `engaged` with no holder.
#[test]
fn haptic_engagement_ends_when_the_lease_is_freed() {
    let _one = one_at_a_time();
    let b = Bench::new("lease-ends");
    let (_srv, addr) = serve(&b, "sim", "server.log");
    wait_status(&addr, 10.0, "link up", |s| s["haptic"]["link"] == "up");
    for gives_back in [false, true] {
        runtime().block_on(async {
            let (mut ws, _) = welcomed(&addr, Some(TOKEN)).await;
            send(&mut ws, json!({"type": "take_lease", "id": 1})).await;
            assert_eq!(reply(&mut ws, 1).await["type"], "ok");
            send(&mut ws, json!({"type": "haptic", "id": 2, "action": "engage"})).await;
            assert_eq!(reply(&mut ws, 2).await["type"], "ok");
            wait_status(&addr, 20.0, "engaged", |s| s["haptic"]["phase"] == "engaged");
            if gives_back {
                send(&mut ws, json!({"type": "release_lease", "id": 3})).await;
                assert_eq!(reply(&mut ws, 3).await["type"], "ok");
            }
        });
        wait_status(&addr, 20.0, "z-control off with the lease free", |s| {
            s["lease"].is_null() && s["haptic"]["phase"] == "off"
        });
    }
}

/// A server with `--haptic external` (its own watchdog at 100 ms) and a bridge whose scripted
/// hand, once engaged, goes 12.5 mm down in 3 s (past the surface, 100 nm = 10 mm below the
/// parking height) and stays there, with `bridge_args` and a trace; returns once the hand feels
/// more than 0.3 N: the server, its address, the bridge, its log lines and the trace's path.
fn pressing(b: &Bench, bridge_args: &[&str]) -> (Proc, String, Proc, Arc<Mutex<Vec<String>>>, PathBuf) {
    let (srv, addr) = serve_with(b, "external", "server.log", &["--haptic-timeout-ms", "100"]);
    let trace = b.dir.join("trace.csv");
    let script = b.dir.join("press-and-stay.csv");
    std::fs::write(&script, "t_s,handle_m\n0,0\n3,-0.0125\n60,-0.0125\n").unwrap();
    let operator = format!("file:{}", script.display());
    let mut args = vec![
        "--operator",
        &operator,
        "--duration",
        "60",
        "--trace",
        trace.to_str().unwrap(),
    ];
    args.extend_from_slice(bridge_args);
    let (br, lines) = bridge(b, &args);
    wait_status(&addr, 10.0, "link up", |s| s["haptic"]["link"] == "up");
    assert_eq!(haptic(&addr, "engage")["type"], "ok");
    wait_status(&addr, 20.0, "engaged", |s| s["haptic"]["phase"] == "engaged");
    wait_status(&addr, 10.0, "pressing", |s| {
        s["haptic"]["force_n"].as_f64().is_some_and(|f| f > 0.3)
    });
    (srv, addr, br, lines, trace)
}

/// Stops the bridge of a [`pressing`] test (SIGTERM: it zeroes its force and exits 0) and
/// reads its trace; with the index of the last cycle pressed with more than 0.3 N on a live link.
fn end_press(br: &mut Proc, trace: &Path) -> (Vec<Row>, usize) {
    nanopush_e2e::sigterm(&br.0);
    assert!(wait_exit(&mut br.0, 5.0).success(), "the bridge exits 0 on SIGTERM");
    let rows = read_trace(trace);
    let pressed = rows
        .iter()
        .rposition(|r| r.link && r.force > 0.3)
        .expect("pressed before the server went");
    (rows, pressed)
}

/// One row of the bridge's trace.
#[derive(Debug, Clone, Copy)]
struct Row {
    t: f64,
    handle: f64,
    force: f64,
    tip_z: f64,
    link: bool,
    energy: f64,
}

fn read_trace(path: &Path) -> Vec<Row> {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text.lines();
    assert_eq!(
        lines.next(),
        Some("t_s,handle_m,handle_force_n,tip_z_m,tip_force_n,link,pc_damping,port_energy_j,raw_port_energy_j,holding")
    );
    lines
        .map(|l| {
            let c: Vec<&str> = l.split(',').collect();
            let f = |i: usize| c[i].parse::<f64>().unwrap();
            Row {
                t: f(0),
                handle: f(1),
                force: f(2),
                tip_z: f(3),
                link: c[5] == "up",
                energy: f(7),
            }
        })
        .collect()
}

/// The press through the real processes: the tip follows the hand down, the hand feels the
/// snap-in and then the adhesion hold it until the pull-off lets go (Fig 3's curve, scaled), the
/// force never exceeds the device's limit, and the port energy never goes below −1 µJ.
///
/// Both sides run with a 100 ms link time-out: this is a test of the feel, not of the watchdog
/// (the kill tests below check the 5 ms default), and a virtual machine now and then pauses both
/// processes for ~5 ms, which the default would rightly treat as a lost link.
#[test]
fn a_press_through_the_server_feels_the_snap_in_and_the_pull_off() {
    let _one = one_at_a_time();
    let b = Bench::new("press");
    let (_srv, addr) = serve_with(&b, "external", "server.log", &["--haptic-timeout-ms", "100"]);
    let trace = b.dir.join("trace.csv");
    let (mut br, lines) = bridge(
        &b,
        &[
            "--operator",
            "press",
            "--duration",
            "60",
            "--server-timeout-ms",
            "100",
            "--trace",
            trace.to_str().unwrap(),
        ],
    );
    let s = wait_status(&addr, 10.0, "link up", |s| s["haptic"]["link"] == "up");
    assert_eq!(s["haptic"]["device"], "sim");
    assert_eq!(haptic(&addr, "engage")["type"], "ok");
    wait_status(&addr, 20.0, "engaged", |s| s["haptic"]["phase"] == "engaged");
    let st = wait_exit(&mut br.0, 60.0);
    assert!(st.success(), "the bridge exits 0 when the press ends: {st}");
    let rows = read_trace(&trace);
    assert!(rows.len() > 5000, "{} rows", rows.len());
    // Never more than the device's 2.5 N; never below −1 µJ.
    assert!(rows.iter().all(|r| r.force.abs() <= 2.5));
    let e_min = rows.iter().map(|r| r.energy).fold(f64::INFINITY, f64::min);
    assert!(e_min > -1e-6, "port energy went to {e_min:e} J");
    // Engaged at the parking height, 100 nm above the surface the approach found; the hand
    // starts down from there.
    let engaged = rows
        .iter()
        .position(|r| r.link && (r.tip_z - 100e-9).abs() < 1e-9 && r.handle < -0.1e-3)
        .expect("the press starts from the parking height");
    let lowest = (engaged..rows.len())
        .min_by(|&i, &j| rows[i].handle.total_cmp(&rows[j].handle))
        .unwrap();
    // Going down, the tip follows the hand: 10 nm of tip per mm of handle until it touches.
    let mid = (engaged..lowest)
        .find(|&i| rows[i].tip_z < 50e-9)
        .expect("halfway down");
    let (r0, r1) = (rows[engaged], rows[mid]);
    let ratio = (r1.tip_z - r0.tip_z) / (r1.handle - r0.handle);
    assert!((ratio - 10e-9 / 1e-3).abs() < 0.2e-6, "tip/handle {ratio:e}");
    // The snap-in: on the way down the hand is pulled down (attraction) before it is pushed up.
    let down = &rows[engaged..=lowest];
    let snap = down
        .iter()
        .position(|r| r.force < -0.2)
        .expect("a snap-in pulls the hand down");
    assert!(
        down[snap..].iter().any(|r| r.force > 0.5),
        "then the surface pushes back"
    );
    // The pull-off: on the way up the adhesion holds the hand (a force below −0.5 N) and lets go
    // at once (within 5 ms the force is back near zero).
    let up = &rows[lowest..];
    let (hold, strongest) = up
        .iter()
        .enumerate()
        .min_by(|a, b| a.1.force.total_cmp(&b.1.force))
        .map(|(i, r)| (i, r.force))
        .unwrap();
    assert!(strongest < -0.5, "the adhesion should hold the hand: {strongest} N");
    let release = up[hold..]
        .iter()
        .position(|r| r.force > -0.1)
        .expect("the pull-off lets go");
    assert!(up[hold + release].t - up[hold].t < 0.005, "a jump, not a slope");
    assert!(up.last().unwrap().tip_z > 50e-9, "the hand took the tip back up");
    // iceoryx2 started quietly on both sides (its configuration is built in code).
    let server_log = std::fs::read_to_string(b.dir.join("server.log")).unwrap();
    for log in [server_log, lines.lock().unwrap().join("\n")] {
        assert!(!log.contains("No config file"), "{log}");
    }
}

/// `kill -9` of the supervised bridge: the server lives, says "haptic link down" within 5 ms of
/// the last sample, takes the tip back to its parking height, restarts the bridge, and the link
/// is up again and engages anew.
#[test]
fn a_killed_bridge_is_survived_restarted_and_engaged_again() {
    let _one = one_at_a_time();
    let b = Bench::new("kill-bridge");
    let (_srv, addr) = serve(&b, "sim", "server.log");
    let s = wait_status(&addr, 10.0, "link up", |s| s["haptic"]["link"] == "up");
    let pid = s["haptic"]["pid"].as_u64().unwrap();
    assert_eq!(haptic(&addr, "engage")["type"], "ok");
    wait_status(&addr, 20.0, "engaged", |s| s["haptic"]["phase"] == "engaged");
    let log = b.dir.join("server.log");
    let before = std::fs::read_to_string(&log).unwrap().lines().count();
    // SAFETY: kill(2) on the bridge's pid, read from the server.
    unsafe {
        libc::kill(pid as libc::pid_t, libc::SIGKILL);
    }
    let deadline = Instant::now() + Duration::from_secs(5);
    let line = loop {
        let text = std::fs::read_to_string(&log).unwrap();
        if let Some(l) = text.lines().skip(before).find(|l| l.contains("haptic link down")) {
            break l.to_string();
        }
        assert!(Instant::now() < deadline, "no 'haptic link down' in the log");
        std::thread::sleep(Duration::from_millis(10));
    };
    let ms: f64 = line
        .split("no handle sample for ")
        .nth(1)
        .and_then(|r| r.split(" ms").next())
        .and_then(|v| v.parse().ok())
        .unwrap_or_else(|| panic!("{line}"));
    assert!(ms <= 5.0, "detected {ms} ms after the last sample");
    // The tip goes back to its parking height, 100 nm above the surface, and waits there.
    let s = wait_status(&addr, 5.0, "parked", |s| {
        s["haptic"]["tip_z_m"]
            .as_f64()
            .is_some_and(|z| (z - 100e-9).abs() < 1e-9)
    });
    assert_ne!(s["haptic"]["phase"], "engaged");
    // A new bridge (the supervisor's restart), the link up, the force ramp again.
    let s = wait_status(&addr, 10.0, "restarted", |s| {
        s["haptic"]["restarts"].as_u64() >= Some(1) && s["haptic"]["link"] == "up"
    });
    assert_ne!(s["haptic"]["pid"].as_u64().unwrap(), pid);
    assert!(s["haptic"]["link_downs"].as_u64() >= Some(1));
    wait_status(&addr, 10.0, "engaged again", |s| s["haptic"]["phase"] == "engaged");
    let (code, body) = http_get(&addr, &format!("/metrics?token={TOKEN}"));
    assert_eq!(code, 200);
    let text = String::from_utf8(body).unwrap();
    for family in [
        "nanopush_haptic_link_up 1",
        "nanopush_haptic_engaged 1",
        "nanopush_haptic_restarts_total 1",
        "# TYPE nanopush_haptic_latency_seconds histogram",
    ] {
        assert!(text.contains(family), "{family} in /metrics");
    }
}

/// `kill -9` of the server: the bridge renders zero force within 5 ms of the server's last
/// sample, and takes up a new server on the same link without a restart.
#[test]
fn a_killed_server_zeroes_the_force_and_the_bridge_takes_up_a_new_one() {
    let _one = one_at_a_time();
    let b = Bench::new("kill-server");
    // The server's own watchdog is not under test here (the kill-bridge test checks it): a long
    // one keeps a VM's pause from re-anchoring the hand mid-press. The bridge's is the default.
    // The server is killed while the hand presses.
    let (mut srv, _addr, mut br, lines, trace) = pressing(&b, &[]);
    let before = lines.lock().unwrap().len();
    let _ = srv.0.kill();
    let _ = srv.0.wait();
    let line = wait_line_after(&lines, before, 5.0, "server silent");
    let ms: f64 = line
        .split("its last sample ")
        .nth(1)
        .and_then(|r| r.split(" ms").next())
        .and_then(|v| v.parse().ok())
        .unwrap_or_else(|| panic!("{line}"));
    assert!(ms <= 5.0, "zeroed {ms} ms after the server's last sample");
    // A new server on the same link: the bridge is live again without a restart.
    let (_srv2, addr2) = serve(&b, "external", "server2.log");
    wait_status(&addr2, 10.0, "link up", |s| s["haptic"]["link"] == "up");
    let deadline = Instant::now() + Duration::from_secs(5);
    while lines
        .lock()
        .unwrap()
        .iter()
        .filter(|l| l.contains("server live"))
        .count()
        < 2
    {
        assert!(Instant::now() < deadline, "the bridge did not take up the new server");
        std::thread::sleep(Duration::from_millis(10));
    }
    // From the silence on, every force was 0. The stretch the kill made: pressed with more than
    // 0.3 N up to it, exactly 0 N through it.
    let (rows, pressed) = end_press(&mut br, &trace);
    let silent = rows[pressed..].iter().position(|r| !r.link).expect("a silent stretch") + pressed;
    let back = rows[silent..].iter().position(|r| r.link).expect("live again") + silent;
    assert!(rows[silent..back].iter().all(|r| r.force == 0.0));
    let gap = rows[silent].t - rows[pressed].t;
    assert!(gap < 0.006, "zeroed {gap} s after the last pressed cycle");
}

/// SIGTERM of the server while the hand presses: the server itself lets go of the hand before it
/// exits. The hand's force drops to exactly 0 N while the link is still up (the server's own
/// `active = 0`, not the bridge's watchdog, which is set to 100 ms here so the two cannot be
/// confused) and stays 0 while the hand keeps pressing; the server exits 0 with the tip parked.
#[test]
fn a_terminated_server_zeroes_the_hands_force_before_it_goes() {
    let _one = one_at_a_time();
    let b = Bench::new("term");
    let (mut srv, _addr, mut br, lines, trace) = pressing(&b, &["--server-timeout-ms", "100"]);
    nanopush_e2e::sigterm(&srv.0);
    assert!(wait_exit(&mut srv.0, 10.0).success(), "the server exits 0 on SIGTERM");
    // The bridge notices the silence (100 ms later), then is stopped.
    wait_line(&lines, 5.0, "server silent");
    let (rows, pressed) = end_press(&mut br, &trace);
    let zero = rows[pressed..]
        .iter()
        .position(|r| r.force == 0.0)
        .expect("the force went to zero")
        + pressed;
    assert!(
        rows[zero].link,
        "zeroed by the watchdog, not by the server: {:?}",
        rows[zero]
    );
    assert!(
        rows[zero].t - rows[pressed].t < 0.05,
        "zeroed {} s after the last pressed cycle",
        rows[zero].t - rows[pressed].t
    );
    let end = rows.len() - 1;
    assert!(
        rows[zero..].iter().all(|r| r.force == 0.0),
        "a force came back after the release"
    );
    assert!(
        rows[end].t - rows[zero].t > 0.1,
        "the hand was watched pressing on after the release"
    );
    let log = std::fs::read_to_string(b.dir.join("server.log")).unwrap();
    assert!(log.contains("control loop ended"), "{log}");
}

/// One bridge at a time: a second one on the same link is refused with a clear message.
#[test]
fn a_second_bridge_is_refused() {
    let _one = one_at_a_time();
    let b = Bench::new("second");
    let (_first, lines) = bridge(&b, &["--operator", "hold", "--duration", "30"]);
    wait_line(&lines, 5.0, "waiting for nanopush serve");
    let out = Command::new(bin("nanopush-haptic"))
        .env("NANOPUSH_HAPTIC_NAMESPACE", &b.namespace)
        .args(["--device", "sim", "--duration", "1"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("another nanopush-haptic is live"), "{err}");
}

/// Without a haptic link the command says so; bad scales name the field and the range.
#[test]
fn haptic_commands_are_refused_with_the_reason() {
    let _one = one_at_a_time();
    let b = Bench::new("refuse");
    let (_srv, addr) = serve(&b, "none", "server.log");
    let r = haptic(&addr, "engage");
    assert_eq!(r["code"], "unavailable", "{r}");
    assert!(r["message"].as_str().unwrap().contains("--haptic sim"));
    assert_eq!(status(&addr)["haptic"]["link"], "off");
    runtime().block_on(async {
        let (mut ws, _) = welcomed(&addr, Some(TOKEN)).await;
        send(&mut ws, json!({"type": "haptic", "id": 1, "action": "engage"})).await;
        assert_eq!(reply(&mut ws, 1).await["code"], "no_lease");
        send(&mut ws, json!({"type": "take_lease", "id": 2})).await;
        reply(&mut ws, 2).await;
        send(
            &mut ws,
            json!({"type": "haptic", "id": 3, "action": "scale", "nm_per_mm": 1e6}),
        )
        .await;
        let r = reply(&mut ws, 3).await;
        assert_eq!(r["code"], "out_of_range");
        assert!(r["message"].as_str().unwrap().contains("nm_per_mm"), "{r}");
        send(&mut ws, json!({"type": "haptic", "id": 4, "action": "scale"})).await;
        assert_eq!(reply(&mut ws, 4).await["code"], "invalid");
        send(&mut ws, json!({"type": "haptic", "id": 5, "action": "wobble"})).await;
        let r = until(&mut ws, 5.0, |m| is(m, "error")).await;
        assert_eq!(r["code"], "malformed");
        assert!(r["message"].as_str().unwrap().contains("wobble"), "{r}");
    });
}

/// The reference sketch's settings (1 Mbaud, 1 kHz declared) render a felt
/// press through the real server, and an unplug and re-plug in the middle of the press is
/// logged (the bridge names the cable, the server the link), survived (the same bridge, no
/// restart) and resumed (the link comes back, z-control engages again and the hand feels the
/// press again); the counters are in /api/status, where the page's haptic panel reads them.
#[test]
fn a_serial_board_renders_a_press_and_survives_an_unplug() {
    use nanopush_haptic::operator::Script;
    use nanopush_haptic::serial::fake::FakeBoard;
    let _one = one_at_a_time();
    let b = Bench::new("serial");
    let (_srv, addr) = serve_with(&b, "external", "server.log", &["--haptic-timeout-ms", "100"]);
    let script = b.dir.join("press-and-stay.csv");
    std::fs::write(&script, "t_s,handle_m\n0,0\n3,-0.0125\n60,-0.0125\n").unwrap();
    let press = || Script::parse(&format!("file:{}", script.display())).unwrap();
    let link = b.dir.join("by-id-hapkit");
    let board = FakeBoard::plug_in(Some(&link), press()).expect("a fake board");
    let device = format!("serial:{}", link.display());
    let (mut br, lines) = bridge_on(&b, &device, &["--duration", "60", "--server-timeout-ms", "100"]);
    let s = wait_status(&addr, 10.0, "link up", |s| s["haptic"]["link"] == "up");
    assert_eq!(s["haptic"]["device"], "serial");
    assert_eq!(
        s["haptic"]["rate_hz"], 1000.0,
        "the sketch's 1 Mbaud carries 1 kHz: {s}"
    );
    let pid = s["haptic"]["pid"].clone();
    assert_eq!(haptic(&addr, "engage")["type"], "ok");
    wait_status(&addr, 20.0, "engaged", |s| s["haptic"]["phase"] == "engaged");
    board.engage();
    wait_status(&addr, 10.0, "a felt press", |s| {
        s["haptic"]["force_n"].as_f64().is_some_and(|f| f > 0.3)
    });
    // The bridge is stopped for 50 ms in the middle of the press (the board's watchdog zeroes
    // its force meanwhile): it must not resume at the force from before the pause.
    let pid_n = br.0.id() as libc::pid_t;
    // SAFETY: plain kill(2) on our own child.
    unsafe { libc::kill(pid_n, libc::SIGSTOP) };
    let stopped = Instant::now();
    std::thread::sleep(Duration::from_millis(50));
    // SAFETY: as above.
    unsafe { libc::kill(pid_n, libc::SIGCONT) };
    std::thread::sleep(Duration::from_millis(200));
    let forces = board.forces();
    let before = forces
        .iter()
        .rev()
        .find(|(t, _)| *t < stopped)
        .map(|&(_, f)| f)
        .unwrap();
    let after: Vec<f64> = forces
        .iter()
        .filter(|(t, _)| *t > stopped + Duration::from_millis(40))
        .map(|&(_, f)| f)
        .collect();
    assert!(before.abs() > 0.3, "pressing before the pause: {before} N");
    assert!(
        after[0].abs() <= 0.1 * before.abs(),
        "no kick after the pause: {before} N then {:?}",
        &after[..5.min(after.len())]
    );
    // The cable is pulled in the middle of the press: the server shows the loss while it lasts.
    board.unplug();
    wait_line(&lines, 5.0, &format!("cable: {device} was lost"));
    wait_status(&addr, 5.0, "link down", |s| s["haptic"]["link"] == "down");
    wait_status(&addr, 5.0, "the loss shown while it lasts", |s| {
        s["haptic"]["device_faults"]["losses"] == 1 && s["haptic"]["device_faults"]["reopens"] == 0
    });
    std::thread::sleep(Duration::from_millis(300));
    let board = FakeBoard::plug_in(Some(&link), press()).expect("plugged in again");
    wait_line(&lines, 10.0, &format!("cable: {device} is back"));
    wait_status(&addr, 10.0, "link up again", |s| s["haptic"]["link"] == "up");
    wait_status(&addr, 20.0, "engaged again", |s| s["haptic"]["phase"] == "engaged");
    board.engage();
    let s = wait_status(&addr, 10.0, "the press felt again", |s| {
        s["haptic"]["force_n"].as_f64().is_some_and(|f| f > 0.3)
    });
    assert_eq!(s["haptic"]["pid"], pid, "the same bridge: no restart");
    let faults = &s["haptic"]["device_faults"];
    assert_eq!(
        (faults["losses"].as_u64(), faults["reopens"].as_u64()),
        (Some(1), Some(1)),
        "{s}"
    );
    assert_eq!(faults["side"]["losses"], "cable", "{s}");
    let log = std::fs::read_to_string(b.dir.join("server.log")).unwrap();
    assert!(log.contains("haptic link down"), "{log}");
    nanopush_e2e::sigterm(&br.0);
    assert!(
        wait_exit(&mut br.0, 5.0).success(),
        "the bridge exits 0: the device is back"
    );
}
