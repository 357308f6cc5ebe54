//! `nanopush-load`: a load benchmark of `nanopush serve`. A benchmark, not a test: it measures
//! and prints, and asserts nothing about timing.
//!
//! For each level of viewers it starts a fresh server (so the server's histograms and maximum
//! cover that level only), connects N WebSocket viewers that subscribe to `tip`, scrapes
//! `/metrics` once every viewer is subscribed and again at the end of the measuring window, and
//! reports from the difference of the two scrapes: the control loop's period error (p50 and p99
//! as bucket upper bounds, the bucket holding the largest value, the mean), overruns and ticks;
//! per client, the telemetry rate delivered and the frames skipped (`lagged`). The maximum from
//! `/api/status` covers the server's whole life, connection setup included. Then it sends the
//! server SIGTERM and waits for it.
//!
//! The viewers run in this process on one tokio current-thread runtime: the benchmark shares the
//! machine's cores with the server it measures, and its figures include that cost. The CPU time
//! of the server, of its control-loop thread, of this process and of everything else on the
//! machine over the window is read from `/proc` and printed with the figures.

use std::collections::BTreeSet;
use std::io::{BufRead, BufReader};
use std::path::PathBuf;
use std::process::{Child, Command, Stdio};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering::Relaxed};
use std::time::{Duration, Instant};

use futures_util::{SinkExt, StreamExt};
use serde_json::{Value, json};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::sync::{Semaphore, mpsc};
use tokio_tungstenite::tungstenite::Message;

const TOKEN: &str = "nanopush-load-operator-token";
/// Viewers connecting at once (the rest wait their turn).
const CONNECT_CONCURRENCY: usize = 32;
/// The period-error threshold the README's goal names (s); a bucket bound of the histogram.
const GOAL_P99_S: f64 = 20e-6;

const USAGE: &str = "\
nanopush-load: load benchmark of `nanopush serve` (a benchmark: it asserts nothing)

Usage: nanopush-load [--viewers 50,200,500] [--seconds 30] [--rate-hz 1000]
                     [--server target/release/nanopush] [--allow-cpu-halt] [--json]

  --viewers LIST   levels of WebSocket viewers, comma-separated (a fresh server for each;
                   0 is a baseline: the server alone)
  --seconds S      measuring window per level, after every viewer has subscribed (default 30)
  --rate-hz HZ     control loop rate passed to the server (default 1000)
  --server PATH    the nanopush binary (default: this workspace's target/release/nanopush)
  --allow-cpu-halt passed to the server: idle cores may halt (no zero CPU latency request)
  --json           print one JSON document instead of tables (progress still goes to stderr)
";

#[derive(Debug, Clone)]
struct Opts {
    viewers: Vec<usize>,
    seconds: f64,
    rate_hz: f64,
    server: PathBuf,
    allow_cpu_halt: bool,
    json: bool,
}

fn parse_args() -> Result<Opts, String> {
    let mut o = Opts {
        viewers: vec![50, 200, 500],
        seconds: 30.0,
        rate_hz: 1000.0,
        server: nanopush_e2e::workspace().join("target/release/nanopush"),
        allow_cpu_halt: false,
        json: false,
    };
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        let (key, inline) = match a.split_once('=') {
            Some((k, v)) => (k.to_string(), Some(v.to_string())),
            None => (a.clone(), None),
        };
        let mut value = |name: &str| {
            inline
                .clone()
                .or_else(|| args.next())
                .ok_or_else(|| format!("{name} needs a value\n\n{USAGE}"))
        };
        match key.as_str() {
            "--viewers" => {
                o.viewers = value("--viewers")?
                    .split(',')
                    .map(|v| v.trim().parse::<usize>().map_err(|e| format!("--viewers {v:?}: {e}")))
                    .collect::<Result<_, _>>()?;
            }
            "--seconds" => o.seconds = value("--seconds")?.parse().map_err(|e| format!("--seconds: {e}"))?,
            "--rate-hz" => o.rate_hz = value("--rate-hz")?.parse().map_err(|e| format!("--rate-hz: {e}"))?,
            "--server" => o.server = PathBuf::from(value("--server")?),
            "--allow-cpu-halt" => o.allow_cpu_halt = true,
            "--json" => o.json = true,
            "-h" | "--help" => {
                print!("{USAGE}");
                std::process::exit(0);
            }
            _ => return Err(format!("unknown argument {a:?}\n\n{USAGE}")),
        }
    }
    if o.viewers.is_empty() || o.viewers.iter().any(|&n| n > 1900) {
        return Err("--viewers: each level must be in [0, 1900] (the server runs with --max-clients 2000)".into());
    }
    if !(1.0..=3600.0).contains(&o.seconds) {
        return Err(format!("--seconds {} is out of range; allowed: [1, 3600]", o.seconds));
    }
    if !(100.0..=10_000.0).contains(&o.rate_hz) {
        return Err(format!(
            "--rate-hz {} is out of range; allowed: [100, 10000]",
            o.rate_hz
        ));
    }
    if !o.server.exists() {
        return Err(format!(
            "no server binary at {}; build it with `cargo build --release -p nanopush` or pass --server",
            o.server.display()
        ));
    }
    Ok(o)
}

// ---------------------------------------------------------------------------------------------
// The server process.

/// A `nanopush serve` on a free port in a scratch directory; killed (if still running) and its
/// directory removed on drop.
struct Server {
    child: Child,
    addr: String,
    dir: PathBuf,
}

