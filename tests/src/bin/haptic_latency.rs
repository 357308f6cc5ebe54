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

use std::io::Read;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use nanopush_e2e::{Proc, bin, workspace};

const TOKEN: &str = "latency-bench-token";

/// The body of a GET of `path` from the server.
fn get(addr: &str, path: &str) -> String {
    let (_, body) = nanopush_e2e::client::get(addr, path).expect("a GET from the server");
    String::from_utf8_lossy(&body).into_owned()
}

/// `nanopush serve --haptic MODE` on a free port, on link namespace `ns`: the server and its
/// address.
fn serve(mode: &str, ns: &str) -> (Proc, String) {
    let mut child = Command::new(bin("nanopush"))
        .current_dir(workspace())
        .env("NANOPUSH_HAPTIC_NAMESPACE", ns)
        .args(["serve", "--port", "0", "--haptic", mode, "--operator-token", TOKEN])
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .expect("starting nanopush serve");
    let addr = nanopush_e2e::listening_addr(&mut child)
        .unwrap_or_else(|first| panic!("nanopush serve did not start: its first line {first:?}"));
    (Proc(child), addr)
}

/// The sums and counts of each compute phase's histogram, for means between two snapshots.
struct Compute {
    sums: [f64; 3],
    counts: [f64; 3],
}

/// The compute phases' histogram sums and counts now.
fn compute(addr: &str) -> Compute {
    let text = get(addr, "/metrics");
    let series = |kind: &str, phase: &str| {
        let name = format!("nanopush_loop_compute_seconds_{kind}{{phase=\"{phase}\"}}");
        nanopush_e2e::metrics::series(&text, &name).unwrap_or(0.0)
    };
    let phases = ["control", "physics", "publish"];
    Compute {
        sums: phases.map(|p| series("sum", p)),
        counts: phases.map(|p| series("count", p)),
    }
}

/// Each phase's mean compute time (µs) between two readings.
/// Each phase's mean compute time (µs) over `secs`, from a second on.
fn mean_compute(addr: &str, secs: f64) -> [f64; 3] {
    std::thread::sleep(Duration::from_secs(1));
    let a = compute(addr);
    std::thread::sleep(Duration::from_secs_f64(secs));
    let b = compute(addr);
    mean_between(&a, &b)
}

/// Waits until `/api/status` contains `needle` (read every `every_ms`), `secs` at most.
fn wait_status(addr: &str, needle: &str, secs: u64, every_ms: u64, what: &str) {
    let t0 = Instant::now();
    while !get(addr, &format!("/api/status?token={TOKEN}")).contains(needle) {
        assert!(t0.elapsed() < Duration::from_secs(secs), "{what}");
        std::thread::sleep(Duration::from_millis(every_ms));
    }
}

fn mean_between(a: &Compute, b: &Compute) -> [f64; 3] {
    std::array::from_fn(|i| (b.sums[i] - a.sums[i]) / (b.counts[i] - a.counts[i]).max(1.0) * 1e6)
}

/// As the lease holder, engages haptic z-control, and stays connected (reading, so that it
/// answers the server's pings) until the server closes the socket: z-control ends when the lease
/// is freed.
fn engage(addr: &str) {
    use futures_util::{SinkExt, StreamExt};
    use tokio_tungstenite::tungstenite::Message;
    let url = nanopush_e2e::client::ws_url(addr, Some(TOKEN));
    std::thread::spawn(move || {
        let rt = tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()
            .expect("a runtime");
        rt.block_on(async move {
            let (mut ws, _) = tokio_tungstenite::connect_async(url).await.expect("the WebSocket");
            for msg in [
                r#"{"type":"take_lease","id":1}"#,
                r#"{"type":"haptic","id":2,"action":"engage"}"#,
            ] {
                ws.send(Message::Text(msg.into())).await.expect("a command sent");
            }
            while let Some(Ok(_)) = ws.next().await {}
        });
    });
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
    let without = mean_compute(&addr, secs);
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
    wait_status(&addr, "\"link\":\"up\"", 10, 20, "the link did not come up");
    engage(&addr);
    wait_status(
        &addr,
        "\"phase\":\"engaged\"",
        30,
        50,
        "haptic z-control did not engage",
    );
    let with = mean_compute(&addr, secs);
    let mut summary = String::new();
    bridge.0.stdout.take().unwrap().read_to_string(&mut summary).unwrap();
    let _ = bridge.0.wait();
    let v: serde_json::Value = serde_json::from_str(summary.trim()).expect("the bridge's --json summary");
    print_results(&v, &without, &with);
}

/// The bridge's latency and cycles (`v`, its `--json` summary), and the loop's compute per tick
/// without a haptic link and with one engaged.
fn print_results(v: &serde_json::Value, without: &[f64; 3], with: &[f64; 3]) {
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
        total(without)
    );
    println!(
        "  with a bridge, engaged                     {:7.2}  {:7.2}  {:7.2}  {:6.2}",
        with[0],
        with[1],
        with[2],
        total(with)
    );
    println!(
        "  difference                                                   {:+6.2}",
        total(with) - total(without)
    );
}
