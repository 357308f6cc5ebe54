//! `nanopush-soak`: a soak benchmark of `nanopush serve` against careless and hostile clients
//! (not a test: it measures and prints). In release, on a quiet machine:
//!
//! ```text
//! cargo build --release --workspace --bins
//! target/release/nanopush-soak [SECONDS]        # default 600
//! ```
//!
//! One server (`--haptic none`, the default scene); first an idle window of 30 s for the loop's
//! overrun rate alone; then, for SECONDS: 500 viewers subscribed to telemetry; one operator who
//! holds the lease, subscribes to telemetry and sends a command (a ping) every 100 ms; 50
//! slowloris sockets that each send a partial request and, once the server closes them, start
//! again; one client sending garbage (random bytes, arrays, unknown types, floods past the rate
//! limit). It reports: the operator's commands sent and answered, the operator's telemetry gaps
//! (p50, p99, max, beyond the period), the server's open file descriptors and resident memory
//! before the load, at its end and 10 s after the clients left, and the loop's overruns per
//! minute idle and under the load.

use std::io::{BufRead, BufReader, Read, Write};
use std::net::TcpStream;
use std::process::{Child, Command, Stdio};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering::Relaxed};
use std::time::{Duration, Instant};

use futures_util::{SinkExt, StreamExt};
use nanopush_e2e::{bin, workspace};
use serde_json::json;
use tokio_tungstenite::tungstenite::Message;

const TOKEN: &str = "nanopush-soak-operator";
const VIEWERS: usize = 500;
const LORISES: usize = 50;

struct Proc(Child);

impl Drop for Proc {
    fn drop(&mut self) {
        // SAFETY: SIGTERM to our own child, then reaped.
        unsafe {
            libc::kill(self.0.id() as libc::pid_t, libc::SIGTERM);
        }
        let _ = self.0.wait();
    }
}

fn get(addr: &str, path: &str) -> String {
    let Ok(mut s) = TcpStream::connect(addr) else {
        return String::new();
    };
    let _ = write!(s, "GET {path} HTTP/1.0\r\nHost: {addr}\r\n\r\n");
    let mut buf = String::new();
    let _ = s.read_to_string(&mut buf);
    buf.split_once("\r\n\r\n")
        .map(|(_, b)| b.to_string())
        .unwrap_or_default()
}

fn metric(addr: &str, name: &str) -> f64 {
    get(addr, "/metrics")
        .lines()
        .find_map(|l| l.strip_prefix(&format!("{name} ")))
        .and_then(|v| v.parse().ok())
        .unwrap_or(f64::NAN)
}

/// Open file descriptors and resident memory (kB) of a process.
fn footprint(pid: u32) -> (usize, u64) {
    let fds = std::fs::read_dir(format!("/proc/{pid}/fd")).map_or(0, |d| d.count());
    let rss = std::fs::read_to_string(format!("/proc/{pid}/status"))
        .ok()
        .and_then(|s| {
            s.lines()
                .find_map(|l| l.strip_prefix("VmRSS:"))
                .and_then(|v| v.trim().trim_end_matches("kB").trim().parse().ok())
        })
        .unwrap_or(0);
    (fds, rss)
}

type Ws = tokio_tungstenite::WebSocketStream<tokio_tungstenite::MaybeTlsStream<tokio::net::TcpStream>>;

async fn ws(addr: &str, token: Option<&str>) -> Option<Ws> {
    let url = match token {
        Some(t) => format!("ws://{addr}/ws?token={t}"),
        None => format!("ws://{addr}/ws"),
    };
    tokio_tungstenite::connect_async(url).await.ok().map(|(w, _)| w)
}

async fn viewer(addr: String, stop: Arc<AtomicBool>, frames: Arc<AtomicU64>) {
    let Some(mut w) = ws(&addr, None).await else { return };
    let _ = w
        .send(Message::Text(
            json!({"type": "subscribe", "streams": ["tip"]}).to_string().into(),
        ))
        .await;
    while !stop.load(Relaxed) {
        match tokio::time::timeout(Duration::from_millis(200), w.next()).await {
            Ok(Some(Ok(_))) => {
                frames.fetch_add(1, Relaxed);
            }
            Ok(_) => return,
            Err(_) => {}
        }
    }
}