impl Server {
    fn start(o: &Opts, viewers: usize) -> Result<Server, String> {
        let dir = std::env::temp_dir().join(format!("nanopush-load-{}-{viewers}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).map_err(|e| format!("creating {}: {e}", dir.display()))?;
        let log = std::fs::File::create(dir.join("server.log")).map_err(|e| format!("creating the server log: {e}"))?;
        let mut child = Command::new(&o.server)
            .current_dir(nanopush_e2e::workspace())
            .args([
                "serve",
                "--port",
                "0",
                "--haptic",
                "none",
                "--max-clients",
                "2000",
                "--max-clients-per-address",
                "2000",
            ])
            .args([
                "--operator-token",
                TOKEN,
                "--rate-hz",
                &o.rate_hz.to_string(),
                "--data-dir",
            ])
            .arg(dir.join("records"))
            .args(o.allow_cpu_halt.then_some("--allow-cpu-halt"))
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(log)
            .spawn()
            .map_err(|e| format!("starting {}: {e}", o.server.display()))?;
        let out = child.stdout.take().expect("stdout is piped");
        let mut lines = BufReader::new(out).lines();
        let first = lines.next().and_then(Result::ok).unwrap_or_default();
        let Some(addr) = first.strip_prefix("nanopush serve: listening on ") else {
            let _ = child.kill();
            let _ = child.wait();
            let log = std::fs::read_to_string(dir.join("server.log")).unwrap_or_default();
            return Err(format!(
                "the server did not start (first line {first:?}); its log:\n{log}"
            ));
        };
        let addr = addr.trim().to_string();
        std::thread::spawn(move || for _ in lines {});
        Ok(Server { child, addr, dir })
    }

    fn pid(&self) -> u32 {
        self.child.id()
    }

    /// SIGTERM, then wait (30 s at most, then SIGKILL): the time to exit and the exit code.
    async fn stop(&mut self) -> (f64, Option<i32>, bool) {
        let t = Instant::now();
        // SAFETY: kill(2) on our own child's pid, which has not been waited for (so not reused).
        unsafe {
            libc::kill(self.child.id() as libc::pid_t, libc::SIGTERM);
        }
        loop {
            match self.child.try_wait() {
                Ok(Some(status)) => return (t.elapsed().as_secs_f64(), status.code(), false),
                Ok(None) if t.elapsed() < Duration::from_secs(30) => {
                    tokio::time::sleep(Duration::from_millis(10)).await;
                }
                _ => {
                    let _ = self.child.kill();
                    let code = self.child.wait().ok().and_then(|s| s.code());
                    return (t.elapsed().as_secs_f64(), code, true);
                }
            }
        }
    }

    /// The server log's WARN and ERROR lines (distinct messages, first few), and how many.
    fn log_problems(&self) -> (usize, Vec<String>) {
        let log = std::fs::read_to_string(self.dir.join("server.log")).unwrap_or_default();
        let bad: Vec<&str> = log
            .lines()
            .filter(|l| l.contains(" WARN ") || l.contains(" ERROR "))
            .collect();
        let mut distinct = BTreeSet::new();
        for l in &bad {
            // Drop the timestamp so repeated messages collapse.
            let msg = l.split_once(' ').map_or(*l, |(_, rest)| rest).trim();
            distinct.insert(msg.to_string());
        }
        (bad.len(), distinct.into_iter().take(5).collect())
    }
}

impl Drop for Server {
    fn drop(&mut self) {
        if matches!(self.child.try_wait(), Ok(None)) {
            let _ = self.child.kill();
            let _ = self.child.wait();
        }
        let _ = std::fs::remove_dir_all(&self.dir);
    }
}

/// A plain HTTP/1.1 GET: the body of a 200 answer.
async fn http_get(addr: &str, path: &str) -> Result<String, String> {
    let fetch = async {
        let mut s = tokio::net::TcpStream::connect(addr).await?;
        s.write_all(format!("GET {path} HTTP/1.1\r\nHost: {addr}\r\nConnection: close\r\n\r\n").as_bytes())
            .await?;
        let mut buf = Vec::new();
        s.read_to_end(&mut buf).await?;
        Ok::<_, std::io::Error>(buf)
    };
    let buf = tokio::time::timeout(Duration::from_secs(10), fetch)
        .await
        .map_err(|_| format!("GET {path}: no answer in 10 s"))?
        .map_err(|e| format!("GET {path}: {e}"))?;
    let head_end = buf
        .windows(4)
        .position(|w| w == b"\r\n\r\n")
        .ok_or_else(|| format!("GET {path}: no HTTP header"))?;
    let head = String::from_utf8_lossy(&buf[..head_end]).to_ascii_lowercase();
    let status = head.split_whitespace().nth(1).unwrap_or("");
    if status != "200" {
        return Err(format!("GET {path}: HTTP {status}"));
    }
    let mut body = buf[head_end + 4..].to_vec();
    if head.contains("transfer-encoding: chunked") {
        body = dechunk(&body);
    }
    String::from_utf8(body).map_err(|e| format!("GET {path}: {e}"))
}

fn dechunk(mut b: &[u8]) -> Vec<u8> {
    let mut out = Vec::new();
    while let Some(eol) = b.windows(2).position(|w| w == b"\r\n") {
        let n = std::str::from_utf8(&b[..eol])
            .ok()
            .and_then(|s| usize::from_str_radix(s.trim(), 16).ok())
            .unwrap_or(0);
        if n == 0 || b.len() < eol + 2 + n {
            break;
        }
        out.extend_from_slice(&b[eol + 2..eol + 2 + n]);
        b = &b[(eol + 4 + n).min(b.len())..];
    }
    out
}

// ---------------------------------------------------------------------------------------------
// Prometheus text.

/// One scrape: (metric name, label text inside the braces, value).
struct Scrape(Vec<(String, String, f64)>);

impl Scrape {
    fn parse(text: &str) -> Scrape {
        let mut v = Vec::new();
        for line in text.lines() {
            let line = line.trim();
            if line.is_empty() || line.starts_with('#') {
                continue;
            }
            let Some((series, value)) = line.rsplit_once(' ') else {
                continue;
            };
            let value = match value {
                "+Inf" => f64::INFINITY,
                "-Inf" => f64::NEG_INFINITY,
                x => match x.parse() {
                    Ok(x) => x,
                    Err(_) => continue,
                },
            };
            let (name, labels) = match series.split_once('{') {
                Some((n, l)) => (n, l.trim_end_matches('}')),
                None => (series, ""),
            };
            v.push((name.to_string(), labels.to_string(), value));
        }
        Scrape(v)
    }

    /// An unlabelled series.
    fn value(&self, name: &str) -> Option<f64> {
        self.0.iter().find(|(n, l, _)| n == name && l.is_empty()).map(|s| s.2)
    }

    /// A histogram's cumulative buckets `(le, count)`, in exposition order; `phase` selects the
    /// series of a labelled family.
    fn buckets(&self, base: &str, phase: Option<&str>) -> Vec<(f64, f64)> {
        let name = format!("{base}_bucket");
        self.0
            .iter()
            .filter(|(n, l, _)| *n == name && phase.is_none_or(|p| label(l, "phase").as_deref() == Some(p)))
            .filter_map(|(_, l, v)| {
                let le = label(l, "le")?;
                let le = if le == "+Inf" { f64::INFINITY } else { le.parse().ok()? };
                Some((le, *v))
            })
            .collect()
    }
}

fn label(labels: &str, key: &str) -> Option<String> {
    labels.split(',').find_map(|kv| {
        let (k, v) = kv.split_once('=')?;
        (k.trim() == key).then(|| v.trim().trim_matches('"').to_string())
    })
}

/// A histogram over the window: counts per bucket (not cumulative), with the buckets' upper
/// bounds; bucket i holds values in (bounds[i-1], bounds[i]].
#[derive(Debug, Default)]
struct Window {
    bounds: Vec<f64>,
    counts: Vec<u64>,
}

impl Window {
    /// The difference of two scrapes of the same histogram.
    fn between(start: &[(f64, f64)], end: &[(f64, f64)]) -> Window {
        let mut w = Window::default();
        let mut prev = 0.0;
        for (i, &(le, cum)) in end.iter().enumerate() {
            let before = start.get(i).filter(|s| s.0 == le).map_or(0.0, |s| s.1);
            let d = (cum - before).max(0.0);
            w.bounds.push(le);
            w.counts.push((d - prev).max(0.0).round() as u64);
            prev = d;
        }
        w
    }

    fn total(&self) -> u64 {
        self.counts.iter().sum()
    }

    /// Upper bound of the bucket holding quantile `q`.
    fn quantile_bound(&self, q: f64) -> Option<f64> {
        let total = self.total();
        if total == 0 {
            return None;
        }
        let target = ((q * total as f64).ceil() as u64).max(1);
        let mut acc = 0;
        for (c, b) in self.counts.iter().zip(&self.bounds) {
            acc += c;
            if acc >= target {
                return Some(*b);
            }
        }
        self.bounds.last().copied()
    }

    /// The bucket holding the largest value: (lower bound, upper bound].
    fn max_bucket(&self) -> Option<(f64, f64)> {
        let i = self.counts.iter().rposition(|&c| c > 0)?;
        let lo = if i == 0 { 0.0 } else { self.bounds[i - 1] };
        Some((lo, self.bounds[i]))
    }

    /// Values above `x` (a bucket bound).
    fn above(&self, x: f64) -> u64 {
        self.counts
            .iter()
            .zip(&self.bounds)
            .filter(|(_, b)| **b > x * (1.0 + 1e-9))
            .map(|(c, _)| c)
            .sum()
    }
}

// ---------------------------------------------------------------------------------------------
// CPU time from /proc.

fn clk_tck() -> f64 {
    // SAFETY: sysconf with a valid name has no preconditions.
    let t = unsafe { libc::sysconf(libc::_SC_CLK_TCK) };
    if t > 0 { t as f64 } else { 100.0 }
}

/// The fields of a /proc/…/stat line after the command name (field 3, the state, is index 0).
fn stat_fields(path: &str) -> Option<Vec<String>> {
    let s = std::fs::read_to_string(path).ok()?;
    let rest = &s[s.rfind(')')? + 1..];
    Some(rest.split_whitespace().map(str::to_string).collect())
}

/// utime + stime (s) of a process or thread.
fn cpu_seconds(path: &str) -> Option<f64> {
    let f = stat_fields(path)?;
    let ut: f64 = f.get(11)?.parse().ok()?;
    let st: f64 = f.get(12)?.parse().ok()?;
    Some((ut + st) / clk_tck())
}

/// The thread of `pid` named `name`.
fn find_thread(pid: u32, name: &str) -> Option<u32> {
    std::fs::read_dir(format!("/proc/{pid}/task"))
        .ok()?
        .flatten()
        .find_map(|e| {
            let tid: u32 = e.file_name().to_str()?.parse().ok()?;
            let comm = std::fs::read_to_string(format!("/proc/{pid}/task/{tid}/comm")).ok()?;
            (comm.trim() == name).then_some(tid)
        })
}

/// A line's value from /proc/…/status.
fn status_field(path: &str, key: &str) -> Option<u64> {
    let s = std::fs::read_to_string(path).ok()?;
    s.lines()
        .find_map(|l| l.strip_prefix(key)?.trim_start_matches(':').trim().parse().ok())
}

/// Machine-wide CPU time from /proc/stat's first line: (busy, steal), in seconds.
fn machine_cpu() -> Option<(f64, f64)> {
    let s = std::fs::read_to_string("/proc/stat").ok()?;
    let line = s.lines().next()?.strip_prefix("cpu ")?;
    let v: Vec<f64> = line.split_whitespace().filter_map(|x| x.parse().ok()).collect();
    // user nice system idle iowait irq softirq steal (guest time is inside user).
    let total: f64 = v.iter().take(8).sum();
    let idle = v.get(3)? + v.get(4)?;
    let steal = *v.get(7)?;
    let t = clk_tck();
    Some(((total - idle) / t, steal / t))
}

/// One core's CPU time from /proc/stat: (irq + softirq, steal), in seconds.
fn core_cpu(core: usize) -> Option<(f64, f64)> {
    let s = std::fs::read_to_string("/proc/stat").ok()?;
    let prefix = format!("cpu{core} ");
    let line = s.lines().find_map(|l| l.strip_prefix(prefix.as_str()))?;
    let v: Vec<f64> = line.split_whitespace().filter_map(|x| x.parse().ok()).collect();
    let t = clk_tck();
    Some(((v.get(5)? + v.get(6)?) / t, v.get(7)? / t))
}

/// The core a thread last ran on (the loop is pinned, so its core).
fn thread_core(pid: u32, tid: u32) -> Option<usize> {
    stat_fields(&format!("/proc/{pid}/task/{tid}/stat"))?
        .get(36)?
        .parse()
        .ok()
}

#[derive(Debug, Clone, Copy, Default)]
struct CpuSample {
    server: f64,
    loop_thread: f64,
    loop_nvcsw: u64,
    bench: f64,
    busy: f64,
    steal: f64,
    core_irq: f64,
    core_steal: f64,
}

fn cpu_sample(pid: u32, loop_tid: Option<u32>, core: Option<usize>) -> CpuSample {
    let (busy, steal) = machine_cpu().unwrap_or_default();
    let (core_irq, core_steal) = core.and_then(core_cpu).unwrap_or_default();
    let task = loop_tid.map(|t| format!("/proc/{pid}/task/{t}"));
    CpuSample {
        server: cpu_seconds(&format!("/proc/{pid}/stat")).unwrap_or(0.0),
        loop_thread: task
            .as_ref()
            .and_then(|t| cpu_seconds(&format!("{t}/stat")))
            .unwrap_or(0.0),
        loop_nvcsw: task
            .as_ref()
            .and_then(|t| status_field(&format!("{t}/status"), "nonvoluntary_ctxt_switches"))
            .unwrap_or(0),
        bench: cpu_seconds("/proc/self/stat").unwrap_or(0.0),
        busy,
        steal,
        core_irq,
        core_steal,
    }
}

/// User-space threads running SCHED_FIFO or SCHED_RR outside `except` (pid): "pid/comm".
fn other_realtime_threads(except: u32) -> Vec<String> {
    let mut out = Vec::new();
    let Ok(procs) = std::fs::read_dir("/proc") else {
        return out;
    };
    for p in procs.flatten() {
        let Some(pid) = p.file_name().to_str().and_then(|s| s.parse::<u32>().ok()) else {
            continue;
        };
        // Kernel threads have an empty command line.
        if pid == except || std::fs::read(format!("/proc/{pid}/cmdline")).map_or(true, |c| c.is_empty()) {
            continue;
        }
        let Ok(tasks) = std::fs::read_dir(format!("/proc/{pid}/task")) else {
            continue;
        };
        for t in tasks.flatten() {
            let path = format!("/proc/{pid}/task/{}/stat", t.file_name().to_string_lossy());
            // Field 41 (policy) is index 38 after the name; 1 = SCHED_FIFO, 2 = SCHED_RR.
            if let Some(f) = stat_fields(&path)
                && matches!(f.get(38).map(String::as_str), Some("1" | "2"))
            {
                let comm = std::fs::read_to_string(format!("/proc/{pid}/comm")).unwrap_or_default();
                out.push(format!("{pid}/{}", comm.trim()));
                break;
            }
        }
    }
    out
}

// ---------------------------------------------------------------------------------------------
// The viewers.

type Ws = tokio_tungstenite::WebSocketStream<tokio_tungstenite::MaybeTlsStream<tokio::net::TcpStream>>;

/// What one viewer received (counters only grow; the window takes differences).
#[derive(Debug, Default)]
struct Stats {
    telemetry: AtomicU64,
    lagged: AtomicU64,
    skipped: AtomicU64,
    other: AtomicU64,
    shutdown: AtomicBool,
    close_frame: AtomicBool,
    closed: AtomicBool,
}

impl Stats {
    fn take(&self, text: &str) {
        // The fast path: serde writes the tag first.
        if text.starts_with(r#"{"type":"telemetry""#) {
            self.telemetry.fetch_add(1, Relaxed);
            return;
        }
        let v: Value = serde_json::from_str(text).unwrap_or(Value::Null);
        match v["type"].as_str() {
            Some("telemetry") => {
                self.telemetry.fetch_add(1, Relaxed);
            }
            Some("lagged") => {
                self.lagged.fetch_add(1, Relaxed);
                self.skipped.fetch_add(v["skipped"].as_u64().unwrap_or(0), Relaxed);
            }
            Some("shutdown") => self.shutdown.store(true, Relaxed),
            _ => {
                self.other.fetch_add(1, Relaxed);
            }
        }
    }
}

/// Connects, subscribes to `tip` and waits for the `ok`.
async fn connect_and_subscribe(addr: &str, stats: &Stats) -> Result<Ws, String> {
    let url = format!("ws://{addr}/ws");
    let mut attempt = 0;
    let mut ws = loop {
        match tokio::time::timeout(Duration::from_secs(10), tokio_tungstenite::connect_async(url.as_str())).await {
            Ok(Ok((ws, _))) => break ws,
            Ok(Err(e)) if attempt >= 5 => return Err(format!("connecting: {e}")),
            Ok(Err(_)) => {
                attempt += 1;
                tokio::time::sleep(Duration::from_millis(50 * attempt)).await;
            }
            Err(_) => return Err("connecting: no upgrade within 10 s".into()),
        }
    };
    let sub = json!({"type": "subscribe", "streams": ["tip"], "id": 1}).to_string();
    ws.send(Message::Text(sub.into()))
        .await
        .map_err(|e| format!("subscribing: {e}"))?;
    let wait_ok = async {
        while let Some(m) = ws.next().await {
            let Ok(Message::Text(t)) = m else { continue };
            let v: Value = serde_json::from_str(t.as_str()).unwrap_or(Value::Null);
            match v["type"].as_str() {
                Some("ok") if v["id"] == 1 => return Ok(()),
                Some("error") => return Err(format!("subscribe refused: {t}")),
                _ => stats.take(t.as_str()),
            }
        }
        Err("closed before the subscription was confirmed".to_string())
    };
    tokio::time::timeout(Duration::from_secs(10), wait_ok)
        .await
        .map_err(|_| "no ok to the subscription within 10 s".to_string())??;
    Ok(ws)
}

async fn viewer(
    addr: Arc<str>,
    stats: Arc<Stats>,
    gate: Arc<Semaphore>,
    ready: mpsc::UnboundedSender<Result<(), String>>,
) {
    let permit = gate.acquire_owned().await;
    let ws = connect_and_subscribe(&addr, &stats).await;
    drop(permit);
    let mut ws = match ws {
        Ok(ws) => ws,
        Err(e) => {
            stats.closed.store(true, Relaxed);
            let _ = ready.send(Err(e));
            return;
        }
    };
    let _ = ready.send(Ok(()));
    while let Some(m) = ws.next().await {
        match m {
            Ok(Message::Text(t)) => stats.take(t.as_str()),
            Ok(Message::Close(_)) => {
                stats.close_frame.store(true, Relaxed);
                break;
            }
            Err(_) => break,
            Ok(_) => {}
        }
    }
    stats.closed.store(true, Relaxed);
}

// ---------------------------------------------------------------------------------------------
// One level.

#[derive(Debug, Default)]
struct Level {
    viewers: usize,
    connected: usize,
    connect_errors: Vec<String>,
    connect_s: f64,
    window_s: f64,
    realtime: Option<f64>,
    other_rt: Vec<String>,
    // Period error over the window (s).
    p50: Option<f64>,
    p99: Option<f64>,
    max_bucket: Option<(f64, f64)>,
    mean: Option<f64>,
    over_goal: u64,
    hist_ticks: u64,
    max_life: Option<f64>,
    overruns: f64,
    ticks: f64,
    compute_p99: [Option<f64>; 3],
    // Delivery, per client over the window.
    rate_mean: f64,
    rate_min: f64,
    rate_max: f64,
    skipped: u64,
    lagged_clients: usize,
    closed_in_window: usize,
    server_sent_rate: f64,
    server_dropped: f64,
    // CPU over the window, in cores.
    cpu_server: f64,
    cpu_loop: f64,
    loop_nvcsw: u64,
    cpu_bench: f64,
    cpu_other: f64,
    cpu_steal: f64,
    loop_core: Option<usize>,
    core_steal_ms: f64,
    core_irq_ms: f64,
    timeline: Vec<Second>,
    // Shutdown.
    stop_s: f64,
    exit_code: Option<i32>,
    killed: bool,
    got_shutdown: usize,
    got_close: usize,
    log_problems: (usize, Vec<String>),
}

/// One second of the window.
#[derive(Debug, Clone, Copy)]
struct Second {
    /// End of the second, from the window's start (s).
    t: f64,
    overruns: f64,
    /// Ticks later than the goal (20 µs).
    over_goal: u64,
    /// The bucket holding the second's largest period error.
    max_bucket: Option<(f64, f64)>,
    /// Steal and irq + softirq time on the loop's core (ms).
    core_steal_ms: f64,
    core_irq_ms: f64,
}

fn counters(stats: &[Arc<Stats>]) -> Vec<(u64, u64, bool)> {
    stats
        .iter()
        .map(|s| {
            (
                s.telemetry.load(Relaxed),
                s.skipped.load(Relaxed),
                s.closed.load(Relaxed),
            )
        })
        .collect()
}

async fn run_level(o: &Opts, n: usize) -> Result<Level, String> {
    let mut lv = Level {
        viewers: n,
        ..Level::default()
    };
    let mut server = Server::start(o, n)?;
    let pid = server.pid();
    lv.other_rt = other_realtime_threads(pid);
    let addr: Arc<str> = server.addr.clone().into();
    eprintln!("nanopush-load: {n} viewers: server pid {pid} on {addr}; connecting …");

    let stats: Vec<Arc<Stats>> = (0..n).map(|_| Arc::new(Stats::default())).collect();
    let gate = Arc::new(Semaphore::new(CONNECT_CONCURRENCY));
    let (tx, mut rx) = mpsc::unbounded_channel();
    let t_connect = Instant::now();
    let tasks: Vec<_> = stats
        .iter()
        .map(|s| tokio::spawn(viewer(addr.clone(), s.clone(), gate.clone(), tx.clone())))
        .collect();
    drop(tx);
    for _ in 0..n {
        match tokio::time::timeout(Duration::from_secs(120), rx.recv()).await {
            Ok(Some(Ok(()))) => lv.connected += 1,
            Ok(Some(Err(e))) => lv.connect_errors.push(e),
            Ok(None) => break,
            Err(_) => {
                lv.connect_errors.push("gave up waiting for viewers after 120 s".into());
                break;
            }
        }
    }
    lv.connect_s = t_connect.elapsed().as_secs_f64();
    if lv.connected == 0 && n > 0 {
        for t in &tasks {
            t.abort();
        }
        return Err(format!("no viewer could connect: {:?}", lv.connect_errors.first()));
    }

    // The window: from right after every viewer is subscribed.
    let m0 = Scrape::parse(&http_get(&addr, "/metrics").await?);
    let loop_tid = find_thread(pid, "control-loop");
    lv.loop_core = loop_tid.and_then(|t| thread_core(pid, t));
    let c0 = counters(&stats);
    let cpu0 = cpu_sample(pid, loop_tid, lv.loop_core);
    let t0 = Instant::now();
    eprintln!(
        "nanopush-load: {n} viewers: {} subscribed in {:.1} s; measuring {} s …",
        lv.connected, lv.connect_s, o.seconds
    );
    // A scrape every second (a timeline of overruns and late ticks against the loop core's
    // steal and interrupt time); the last one ends the window.
    let base = "nanopush_loop_period_error_seconds";
    let (mut prev_m, mut prev_cpu) = (Scrape(m0.0.clone()), cpu0);
    let mut k = 1.0_f64;
    let (c1, cpu1, dt, m1) = loop {
        let at = k.min(o.seconds);
        tokio::time::sleep_until((t0 + Duration::from_secs_f64(at)).into()).await;
        let c = counters(&stats);
        let cpu = cpu_sample(pid, loop_tid, lv.loop_core);
        let dt = t0.elapsed().as_secs_f64();
        let m = Scrape::parse(&http_get(&addr, "/metrics").await?);
        let w = Window::between(&prev_m.buckets(base, None), &m.buckets(base, None));
        let overruns = m.value("nanopush_loop_overruns_total").unwrap_or(0.0)
            - prev_m.value("nanopush_loop_overruns_total").unwrap_or(0.0);
        lv.timeline.push(Second {
            t: dt,
            overruns,
            over_goal: w.above(GOAL_P99_S),
            max_bucket: w.max_bucket(),
            core_steal_ms: (cpu.core_steal - prev_cpu.core_steal) * 1e3,
            core_irq_ms: (cpu.core_irq - prev_cpu.core_irq) * 1e3,
        });
        if at >= o.seconds {
            break (c, cpu, dt, m);
        }
        (prev_m, prev_cpu) = (m, cpu);
        k += 1.0;
    };
    let status: Value = serde_json::from_str(&http_get(&addr, "/api/status").await?).unwrap_or(Value::Null);
    lv.window_s = dt;

    // The loop.
    let w = Window::between(&m0.buckets(base, None), &m1.buckets(base, None));
    lv.p50 = w.quantile_bound(0.5);
    lv.p99 = w.quantile_bound(0.99);
    lv.max_bucket = w.max_bucket();
    lv.hist_ticks = w.total();
    lv.over_goal = w.above(GOAL_P99_S);
    let d = |name: &str| m1.value(name).unwrap_or(0.0) - m0.value(name).unwrap_or(0.0);
    if lv.hist_ticks > 0 {
        lv.mean = Some(d(&format!("{base}_sum")) / lv.hist_ticks as f64);
    }
    lv.max_life = status["loop"]["period_error_max_s"].as_f64();
    lv.overruns = d("nanopush_loop_overruns_total");
    lv.ticks = d("nanopush_loop_ticks_total");
    lv.realtime = m1.value("nanopush_loop_realtime");
    for (i, phase) in ["control", "physics", "publish"].iter().enumerate() {
        let c = "nanopush_loop_compute_seconds";
        lv.compute_p99[i] =
            Window::between(&m0.buckets(c, Some(phase)), &m1.buckets(c, Some(phase))).quantile_bound(0.99);
    }

    // Delivery.
    let mut rates = Vec::new();
    for ((t0c, s0, _), (t1c, s1, closed)) in c0.iter().zip(&c1) {
        if *closed {
            lv.closed_in_window += 1;
        }
        rates.push((t1c - t0c) as f64 / dt);
        lv.skipped += s1 - s0;
        if s1 > s0 {
            lv.lagged_clients += 1;
        }
    }
    // Only the viewers that subscribed count towards the rate.
    let subscribed: Vec<f64> = rates.iter().zip(&c0).filter(|(_, c)| !c.2).map(|(r, _)| *r).collect();
    if !subscribed.is_empty() {
        lv.rate_mean = subscribed.iter().sum::<f64>() / subscribed.len() as f64;
        lv.rate_min = subscribed.iter().copied().fold(f64::INFINITY, f64::min);
        lv.rate_max = subscribed.iter().copied().fold(0.0, f64::max);
    }
    lv.server_sent_rate = d("nanopush_telemetry_sent_total") / dt / lv.connected.max(1) as f64;
    lv.server_dropped = d("nanopush_dropped_frames_total");

    // CPU, in cores.
    lv.cpu_server = (cpu1.server - cpu0.server) / dt;
    lv.cpu_loop = (cpu1.loop_thread - cpu0.loop_thread) / dt;
    lv.loop_nvcsw = cpu1.loop_nvcsw.saturating_sub(cpu0.loop_nvcsw);
    lv.cpu_bench = (cpu1.bench - cpu0.bench) / dt;
    let busy = (cpu1.busy - cpu0.busy) / dt;
    lv.cpu_other = (busy - lv.cpu_server - lv.cpu_bench).max(0.0);
    lv.cpu_steal = (cpu1.steal - cpu0.steal) / dt;
    lv.core_steal_ms = (cpu1.core_steal - cpu0.core_steal) * 1e3;
    lv.core_irq_ms = (cpu1.core_irq - cpu0.core_irq) * 1e3;

    // Stop the server with every viewer still connected, and see them told.
    eprintln!("nanopush-load: {n} viewers: SIGTERM …");
    let (stop_s, code, killed) = server.stop().await;
    lv.stop_s = stop_s;
    lv.exit_code = code;
    lv.killed = killed;
    let until = Instant::now() + Duration::from_secs(3);
    while Instant::now() < until && stats.iter().any(|s| !s.closed.load(Relaxed)) {
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    lv.got_shutdown = stats.iter().filter(|s| s.shutdown.load(Relaxed)).count();
    lv.got_close = stats.iter().filter(|s| s.close_frame.load(Relaxed)).count();
    for t in &tasks {
        t.abort();
    }
    lv.log_problems = server.log_problems();
    Ok(lv)
}

// ---------------------------------------------------------------------------------------------
// Output.

/// Seconds in µs / ms / s, up to two decimals, trailing zeros dropped.
fn dur(s: f64) -> String {
    let (v, unit) = if !s.is_finite() {
        return "∞".into();
    } else if s < 1e-3 {
        (s * 1e6, "µs")
    } else if s < 1.0 {
        (s * 1e3, "ms")
    } else {
        (s, "s")
    };
    let t = format!("{v:.2}");
    let t = t.trim_end_matches('0').trim_end_matches('.');
    format!("{t} {unit}")
}

fn opt_dur(s: Option<f64>) -> String {
    match s {
        Some(s) if s.is_finite() => dur(s),
        Some(_) => "> 100 ms".into(),
        None => "-".into(),
    }
}

fn bucket(b: Option<(f64, f64)>) -> String {
    match b {
        Some((lo, hi)) if hi.is_finite() => format!("{}-{}", dur(lo), dur(hi)),
        Some((lo, _)) => format!("> {}", dur(lo)),
        None => "-".into(),
    }
}

fn print_tables(o: &Opts, cpus: usize, levels: &[Level]) {
    println!(
        "nanopush-load: {cpus} CPUs; control loop at {} Hz; {} s window per level; a fresh server per level.",
        o.rate_hz, o.seconds
    );
    println!(
        "The viewers run in this process (one tokio current-thread runtime) on the same {cpus} cores as the server."
    );
    println!();
    println!(
        "Loop period error over the window (from the /metrics difference). p50 and p99 are bucket upper bounds \
         (nanopush_loop_period_error_seconds resolution); \"max, window\" is the bucket holding the largest value; \
         \"max, life\" is /api/status loop.period_error_max_s, the server's whole life, connection setup included."
    );
    println!();
    println!(
        "| viewers | p50 ≤ | p99 ≤ | max, window | max, life | mean | ticks > 20 µs | overruns | ticks | realtime |"
    );
    println!("|---:|---:|---:|---:|---:|---:|---:|---:|---:|:---:|");
    for l in levels {
        println!(
            "| {} | {} | {} | {} | {} | {} | {} | {} | {} | {} |",
            l.viewers,
            opt_dur(l.p50),
            opt_dur(l.p99),
            bucket(l.max_bucket),
            opt_dur(l.max_life),
            opt_dur(l.mean),
            l.over_goal,
            l.overruns,
            l.ticks,
            match l.realtime {
                Some(1.0) => "SCHED_FIFO",
                Some(_) => "no",
                None => "?",
            }
        );
    }
    println!();
    println!(
        "Telemetry delivered per client over the window (counted by the viewers; the server sends ~60 Hz). \
         \"server sent\" is nanopush_telemetry_sent_total per client; skipped is the sum of lagged.skipped. \
         After the window the server gets SIGTERM with every viewer connected: how many were sent `shutdown` \
         and a close frame, and how long the server took to exit."
    );
    println!();
    println!(
        "| viewers | subscribed | connect s | mean Hz | min Hz | max Hz | server sent Hz | skipped | clients lagged | closed early | shutdown told | close frame | exit s |"
    );
    println!("|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|");
    for l in levels {
        println!(
            "| {} | {} | {:.1} | {:.2} | {:.2} | {:.2} | {:.2} | {} | {} | {} | {}/{} | {}/{} | {:.2}{} |",
            l.viewers,
            l.connected,
            l.connect_s,
            l.rate_mean,
            l.rate_min,
            l.rate_max,
            l.server_sent_rate,
            l.skipped,
            l.lagged_clients,
            l.closed_in_window,
            l.got_shutdown,
            l.connected,
            l.got_close,
            l.connected,
            l.stop_s,
            if l.killed { " (killed)" } else { "" }
        );
    }
    println!();
    println!(
        "CPU over the window, in cores (of {cpus}): the server, its control-loop thread, this benchmark, everything \
         else; hypervisor steal (ms, all cores), and steal and irq+softirq time (ms) on the loop's core (/proc/stat, \
         10 ms resolution); the loop thread's involuntary context switches; compute-time p99 bounds per phase."
    );
    println!();
    println!(
        "| viewers | server | loop thread | bench | other | steal ms | loop core | its steal ms | its irq ms | loop preempted | control p99 ≤ | physics p99 ≤ | publish p99 ≤ |"
    );
    println!("|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|");
    for l in levels {
        println!(
            "| {} | {:.2} | {:.2} | {:.2} | {:.2} | {:.0} | {} | {:.0} | {:.0} | {} | {} | {} | {} |",
            l.viewers,
            l.cpu_server,
            l.cpu_loop,
            l.cpu_bench,
            l.cpu_other,
            l.cpu_steal * l.window_s * 1e3,
            l.loop_core.map_or("?".to_string(), |c| c.to_string()),
            l.core_steal_ms,
            l.core_irq_ms,
            l.loop_nvcsw,
            opt_dur(l.compute_p99[0]),
            opt_dur(l.compute_p99[1]),
            opt_dur(l.compute_p99[2]),
        );
    }
    println!();
    for l in levels {
        println!("{}", timeline_summary(l));
    }
    let mut notes = Vec::new();
    for l in levels {
        if !l.connect_errors.is_empty() {
            notes.push(format!(
                "{} viewers: {} failed to connect, e.g. {}",
                l.viewers,
                l.connect_errors.len(),
                l.connect_errors[0]
            ));
        }
        if !l.other_rt.is_empty() {
            notes.push(format!(
                "{} viewers: other real-time (SCHED_FIFO/RR) processes were running: {}",
                l.viewers,
                l.other_rt.join(", ")
            ));
        }
        if l.log_problems.0 > 0 {
            notes.push(format!(
                "{} viewers: the server logged {} WARN/ERROR lines, e.g. {}",
                l.viewers,
                l.log_problems.0,
                l.log_problems.1.join(" | ")
            ));
        }
        if l.exit_code != Some(0) {
            notes.push(format!(
                "{} viewers: the server exited with {:?}",
                l.viewers, l.exit_code
            ));
        }
    }
    if !notes.is_empty() {
        println!();
        for n in notes {
            println!("note: {n}");
        }
    }
}

/// Per level: the seconds of the window with an overrun or a tick late by more than 1 ms, and
/// whether the loop's core saw steal in them.
fn timeline_summary(l: &Level) -> String {
    let late = |s: &Second| s.max_bucket.is_some_and(|(lo, _)| lo >= 1e-3);
    let bad: Vec<&Second> = l.timeline.iter().filter(|s| s.overruns > 0.0 || late(s)).collect();
    let stolen = bad.iter().filter(|s| s.core_steal_ms > 0.0).count();
    let stolen_all = l.timeline.iter().filter(|s| s.core_steal_ms > 0.0).count();
    let worst = l
        .timeline
        .iter()
        .max_by(|a, b| {
            let x = a.max_bucket.map_or(0.0, |m| m.0);
            let y = b.max_bucket.map_or(0.0, |m| m.0);
            x.total_cmp(&y)
        })
        .map_or(String::new(), |s| {
            format!(
                "; the worst in the second ending at {:.0} s ({}, {} over 20 µs)",
                s.t,
                bucket(s.max_bucket),
                s.over_goal
            )
        });
    format!(
        "{} viewers: {} of {} seconds had an overrun or a tick > 1 ms late, {} of them with steal on the loop's core \
         (steal in {} seconds in all){worst}.",
        l.viewers,
        bad.len(),
        l.timeline.len(),
        stolen,
        stolen_all,
    )
}

fn level_json(l: &Level) -> Value {
    json!({
        "viewers": l.viewers,
        "subscribed": l.connected,
        "connect_errors": l.connect_errors,
        "connect_s": l.connect_s,
        "window_s": l.window_s,
        "realtime": l.realtime,
        "other_realtime_processes": l.other_rt,
        "period_error": {
            "note": "p50/p99 are bucket upper bounds over the window; max_bucket_s is the (lower, upper] bucket of the window's largest; max_life_s is /api/status over the whole server life",
            "p50_bound_s": l.p50,
            "p99_bound_s": l.p99,
            "max_bucket_s": l.max_bucket.map(|(lo, hi)| json!([lo, hi.is_finite().then_some(hi)])),
            "max_life_s": l.max_life,
            "mean_s": l.mean,
            "ticks_over_20us": l.over_goal,
            "ticks": l.hist_ticks,
        },
        "overruns": l.overruns,
        "ticks": l.ticks,
        "compute_p99_bound_s": {"control": l.compute_p99[0], "physics": l.compute_p99[1], "publish": l.compute_p99[2]},
        "telemetry_per_client_hz": {"mean": l.rate_mean, "min": l.rate_min, "max": l.rate_max},
        "server_sent_per_client_hz": l.server_sent_rate,
        "skipped": l.skipped,
        "server_dropped_frames": l.server_dropped,
        "clients_lagged": l.lagged_clients,
        "closed_in_window": l.closed_in_window,
        "cpu_cores": {"server": l.cpu_server, "loop_thread": l.cpu_loop, "bench": l.cpu_bench, "other": l.cpu_other, "steal": l.cpu_steal},
        "loop_involuntary_switches": l.loop_nvcsw,
        "loop_core": l.loop_core,
        "loop_core_steal_ms": l.core_steal_ms,
        "loop_core_irq_softirq_ms": l.core_irq_ms,
        "timeline": l.timeline.iter().map(|s| json!({
            "t_s": s.t,
            "overruns": s.overruns,
            "ticks_over_20us": s.over_goal,
            "max_bucket_s": s.max_bucket.map(|(lo, hi)| json!([lo, hi.is_finite().then_some(hi)])),
            "loop_core_steal_ms": s.core_steal_ms,
            "loop_core_irq_softirq_ms": s.core_irq_ms,
        })).collect::<Vec<_>>(),
        "shutdown": {"exit_s": l.stop_s, "exit_code": l.exit_code, "killed": l.killed, "clients_told": l.got_shutdown, "clients_closed_cleanly": l.got_close},
        "server_log_problems": {"count": l.log_problems.0, "examples": l.log_problems.1},
    })
}

fn main() {
    let o = match parse_args() {
        Ok(o) => o,
        Err(e) => {
            eprintln!("nanopush-load: {e}");
            std::process::exit(2);
        }
    };
    let cpus = std::thread::available_parallelism().map_or(1, usize::from);
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .expect("building the tokio runtime");
    let mut levels = Vec::new();
    for (i, &n) in o.viewers.iter().enumerate() {
        if i > 0 {
            // Let the previous level's sockets and threads go.
            std::thread::sleep(Duration::from_secs(2));
        }
        match rt.block_on(run_level(&o, n)) {
            Ok(l) => levels.push(l),
            Err(e) => {
                eprintln!("nanopush-load: {n} viewers: {e}");
                std::process::exit(1);
            }
        }
    }
    if o.json {
        let doc = json!({
            "schema": "nanopush-load",
            "version": 1,
            "cpus": cpus,
            "rate_hz": o.rate_hz,
            "seconds": o.seconds,
            "note": "the viewers run in this process, on the same cores as the server",
            "levels": levels.iter().map(level_json).collect::<Vec<_>>(),
        });
        println!("{}", serde_json::to_string_pretty(&doc).expect("serializing"));
    } else {
        print_tables(&o, cpus, &levels);
    }
}
