//! `nanopush-haptic-latency`: the haptic link's latency benchmark (not a test: it measures and
//! prints). Run it on a quiet machine, in release:
//!
//! ```text
//! cargo run --release -p nanopush-e2e --bin nanopush-haptic-latency [-- SECONDS]
//! ```
//!
//! 1. the iceoryx2 transport between two processes (`nanopush-haptic bench-transport`):
//!    one-way and round trip, p50/p99/p99.9/max;
//! 2. end-to-end haptic latency — a device sample → the force the server computed from it,
//!    back at the device — from `nanopush serve --haptic external` and a simulated bridge at
//!    1 kHz, as the bridge measures it (`--json`);
//! 3. the control loop's mean compute time per tick (the three phases, from `/metrics`) without
//!    a haptic link and with one engaged, for the loop's tick budget.

use std::io::{BufRead, BufReader, Read, Write};
use std::net::TcpStream;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use nanopush_e2e::{bin, workspace};

const TOKEN: &str = "latency-bench-token";

struct Proc(Child);

impl Drop for Proc {
    fn drop(&mut self) {
        nanopush_e2e::stop(&mut self.0);
    }
}

fn get(addr: &str, path: &str) -> String {
    let mut s = TcpStream::connect(addr).expect("connect");
    write!(s, "GET {path} HTTP/1.1\r\nHost: {addr}\r\nConnection: close\r\n\r\n").unwrap();
    let mut buf = String::new();
    s.read_to_string(&mut buf).unwrap();
    buf.split_once("\r\n\r\n")
        .map(|(_, b)| b.to_string())
        .unwrap_or_default()
}

fn serve(mode: &str, ns: &str) -> (Proc, String) {
    let mut child = Command::new(bin("nanopush"))
        .current_dir(workspace())
        .env("NANOPUSH_HAPTIC_NAMESPACE", ns)
        .args(["serve", "--port", "0", "--haptic", mode, "--operator-token", TOKEN])
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .expect("starting nanopush serve");
    let mut lines = BufReader::new(child.stdout.take().unwrap()).lines();
    let first = lines.next().unwrap().unwrap();
    let addr = first.trim_start_matches("nanopush serve: listening on ").to_string();
    std::thread::spawn(move || for _ in lines {});
    (Proc(child), addr)
}

/// The sums and counts of each compute phase's histogram, for means between two snapshots.
struct Compute {
    sums: [f64; 3],
    counts: [f64; 3],
}

fn compute(addr: &str) -> Compute {
    let text = get(addr, "/metrics");
    let mut c = Compute {
        sums: [0.0; 3],
        counts: [0.0; 3],
    };
    for (i, phase) in ["control", "physics", "publish"].iter().enumerate() {
        for line in text.lines() {
            let v = |l: &str| l.rsplit(' ').next().and_then(|v| v.parse::<f64>().ok()).unwrap_or(0.0);
            if line.starts_with(&format!("nanopush_loop_compute_seconds_sum{{phase=\"{phase}\"}}")) {
                c.sums[i] = v(line);
            }
            if line.starts_with(&format!("nanopush_loop_compute_seconds_count{{phase=\"{phase}\"}}")) {
                c.counts[i] = v(line);
            }
        }
    }
    c
}

fn mean_between(a: &Compute, b: &Compute) -> [f64; 3] {
    std::array::from_fn(|i| (b.sums[i] - a.sums[i]) / (b.counts[i] - a.counts[i]).max(1.0) * 1e6)
}

fn engage(addr: &str) {
    // A bare WebSocket handshake and two text frames: take the lease, engage.
    let mut s = TcpStream::connect(addr).unwrap();
    write!(
        s,
        "GET /ws?token={TOKEN} HTTP/1.1\r\nHost: {addr}\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n\
         Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n\r\n"
    )
    .unwrap();
    let mut head = [0u8; 512];
    let _ = s.read(&mut head);
    for msg in [
        r#"{"type":"take_lease","id":1}"#,
        r#"{"type":"haptic","id":2,"action":"engage"}"#,
    ] {
        let p = msg.as_bytes();
        let mut frame = vec![0x81, 0x80 | p.len() as u8, 1, 2, 3, 4];
        frame.extend(p.iter().enumerate().map(|(i, b)| b ^ [1, 2, 3, 4][i % 4]));
        s.write_all(&frame).unwrap();
    }
    std::thread::sleep(Duration::from_millis(200));
}