async fn loris(addr: String, stop: Arc<AtomicBool>, closed: Arc<AtomicU64>) {
    use tokio::io::{AsyncReadExt, AsyncWriteExt};
    while !stop.load(Relaxed) {
        let Ok(mut s) = tokio::net::TcpStream::connect(&addr).await else {
            tokio::time::sleep(Duration::from_millis(100)).await;
            continue;
        };
        let _ = s
            .write_all(b"GET /api/status HTTP/1.1\r\nHost: 127.0.0.1\r\nX-Slow: ")
            .await;
        let mut b = [0u8; 64];
        loop {
            if stop.load(Relaxed) {
                return;
            }
            match tokio::time::timeout(Duration::from_millis(500), s.read(&mut b)).await {
                Ok(Ok(0)) | Ok(Err(_)) => {
                    closed.fetch_add(1, Relaxed);
                    break;
                }
                // A byte now and then, as a slowloris does.
                Err(_) => {
                    let _ = s.write_all(b"x").await;
                }
                Ok(Ok(_)) => {}
            }
        }
    }
}

async fn garbage(addr: String, stop: Arc<AtomicBool>, sent: Arc<AtomicU64>) {
    let mut seed = 0x9e37_79b9_7f4a_7c15u64;
    let mut rnd = move || {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        seed
    };
    while !stop.load(Relaxed) {
        let Some(mut w) = ws(&addr, None).await else {
            tokio::time::sleep(Duration::from_millis(100)).await;
            continue;
        };
        while !stop.load(Relaxed) {
            let text = match rnd() % 5 {
                0 => (0..(rnd() % 200))
                    .map(|_| char::from(32 + (rnd() % 90) as u8))
                    .collect::<String>(),
                1 => "[\"push\",1,1,0.2,0]".to_string(),
                2 => json!({"type": "fly", "id": rnd() % 1000}).to_string(),
                3 => json!({"type": "push", "particle": 1, "distance_um": f64::NAN.to_string()}).to_string(),
                _ => "x".repeat((rnd() % 20_000) as usize),
            };
            if w.send(Message::Text(text.into())).await.is_err() {
                break;
            }
            sent.fetch_add(1, Relaxed);
            // Read whatever came back, without waiting.
            while let Ok(Some(Ok(_))) = tokio::time::timeout(Duration::from_millis(1), w.next()).await {}
            tokio::time::sleep(Duration::from_millis(5)).await;
        }
    }
}

/// The operator: holds the lease, subscribes to telemetry, sends a ping every 100 ms for `secs`;
/// returns the commands sent, the ones answered and the telemetry arrival times.
async fn operator(addr: String, secs: f64) -> (u64, u64, Vec<Instant>) {
    let mut op = ws(&addr, Some(TOKEN)).await.expect("the operator connects");
    let _ = op
        .send(Message::Text(json!({"type": "take_lease", "id": 1}).to_string().into()))
        .await;
    let _ = op
        .send(Message::Text(
            json!({"type": "subscribe", "id": 2, "streams": ["tip"]})
                .to_string()
                .into(),
        ))
        .await;
    let (mut sent, mut answered) = (0u64, std::collections::HashSet::new());
    let mut arrivals: Vec<Instant> = Vec::new();
    let end = Instant::now() + Duration::from_secs_f64(secs);
    let mut next = Instant::now();
    let mut id = 100u32;
    let answer = |t: &str, answered: &mut std::collections::HashSet<u64>| {
        if t.contains("\"ok\"")
            && let Ok(v) = serde_json::from_str::<serde_json::Value>(t)
            && let Some(i) = v["id"].as_u64()
            && i >= 100
        {
            answered.insert(i);
        }
    };
    while Instant::now() < end {
        if Instant::now() >= next {
            let _ = op
                .send(Message::Text(json!({"type": "ping", "id": id}).to_string().into()))
                .await;
            sent += 1;
            id += 1;
            next += Duration::from_millis(100);
        }
        let wait = next.saturating_duration_since(Instant::now());
        if let Ok(Some(Ok(Message::Text(t)))) = tokio::time::timeout(wait, op.next()).await {
            if t.contains("\"telemetry\"") {
                arrivals.push(Instant::now());
            } else {
                answer(&t, &mut answered);
            }
        }
    }
    // The last answers.
    let drain = Instant::now() + Duration::from_secs(2);
    while Instant::now() < drain {
        if let Ok(Some(Ok(Message::Text(t)))) = tokio::time::timeout(Duration::from_millis(100), op.next()).await {
            answer(&t, &mut answered);
        }
    }
    let _ = op.close(None).await;
    (sent, answered.len() as u64, arrivals)
}

