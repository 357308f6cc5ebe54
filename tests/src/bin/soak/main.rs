//! `nanopush-soak`: a soak benchmark of `nanopush serve` against careless and hostile clients
//! (not a test: it measures and prints). In release, on a quiet machine:
//!
//! ```text
//! cargo build --release --workspace --bins
//! target/release/nanopush-soak [SECONDS] [--unconfined] [--allow-cpu-halt] [--alternate PHASE_S]
//! ```
//!
//! One server (`--haptic none`, the default scene); an idle window of SECONDS/2 (at least 60 s)
//! for the loop's overrun rate alone; then, for SECONDS (default 600): 500 viewers subscribed to
//! telemetry; one operator who holds the lease, subscribes to telemetry and sends a command (a
//! ping) every 100 ms; 50 slowloris sockets that each send a partial request and, once the server
//! closes them, start again; one client sending garbage (random printable text, arrays, unknown types,
//! floods past the rate limit); then a second idle window as long as the first after the clients
//! left, so that the idle rate is measured over as many ticks as the loaded one. It reports: the
//! operator's commands sent and answered, the operator's telemetry gaps (p50, p99, max, beyond the
//! period), the frames the viewers received and the frames the server skipped for a lagging
//! client, the server's open file descriptors and resident memory before the load, at its end
//! and 10 s after the clients left, and the loop's overruns per minute in each window (with how
//! many of its ticks woke over 0.5 ms late and how many computed over 0.2 ms, and the steal and
//! interrupt time of each CPU from `/proc/stat`), then the loaded rate against the idle one: the
//! goal is met when it is no higher; a binomial tail says how likely a higher one is by chance.
//!
//! `--allow-cpu-halt` passes the flag to the server (the loop's core may halt between ticks: the
//! behaviour before `serve/no_halt.rs`). `--alternate PHASE_S` runs the server so and, from this
//! process, takes the machine through three regimes in turn, PHASE_S seconds each, from start to
//! end: every core may halt; the loop's core polls (its PM QoS resume latency `n/a`, as the
//! server would set it); every core polls (`/dev/cpu_dma_latency` = 0 held, as `cyclictest`
//! does). It then restores the setting and reports each window once per regime: a comparison
//! under the same host, whose own load comes and goes over minutes (needs root).
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

mod stats;
use stats::{Regime, Regimes, Sample, Window, compare, cpu_jiffies, gaps, quantile, window};

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
    value(&get(addr, "/metrics"), name)
}

/// The value of series `name` (with its labels, if any) in a Prometheus exposition.
fn value(text: &str, name: &str) -> f64 {
    text.lines()
        .find_map(|l| l.strip_prefix(&format!("{name} ")))
        .and_then(|v| v.parse().ok())
        .unwrap_or(f64::NAN)
}