fn main() {
    let secs: f64 = std::env::args().nth(1).and_then(|a| a.parse().ok()).unwrap_or(10.0);
    let ns = format!("latency{}", std::process::id());
    println!(
        "nanopush haptic latency benchmark ({} build), {secs} s per run",
        if cfg!(debug_assertions) { "debug" } else { "release" }
    );

    // 1. Transport.
    let out = Command::new(bin("nanopush-haptic"))
        .env("NANOPUSH_HAPTIC_NAMESPACE", &ns)
        .args(["bench-transport", "--samples", "200000"])
        .output()
        .expect("bench-transport");
    print!("{}", String::from_utf8_lossy(&out.stdout));

    // 3a. The loop without a haptic link.
    let (srv, addr) = serve("none", &ns);
    std::thread::sleep(Duration::from_secs(1));
    let a = compute(&addr);
    std::thread::sleep(Duration::from_secs_f64(secs));
    let b = compute(&addr);
    let without = mean_between(&a, &b);
    drop(srv);

    // 2 and 3b. With a bridge, engaged.
    let (_srv, addr) = serve("external", &ns);
    let bridge = Command::new(bin("nanopush-haptic"))
        .env("NANOPUSH_HAPTIC_NAMESPACE", &ns)
        .args(["--device", "sim", "--operator", "sine", "--json"])
        .arg("--duration")
        .arg(format!("{}", secs + 8.0))
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .expect("starting nanopush-haptic");
    let mut bridge = Proc(bridge);
    let t0 = Instant::now();
    while !get(&addr, &format!("/api/status?token={TOKEN}")).contains("\"link\":\"up\"") {
        assert!(t0.elapsed() < Duration::from_secs(10), "the link did not come up");
        std::thread::sleep(Duration::from_millis(20));
    }
    engage(&addr);
    let t0 = Instant::now();
    while !get(&addr, &format!("/api/status?token={TOKEN}")).contains("\"phase\":\"engaged\"") {
        assert!(
            t0.elapsed() < Duration::from_secs(30),
            "haptic z-control did not engage"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    std::thread::sleep(Duration::from_secs(1));
    let a = compute(&addr);
    std::thread::sleep(Duration::from_secs_f64(secs));
    let b = compute(&addr);
    let with = mean_between(&a, &b);
    let mut summary = String::new();
    bridge.0.stdout.take().unwrap().read_to_string(&mut summary).unwrap();
    let _ = bridge.0.wait();
    let v: serde_json::Value = serde_json::from_str(summary.trim()).expect("the bridge's --json summary");
    let l = &v["latency_ns"];
    let us = |k: &str| l[k].as_f64().unwrap_or(f64::NAN) / 1e3;
    println!(
        "end-to-end haptic latency at 1 kHz (device sample → force back at the device), {} samples:\n  p50 {:.1} µs, p99 {:.1} µs, p99.9 {:.1} µs, max {:.1} µs",
        l["samples"],
        us("p50"),
        us("p99"),
        us("p999"),
        us("max")
    );
    println!("bridge: {} cycles, {} overruns", v["cycles"], v["overruns"]);
    println!("control loop compute per tick, mean (µs):    control  physics  publish  total");
    let total = |m: &[f64; 3]| m.iter().sum::<f64>();
    println!(
        "  without a haptic link                      {:7.2}  {:7.2}  {:7.2}  {:6.2}",
        without[0],
        without[1],
        without[2],
        total(&without)
    );
    println!(
        "  with a bridge, engaged                     {:7.2}  {:7.2}  {:7.2}  {:6.2}",
        with[0],
        with[1],
        with[2],
        total(&with)
    );
    println!(
        "  difference                                                   {:+6.2}",
        total(&with) - total(&without)
    );
}