fn main() {
    let secs: f64 = std::env::args().nth(1).and_then(|a| a.parse().ok()).unwrap_or(600.0);
    let mut child = Command::new(bin("nanopush"))
        .current_dir(workspace())
        .args(["serve", "--port", "0", "--haptic", "none", "--operator-token", TOKEN])
        .args([
            "--max-clients",
            "2000",
            "--max-clients-per-address",
            "2000",
            "--data-dir",
        ])
        .arg(std::env::temp_dir().join(format!("nanopush-soak-{}", std::process::id())))
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .expect("starting nanopush serve");
    let mut lines = BufReader::new(child.stdout.take().unwrap()).lines();
    let addr = lines
        .next()
        .unwrap()
        .unwrap()
        .trim_start_matches("nanopush serve: listening on ")
        .to_string();
    std::thread::spawn(move || for _ in lines {});
    let server = Proc(child);
    let pid = server.0.id();
    println!(
        "nanopush soak ({} build): {VIEWERS} viewers, 1 operator at 10 Hz, {LORISES} slowloris sockets, 1 garbage client, {secs} s",
        if cfg!(debug_assertions) { "debug" } else { "release" }
    );

    // Idle: the loop alone.
    std::thread::sleep(Duration::from_secs(2));
    let idle_window = 30.0;
    let o0 = metric(&addr, "nanopush_loop_overruns_total");
    std::thread::sleep(Duration::from_secs_f64(idle_window));
    let idle_overruns = metric(&addr, "nanopush_loop_overruns_total") - o0;
    let before = footprint(pid);

    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(1)
        .enable_all()
        .build()
        .unwrap();
    let stop = Arc::new(AtomicBool::new(false));
    let frames = Arc::new(AtomicU64::new(0));
    let closed = Arc::new(AtomicU64::new(0));
    let junk = Arc::new(AtomicU64::new(0));
    let (sent, answered, gaps, during, overruns) = rt.block_on(async {
        let mut tasks = Vec::new();
        for i in 0..VIEWERS {
            tasks.push(tokio::spawn(viewer(addr.clone(), stop.clone(), frames.clone())));
            if i % 32 == 31 {
                tokio::time::sleep(Duration::from_millis(20)).await;
            }
        }
        for _ in 0..LORISES {
            tasks.push(tokio::spawn(loris(addr.clone(), stop.clone(), closed.clone())));
        }
        tasks.push(tokio::spawn(garbage(addr.clone(), stop.clone(), junk.clone())));
        tokio::time::sleep(Duration::from_secs(3)).await;
        let o1 = metric(&addr, "nanopush_loop_overruns_total");
        // The operator, on a thread and runtime of its own: its measurements are not delayed by
        // the 500 viewers this process also serves.
        let (op_addr, op_secs) = (addr.clone(), secs);
        let handle = std::thread::spawn(move || {
            tokio::runtime::Builder::new_current_thread()
                .enable_all()
                .build()
                .unwrap()
                .block_on(operator(op_addr, op_secs))
        });
        let (sent, answered, arrivals) =
            tokio::task::spawn_blocking(move || handle.join().expect("the operator thread"))
                .await
                .unwrap();
        let o2 = metric(&addr, "nanopush_loop_overruns_total");
        let during = footprint(pid);
        stop.store(true, Relaxed);
        for t in tasks {
            let _ = tokio::time::timeout(Duration::from_secs(5), t).await;
        }
        let mut gaps: Vec<f64> = arrivals.windows(2).map(|w| (w[1] - w[0]).as_secs_f64()).collect();
        gaps.sort_by(f64::total_cmp);
        (sent, answered, gaps, during, o2 - o1)
    });
    drop(rt);
    std::thread::sleep(Duration::from_secs(10));
    let after = footprint(pid);
    let q = |p: f64| {
        gaps.get(((gaps.len() as f64 * p) as usize).min(gaps.len().saturating_sub(1)))
            .copied()
            .unwrap_or(f64::NAN)
    };
    let period = 1.0 / 60.0;
    println!("operator: {sent} commands sent, {answered} answered");
    println!(
        "operator telemetry: {} frames, gap p50 {:.1} ms, p99 {:.1} ms ({:+.1} ms beyond the {:.1} ms period), max {:.1} ms",
        gaps.len() + 1,
        q(0.5) * 1e3,
        q(0.99) * 1e3,
        (q(0.99) - period) * 1e3,
        period * 1e3,
        gaps.last().copied().unwrap_or(f64::NAN) * 1e3
    );
    println!(
        "viewers: {} telemetry frames in all; slowloris sockets closed by the server: {}; garbage messages sent: {}",
        frames.load(Relaxed),
        closed.load(Relaxed),
        junk.load(Relaxed)
    );
    println!(
        "server fds / RSS: before {} / {} kB, under load {} / {} kB, 10 s after {} / {} kB",
        before.0, before.1, during.0, during.1, after.0, after.1
    );
    println!(
        "loop overruns per minute: idle {:.1}, under the load {:.1}",
        idle_overruns / idle_window * 60.0,
        overruns / secs * 60.0
    );
    drop(server);
}
