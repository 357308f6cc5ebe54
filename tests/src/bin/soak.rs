//! `nanopush-soak`: a soak benchmark of `nanopush serve` against careless and hostile clients
//! (not a test: it measures and prints). In release, on a quiet machine:
//!
//! ```text
//! cargo build --release --workspace --bins
//! target/release/nanopush-soak [SECONDS] [--unconfined]      # default 600
//! ```
//!
//! One server (`--haptic none`, the default scene); an idle window of 60 s for the loop's overrun
//! rate alone; then, for SECONDS: 500 viewers subscribed to telemetry; one operator who holds the
//! lease, subscribes to telemetry and sends a command (a ping) every 100 ms; 50 slowloris sockets
//! that each send a partial request and, once the server closes them, start again; one client
//! sending garbage (random bytes, arrays, unknown types, floods past the rate limit); then a
//! second idle window of 60 s after the clients left. It reports: the operator's commands sent and
//! answered, the operator's telemetry gaps (p50, p99, max, beyond the period), the frames the
//! viewers received and the frames the server skipped for a lagging client, the server's open file
//! descriptors and resident memory before the load, at its end and 10 s after
//! the clients left, and the loop's overruns per minute in each window, split by whether the
//! hypervisor took time from the loop's vCPU in that second (steal in `/proc/stat`).
//!
//! The clients run on the same machine as the server, where a lab's would not. By default they
//! are confined as if they were elsewhere: this process is kept off the loop's core (the last
//! one, as the server chooses), the load's threads run at nice 19, and the operator, the probe
//! that measures, runs at SCHED_FIFO 10 (when granted) so that its own measurement does not wait
//! behind the load it generates. `--unconfined` runs everything as ordinary threads on every
//! core, for comparison.

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

/// The CPUs other than `cpu` for the calling thread and the threads it starts afterwards.
fn avoid_cpu(cpu: usize, ncpu: usize) -> bool {
    // SAFETY: a zeroed cpu_set_t is a valid empty set; CPU_SET and sched_setaffinity act on the
    // calling thread with a set of the size we pass.
    unsafe {
        let mut set: libc::cpu_set_t = std::mem::zeroed();
        for c in (0..ncpu).filter(|&c| c != cpu) {
            libc::CPU_SET(c, &mut set);
        }
        libc::sched_setaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &set) == 0
    }
}

/// One second's reading: the loop's overruns so far, and the jiffies the loop's vCPU spent
/// stolen by the hypervisor, in interrupts and in softirqs so far (`/proc/stat`).
#[derive(Debug, Clone, Copy)]
struct Sample {
    at: Instant,
    overruns: f64,
    steal: u64,
    irq: u64,
}

fn cpu_jiffies(cpu: usize) -> (u64, u64) {
    let stat = std::fs::read_to_string("/proc/stat").unwrap_or_default();
    let line = stat
        .lines()
        .find(|l| l.starts_with(&format!("cpu{cpu} ")))
        .unwrap_or_default();
    let f: Vec<u64> = line.split_whitespace().skip(1).filter_map(|v| v.parse().ok()).collect();
    // user nice system idle iowait irq softirq steal
    let at = |i: usize| f.get(i).copied().unwrap_or(0);
    (at(7), at(5) + at(6))
}

/// Overruns per minute over the samples between `from` and `to`, and the share of them that
/// fell in seconds when the loop's vCPU was stolen from; the steal and interrupt time (ms a minute).
struct Window {
    minutes: f64,
    overruns: f64,
    in_stolen_seconds: f64,
    stolen_seconds: usize,
    steal_ms: f64,
    irq_ms: f64,
    /// Overruns in each whole minute of the window.
    per_minute: Vec<f64>,
}

fn window(samples: &[Sample], from: Instant, to: Instant) -> Window {
    let w: Vec<&Sample> = samples.iter().filter(|s| s.at >= from && s.at <= to).collect();
    let jiffy_ms = 1e3 / unsafe { libc::sysconf(libc::_SC_CLK_TCK) } as f64;
    let (mut overruns, mut in_stolen, mut stolen_seconds) = (0.0, 0.0, 0);
    let mut per_minute = vec![0.0; ((to - from).as_secs_f64() / 60.0).floor() as usize];
    for p in w.windows(2) {
        let d = p[1].overruns - p[0].overruns;
        overruns += d;
        if let Some(m) = per_minute.get_mut(((p[1].at - from).as_secs_f64() / 60.0) as usize) {
            *m += d;
        }
        if p[1].steal > p[0].steal {
            in_stolen += d;
            stolen_seconds += 1;
        }
    }
    let (first, last) = (w.first(), w.last());
    let minutes = match (first, last) {
        (Some(a), Some(b)) => (b.at - a.at).as_secs_f64() / 60.0,
        _ => f64::NAN,
    };
    let span = |f: fn(&Sample) -> u64| match (first, last) {
        (Some(a), Some(b)) => (f(b) - f(a)) as f64 * jiffy_ms / minutes,
        _ => f64::NAN,
    };
    Window {
        minutes,
        overruns,
        in_stolen_seconds: in_stolen,
        stolen_seconds,
        steal_ms: span(|s| s.steal),
        irq_ms: span(|s| s.irq),
        per_minute,
    }
}