/// How many values of histogram `name` (series labels `labels`, may be empty) exceeded `le`, one
/// of its bucket bounds as the server writes it.
fn above(text: &str, name: &str, labels: &str, le: &str) -> f64 {
    let sep = if labels.is_empty() { "" } else { "," };
    value(
        text,
        &format!(
            "{name}_count{}",
            if labels.is_empty() {
                String::new()
            } else {
                format!("{{{labels}}}")
            }
        ),
    ) - value(text, &format!("{name}_bucket{{{labels}{sep}le=\"{le}\"}}"))
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

/// Puts the machine in `regime` for an alternating run: the loop core's PM QoS resume latency
/// `n/a` (0 µs: it polls, as the server keeps it) or the value found at the start (`original`),
/// and a system-wide zero latency request (`/dev/cpu_dma_latency`) held in `all` or not.
fn enter(regime: Regime, setting: &str, original: &str, all: &mut Option<std::fs::File>) {
    let value = if regime == Regime::CorePolls { "n/a" } else { original };
    if let Err(e) = std::fs::write(setting, value) {
        panic!("--alternate needs to write {setting} (root): {e}");
    }
    if regime != Regime::AllPoll {
        *all = None;
    } else if all.is_none() {
        let mut f = std::fs::OpenOptions::new()
            .write(true)
            .open("/dev/cpu_dma_latency")
            .expect("--alternate needs to write /dev/cpu_dma_latency (root)");
        f.write_all(&0i32.to_ne_bytes()).expect("writing /dev/cpu_dma_latency");
        *all = Some(f);
    }
}

/// The loop core's setting as found, written back if the run is interrupted (SIGINT, SIGTERM,
/// SIGHUP): the path and the value, prepared before the handler is installed.
static GIVE_BACK: std::sync::OnceLock<(std::ffi::CString, Vec<u8>)> = std::sync::OnceLock::new();

/// The server's pid, for the signal handler to end it too.
static SERVER_PID: std::sync::atomic::AtomicI32 = std::sync::atomic::AtomicI32::new(0);

/// Writes the setting back with async-signal-safe calls only, asks the server to end (it gives
/// its own state back), then ends the process.
extern "C" fn give_back(sig: libc::c_int) {
    let server = SERVER_PID.load(Relaxed);
    if server > 0 {
        // SAFETY: kill(2) is async-signal-safe; the pid is our child's, not yet reaped.
        unsafe { libc::kill(server, libc::SIGTERM) };
    }
    if let Some((path, value)) = GIVE_BACK.get() {
        // SAFETY: open/write/close/_exit are async-signal-safe; the buffers live forever.
        unsafe {
            let fd = libc::open(path.as_ptr(), libc::O_WRONLY);
            if fd >= 0 {
                libc::write(fd, value.as_ptr().cast(), value.len());
                libc::close(fd);
            }
        }
    }
    // SAFETY: ends the process at once, as the signal's default action would have.
    unsafe { libc::_exit(128 + sig) };
}

/// An alternating run sets the loop core's setting itself: it must give it back however the run
/// ends. On a normal end and a panic the returned guard does; on a signal, the handler.
fn give_back_at_the_end(setting: &str, original: &str) -> impl Drop {
    struct Guard(String, String);
    impl Drop for Guard {
        fn drop(&mut self) {
            let _ = std::fs::write(&self.0, &self.1);
        }
    }
    let path = std::ffi::CString::new(setting).expect("a path without NUL");
    let _ = GIVE_BACK.set((path, original.as_bytes().to_vec()));
    for sig in [libc::SIGINT, libc::SIGTERM, libc::SIGHUP] {
        // SAFETY: installs a handler that uses async-signal-safe calls only.
        unsafe { libc::signal(sig, give_back as *const () as libc::sighandler_t) };
    }
    Guard(setting.to_string(), original.to_string())
}

fn print_window(name: &str, w: &Window) {
    let ms = |v: &[f64]| v.iter().map(|x| format!("{x:.0}")).collect::<Vec<_>>().join(" / ");
    println!(
        "loop overruns {name}: {:.1} a minute ({:.0} in {:.1} min; {:.0} of them in the {} seconds the loop's vCPU was stolen from); steal {} ms a minute, interrupts {} ms a minute (CPU 0 / 1 / ...)",
        w.rate(),
        w.overruns,
        w.minutes,
        w.in_stolen_seconds,
        w.stolen_seconds,
        ms(&w.steal_ms),
        ms(&w.irq_ms)
    );
    println!(
        "  ticks that woke over 0.5 ms late: {:.0}; ticks with a phase computing over 0.2 ms: {:.0}",
        w.late, w.slow
    );
    if w.per_minute.len() > 1 {
        println!("  in each minute: {:?}", w.per_minute);
    }
}

fn print_gaps(name: &str, gaps: &[f64]) {
    let period = 1.0 / 60.0;
    let p99 = quantile(gaps, 0.99);
    println!(
        "operator telemetry{name}: {} gaps, p50 {:.1} ms, p99 {:.1} ms ({:+.1} ms beyond the {:.1} ms period), max {:.1} ms",
        gaps.len(),
        quantile(gaps, 0.5) * 1e3,
        p99 * 1e3,
        (p99 - period) * 1e3,
        period * 1e3,
        gaps.last().copied().unwrap_or(f64::NAN) * 1e3
    );
}

fn main() {
    let mut secs = 600.0;
    let mut confined = true;
    let mut server_args: Vec<&str> = Vec::new();
    let mut alternate: Option<f64> = None;
    let usage =
        "usage: nanopush-soak [SECONDS >= 10] [--unconfined] [--allow-cpu-halt] [--alternate PHASE_SECONDS >= 5]";
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        match a.as_str() {
            "--unconfined" => confined = false,
            "--allow-cpu-halt" => server_args.push("--allow-cpu-halt"),
            "--alternate" => match args.next().map(|v| v.parse::<f64>()) {
                Some(Ok(v)) if v >= 5.0 && v.is_finite() => alternate = Some(v),
                other => {
                    eprintln!("{usage}; --alternate takes a phase length in seconds, at least 5; got {other:?}");
                    std::process::exit(2);
                }
            },
            _ => match a.parse::<f64>() {
                Ok(v) if v >= 10.0 && v.is_finite() => secs = v,
                _ => {
                    eprintln!("{usage}; got {a:?}");
                    std::process::exit(2);
                }
            },
        }
    }
    if alternate.is_some() && !server_args.contains(&"--allow-cpu-halt") {
        // The server holds no request of its own: the soak's decides the regime.
        server_args.push("--allow-cpu-halt");
    }
    let ncpu = std::thread::available_parallelism().map_or(1, |n| n.get());
    let loop_cpu = ncpu - 1;
    // The loop core's setting as found: an alternating run sets it and gives it back.
    let setting = nanopush_e2e::pm_qos_setting(loop_cpu);
    let original = std::fs::read_to_string(&setting).map_or_else(|_| "0".into(), |v| v.trim().to_string());
    if alternate.is_some() {
        // Found polling, the core could not halt in the "cores may halt" regime: the comparison
        // would compare nothing. A server killed with SIGKILL leaves it so until the next one.
        if original == "n/a" {
            eprintln!(
                "--alternate: core {loop_cpu} already polls ({setting} is n/a: a server still running, or one killed \
                 with SIGKILL; see /run/nanopush/no-halt-cpu{loop_cpu}). Stop the server, or give the core back with \
                 `echo 0 > {setting}`, and start again."
            );
            std::process::exit(2);
        }
    }
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
        .args(&server_args)
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .expect("starting nanopush serve");
    SERVER_PID.store(child.id() as i32, Relaxed);
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
    let status: serde_json::Value = serde_json::from_str(&get(&addr, "/api/status")).unwrap_or_default();
    println!(
        "server: SCHED_FIFO {}, the loop's core {}",
        if status["loop"]["realtime"] == true {
            "granted"
        } else {
            "not granted"
        },
        if status["loop"]["no_halt"] == true {
            "polls (kept so by the server)"
        } else {
            "may halt (left alone by the server)"
        }
    );

    // An alternating run: this process cycles the three regimes from the start to the end, so
    // that the host's own ups and downs fall on every regime alike.
    let regimes = Arc::new(std::sync::Mutex::new(Regimes::default()));
    let alternating = Arc::new(AtomicBool::new(alternate.is_some()));
    let _give_back = alternate.map(|_| give_back_at_the_end(&setting, &original));
    let alternator = alternate.map(|phase| {
        let (regimes, alternating) = (regimes.clone(), alternating.clone());
        let (setting, original) = (setting.clone(), original.clone());
        std::thread::spawn(move || {
            let (mut all, mut next) = (None, Instant::now());
            for &regime in Regime::ALL.iter().cycle() {
                enter(regime, &setting, &original, &mut all);
                regimes.lock().unwrap().switches.push((Instant::now(), regime));
                next += Duration::from_secs_f64(phase);
                while alternating.load(Relaxed) && Instant::now() < next {
                    std::thread::sleep(Duration::from_millis(20));
                }
                if !alternating.load(Relaxed) {
                    break;
                }
            }
            // The system-wide request ends with `all`; `_give_back` restores the core's setting.
        })
    });
    if let Some(phase) = alternate {
        println!(
            "alternating every {phase} s: {}, and so on (set by this process)",
            Regime::ALL.map(Regime::name).join(", then ")
        );
    }

    // A reading every second, for the whole run.
    let samples = Arc::new(std::sync::Mutex::new(Vec::<Sample>::new()));
    let sampling = Arc::new(AtomicBool::new(true));
    let sampler = {
        let (samples, sampling, addr) = (samples.clone(), sampling.clone(), addr.clone());
        std::thread::spawn(move || {
            let mut next = Instant::now();
            while sampling.load(Relaxed) {
                let text = get(&addr, "/metrics");
                let overruns = value(&text, "nanopush_loop_overruns_total");
                let late = above(&text, "nanopush_loop_period_error_seconds", "", "5e-4");
                let slow = ["physics", "control", "publish"]
                    .iter()
                    .map(|p| {
                        above(
                            &text,
                            "nanopush_loop_compute_seconds",
                            &format!("phase=\"{p}\""),
                            "2e-4",
                        )
                    })
                    .sum();
                samples.lock().unwrap().push(Sample {
                    at: Instant::now(),
                    overruns,
                    late,
                    slow,
                    cpus: cpu_jiffies(ncpu),
                });
                next += Duration::from_secs(1);
                std::thread::sleep(next.saturating_duration_since(Instant::now()));
            }
        })
    };

    // Idle: the loop alone, before and after the load, each window half as long as the load (at
    // least a minute): the idle rate is then measured over as many ticks as the loaded one.
    let idle_window = Duration::from_secs_f64((secs / 2.0).max(60.0));
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
    alternating.store(false, Relaxed);
    if let Some(a) = alternator {
        let _ = a.join();
    }
    let samples = samples.lock().unwrap().clone();
    let regimes = regimes.lock().unwrap().clone();

    println!("operator: {sent} commands sent, {answered} answered");
    print_gaps("", &gaps(&arrivals, |_, _| true));
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
    let spans = [
        ("idle before", idle0, idle0_end),
        ("under the load", load0, load1),
        ("idle after", idle1, idle1_end),
    ];
    // Every second, or (alternating) the seconds of one regime.
    let regime_names: Vec<(String, Option<Regime>)> = if alternate.is_some() {
        Regime::ALL
            .iter()
            .map(|&r| (format!(" ({})", r.name()), Some(r)))
            .collect()
    } else {
        vec![(String::new(), None)]
    };
    for (suffix, regime) in &regime_names {
        let (suffix, regime) = (suffix.as_str(), *regime);
        let keep = |a: Instant, b: Instant| regime.is_none_or(|r| regimes.within(a, b, r));
        if regime.is_some() {
            print_gaps(suffix, &gaps(&arrivals, keep));
        }
        let w: Vec<Window> = spans
            .iter()
            .map(|&(name, from, to)| {
                let w = window(&samples, from, to, loop_cpu, keep);
                print_window(&format!("{name}{suffix}"), &w);
                w
            })
            .collect();
        println!(
            "loop overruns loaded against idle{suffix}: {}",
            compare(&w[1], &[&w[0], &w[2]])
        );
    }
    drop(server);
}