fn main() {
    let mut secs = 600.0;
    let mut confined = true;
    for a in std::env::args().skip(1) {
        match a.as_str() {
            "--unconfined" => confined = false,
            _ => match a.parse::<f64>() {
                Ok(v) if v >= 10.0 && v.is_finite() => secs = v,
                _ => {
                    eprintln!("usage: nanopush-soak [SECONDS >= 10] [--unconfined]; got {a:?}");
                    std::process::exit(2);
                }
            },
        }
    }
    let ncpu = std::thread::available_parallelism().map_or(1, |n| n.get());
    let loop_cpu = ncpu - 1;
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
    // The server is started first: it inherits this process's CPUs.
    let confined = confined && ncpu > 1 && avoid_cpu(loop_cpu, ncpu);
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
        "nanopush soak ({} build): {VIEWERS} viewers, 1 operator at 10 Hz, {LORISES} slowloris sockets, 1 garbage client, {secs} s; clients {}",
        if cfg!(debug_assertions) { "debug" } else { "release" },
        if confined {
            format!("confined (off the loop's core {loop_cpu}, load at nice 19, the operator probe at SCHED_FIFO 10)")
        } else {
            "unconfined (every core, ordinary threads)".to_string()
        }
    );

    // A reading every second, for the whole run.
    let samples = Arc::new(std::sync::Mutex::new(Vec::<Sample>::new()));
    let sampling = Arc::new(AtomicBool::new(true));
    let sampler = {
        let (samples, sampling, addr) = (samples.clone(), sampling.clone(), addr.clone());
        std::thread::spawn(move || {
            let mut next = Instant::now();
            while sampling.load(Relaxed) {
                let overruns = metric(&addr, "nanopush_loop_overruns_total");
                let (steal, irq) = cpu_jiffies(loop_cpu);
                samples.lock().unwrap().push(Sample {
                    at: Instant::now(),
                    overruns,
                    steal,
                    irq,
                });
                next += Duration::from_secs(1);
                std::thread::sleep(next.saturating_duration_since(Instant::now()));
            }
        })
    };

    // Idle: the loop alone.
    let idle_window = Duration::from_secs(60);
    std::thread::sleep(Duration::from_secs(2));
    let idle0 = Instant::now();
    std::thread::sleep(idle_window);
    let idle0_end = Instant::now();
    let before = footprint(pid);

    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(1)
        .on_thread_start(move || {
            if confined {
                // SAFETY: sets the calling thread's nice value.
                unsafe { libc::setpriority(libc::PRIO_PROCESS, 0, 19) };
            }
        })
        .enable_all()
        .build()
        .unwrap();
    let stop = Arc::new(AtomicBool::new(false));
    let frames = Arc::new(AtomicU64::new(0));
    let closed = Arc::new(AtomicU64::new(0));
    let junk = Arc::new(AtomicU64::new(0));
    let (sent, answered, arrivals, load, during) = rt.block_on(async {
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
        let dropped0 = metric(&addr, "nanopush_dropped_frames_total");
        let load0 = Instant::now();
        // The operator, on a thread and runtime of its own: its measurements are not delayed by
        // the 500 viewers this process also serves.
        let (op_addr, op_secs) = (addr.clone(), secs);
        let handle = std::thread::spawn(move || {
            if confined {
                let p = libc::sched_param { sched_priority: 10 };
                // SAFETY: sets the calling thread's policy with a valid parameter.
                if unsafe { libc::sched_setscheduler(0, libc::SCHED_FIFO, &p) } != 0 {
                    println!("the operator probe runs SCHED_OTHER: SCHED_FIFO was refused");
                }
            }
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
        let load = (load0, Instant::now());
        let dropped = metric(&addr, "nanopush_dropped_frames_total") - dropped0;
        let during = footprint(pid);
        stop.store(true, Relaxed);
        for t in tasks {
            let _ = tokio::time::timeout(Duration::from_secs(5), t).await;
        }
        (sent, answered, arrivals, (load, dropped), during)
    });
    drop(rt);
    std::thread::sleep(Duration::from_secs(10));
    let after = footprint(pid);
    let idle1 = Instant::now();
    std::thread::sleep(idle_window);
    let idle1_end = Instant::now();
    sampling.store(false, Relaxed);
    let _ = sampler.join();
    let samples = samples.lock().unwrap().clone();

    let mut gaps: Vec<f64> = arrivals.windows(2).map(|w| (w[1] - w[0]).as_secs_f64()).collect();
    gaps.sort_by(f64::total_cmp);
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
    let ((load0, load1), dropped) = load;
    println!(
        "viewers: {} telemetry frames received, {dropped} skipped by a lagging client while the operator ran; slowloris sockets closed by the server: {}; garbage messages sent: {}",
        frames.load(Relaxed),
        closed.load(Relaxed),
        junk.load(Relaxed)
    );
    println!(
        "server fds / RSS: before {} / {} kB, under load {} / {} kB, 10 s after {} / {} kB",
        before.0, before.1, during.0, during.1, after.0, after.1
    );
    for (name, w) in [
        ("idle before", window(&samples, idle0, idle0_end)),
        ("under the load", window(&samples, load0, load1)),
        ("idle after", window(&samples, idle1, idle1_end)),
    ] {
        println!(
            "loop overruns {name}: {:.1} a minute ({:.0} in {:.1} min; {:.0} of them in the {} seconds the loop's vCPU was stolen from); steal {:.0} ms a minute, interrupts {:.0} ms a minute",
            w.overruns / w.minutes,
            w.overruns,
            w.minutes,
            w.in_stolen_seconds,
            w.stolen_seconds,
            w.steal_ms,
            w.irq_ms
        );
        if w.per_minute.len() > 1 {
            println!("  in each minute: {:?}", w.per_minute);
        }
    }
    drop(server);
}
