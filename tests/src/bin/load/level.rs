//! One level: a fresh server, N viewers connected and subscribed, a measuring window with a
//! reading every second, the figures from the difference of its two ends, then SIGTERM with
//! every viewer still connected.

use std::sync::Arc;
use std::sync::atomic::Ordering::Relaxed;
use std::time::{Duration, Instant};

use serde_json::Value;
use tokio::sync::{Semaphore, mpsc};
use tokio::task::JoinHandle;

use crate::cpu::{CpuSample, cpu_sample, find_thread, other_realtime_threads, thread_core};
use crate::prometheus::{Scrape, Window};
use crate::server::{Server, http_get};
use crate::viewers::{Stats, counters, viewer};
use crate::{CONNECT_CONCURRENCY, GOAL_P99_S, Opts};

/// The loop's period-error histogram.
const PERIOD_ERROR: &str = "nanopush_loop_period_error_seconds";

/// What one level of viewers measured.
#[derive(Debug, Default)]
pub struct Level {
    pub viewers: usize,
    pub connected: usize,
    pub connect_errors: Vec<String>,
    pub connect_s: f64,
    pub window_s: f64,
    pub realtime: Option<f64>,
    pub other_rt: Vec<String>,
    // Period error over the window (s).
    pub p50: Option<f64>,
    pub p99: Option<f64>,
    pub max_bucket: Option<(f64, f64)>,
    pub mean: Option<f64>,
    pub over_goal: u64,
    pub hist_ticks: u64,
    pub max_life: Option<f64>,
    pub overruns: f64,
    pub ticks: f64,
    pub compute_p99: [Option<f64>; 3],
    // Delivery, per client over the window.
    pub rate_mean: f64,
    pub rate_min: f64,
    pub rate_max: f64,
    pub skipped: u64,
    pub lagged_clients: usize,
    pub closed_in_window: usize,
    pub server_sent_rate: f64,
    pub server_dropped: f64,
    // CPU over the window, in cores.
    pub cpu_server: f64,
    pub cpu_loop: f64,
    pub loop_nvcsw: u64,
    pub cpu_bench: f64,
    pub cpu_other: f64,
    pub cpu_steal: f64,
    pub loop_core: Option<usize>,
    pub core_steal_ms: f64,
    pub core_irq_ms: f64,
    pub timeline: Vec<Second>,
    // Shutdown.
    pub stop_s: f64,
    pub exit_code: Option<i32>,
    pub killed: bool,
    pub got_shutdown: usize,
    pub got_close: usize,
    pub log_problems: (usize, Vec<String>),
}

/// One second of the window.
#[derive(Debug, Clone, Copy)]
pub struct Second {
    /// End of the second, from the window's start (s).
    pub t: f64,
    pub overruns: f64,
    /// Ticks later than the goal (20 µs).
    pub over_goal: u64,
    /// The bucket holding the second's largest period error.
    pub max_bucket: Option<(f64, f64)>,
    /// Steal and irq + softirq time on the loop's core (ms).
    pub core_steal_ms: f64,
    pub core_irq_ms: f64,
}

impl Second {
    /// The second that ends `dt` s into the window, between two readings.
    fn between(dt: f64, (m0, cpu0): (&Scrape, &CpuSample), (m1, cpu1): (&Scrape, &CpuSample)) -> Second {
        let w = Window::between(&m0.buckets(PERIOD_ERROR, None), &m1.buckets(PERIOD_ERROR, None));
        let overruns = m1.value("nanopush_loop_overruns_total").unwrap_or(0.0)
            - m0.value("nanopush_loop_overruns_total").unwrap_or(0.0);
        Second {
            t: dt,
            overruns,
            over_goal: w.above(GOAL_P99_S),
            max_bucket: w.max_bucket(),
            core_steal_ms: (cpu1.core_steal - cpu0.core_steal) * 1e3,
            core_irq_ms: (cpu1.core_irq - cpu0.core_irq) * 1e3,
        }
    }
}

/// One end of the window: the scrape, the viewers' counters and the CPU times.
struct Reading {
    metrics: Scrape,
    clients: Vec<(u64, u64, bool)>,
    cpu: CpuSample,
}

/// Measures one level of `n` viewers.
pub async fn run_level(o: &Opts, n: usize) -> Result<Level, String> {
    let mut lv = Level {
        viewers: n,
        ..Level::default()
    };
    let mut server = Server::start(o, n)?;
    let pid = server.pid();
    lv.other_rt = other_realtime_threads(pid);
    let addr: Arc<str> = server.addr.clone().into();
    eprintln!("nanopush-load: {n} viewers: server pid {pid} on {addr}; connecting …");
    let (stats, tasks) = connect_viewers(&mut lv, &addr).await?;
    let (start, end, status) = measure(o, &mut lv, &addr, pid, &stats).await?;
    loop_figures(&mut lv, &start.metrics, &end.metrics, &status);
    delivery_figures(&mut lv, &start, &end);
    cpu_figures(&mut lv, &start.cpu, &end.cpu);
    shut_down(&mut lv, &mut server, &stats, &tasks).await;
    Ok(lv)
}

/// Starts the level's viewers and waits (120 s at most) until each has subscribed or failed;
/// an Err when none could.
async fn connect_viewers(lv: &mut Level, addr: &Arc<str>) -> Result<(Vec<Arc<Stats>>, Vec<JoinHandle<()>>), String> {
    let n = lv.viewers;
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
    Ok((stats, tasks))
}

/// The window, from right after every viewer is subscribed: a scrape every second (a timeline
/// of overruns and late ticks against the loop core's steal and interrupt time, in
/// `lv.timeline`); the last one ends the window. Its two ends and `/api/status` after it.
async fn measure(
    o: &Opts,
    lv: &mut Level,
    addr: &str,
    pid: u32,
    stats: &[Arc<Stats>],
) -> Result<(Reading, Reading, Value), String> {
    let m0 = Scrape::parse(&http_get(addr, "/metrics").await?);
    let loop_tid = find_thread(pid, "control-loop");
    lv.loop_core = loop_tid.and_then(|t| thread_core(pid, t));
    let c0 = counters(stats);
    let cpu0 = cpu_sample(pid, loop_tid, lv.loop_core);
    let t0 = Instant::now();
    eprintln!(
        "nanopush-load: {} viewers: {} subscribed in {:.1} s; measuring {} s …",
        lv.viewers, lv.connected, lv.connect_s, o.seconds
    );
    let (mut prev_m, mut prev_cpu) = (Scrape(m0.0.clone()), cpu0);
    let mut k = 1.0_f64;
    let end = loop {
        let at = k.min(o.seconds);
        tokio::time::sleep_until((t0 + Duration::from_secs_f64(at)).into()).await;
        let c = counters(stats);
        let cpu = cpu_sample(pid, loop_tid, lv.loop_core);
        let dt = t0.elapsed().as_secs_f64();
        let m = Scrape::parse(&http_get(addr, "/metrics").await?);
        lv.timeline.push(Second::between(dt, (&prev_m, &prev_cpu), (&m, &cpu)));
        if at >= o.seconds {
            lv.window_s = dt;
            break Reading {
                metrics: m,
                clients: c,
                cpu,
            };
        }
        (prev_m, prev_cpu) = (m, cpu);
        k += 1.0;
    };
    let status: Value = serde_json::from_str(&http_get(addr, "/api/status").await?).unwrap_or(Value::Null);
    let start = Reading {
        metrics: m0,
        clients: c0,
        cpu: cpu0,
    };
    Ok((start, end, status))
}

/// The loop over the window: the period error's bounds, its mean, overruns, ticks, whether it
/// ran SCHED_FIFO, and each phase's compute-time p99 bound.
fn loop_figures(lv: &mut Level, m0: &Scrape, m1: &Scrape, status: &Value) {
    let w = Window::between(&m0.buckets(PERIOD_ERROR, None), &m1.buckets(PERIOD_ERROR, None));
    lv.p50 = w.quantile_bound(0.5);
    lv.p99 = w.quantile_bound(0.99);
    lv.max_bucket = w.max_bucket();
    lv.hist_ticks = w.total();
    lv.over_goal = w.above(GOAL_P99_S);
    let d = |name: &str| m1.value(name).unwrap_or(0.0) - m0.value(name).unwrap_or(0.0);
    if lv.hist_ticks > 0 {
        lv.mean = Some(d(&format!("{PERIOD_ERROR}_sum")) / lv.hist_ticks as f64);
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
}

/// Delivery over the window: telemetry rates per client (of the viewers that subscribed), frames
/// skipped, clients lagged or closed, and what the server counted sent and dropped.
fn delivery_figures(lv: &mut Level, start: &Reading, end: &Reading) {
    let dt = lv.window_s;
    let (c0, c1) = (&start.clients, &end.clients);
    let mut rates = Vec::new();
    for ((t0c, s0, _), (t1c, s1, closed)) in c0.iter().zip(c1) {
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
    let subscribed: Vec<f64> = rates.iter().zip(c0).filter(|(_, c)| !c.2).map(|(r, _)| *r).collect();
    if !subscribed.is_empty() {
        lv.rate_mean = subscribed.iter().sum::<f64>() / subscribed.len() as f64;
        lv.rate_min = subscribed.iter().copied().fold(f64::INFINITY, f64::min);
        lv.rate_max = subscribed.iter().copied().fold(0.0, f64::max);
    }
    let d = |name: &str| end.metrics.value(name).unwrap_or(0.0) - start.metrics.value(name).unwrap_or(0.0);
    lv.server_sent_rate = d("nanopush_telemetry_sent_total") / dt / lv.connected.max(1) as f64;
    lv.server_dropped = d("nanopush_dropped_frames_total");
}

/// CPU over the window, in cores: the server, its loop thread, this benchmark, everything else
/// and steal; and the steal and interrupt time on the loop's core.
fn cpu_figures(lv: &mut Level, cpu0: &CpuSample, cpu1: &CpuSample) {
    let dt = lv.window_s;
    lv.cpu_server = (cpu1.server - cpu0.server) / dt;
    lv.cpu_loop = (cpu1.loop_thread - cpu0.loop_thread) / dt;
    lv.loop_nvcsw = cpu1.loop_nvcsw.saturating_sub(cpu0.loop_nvcsw);
    lv.cpu_bench = (cpu1.bench - cpu0.bench) / dt;
    let busy = (cpu1.busy - cpu0.busy) / dt;
    lv.cpu_other = (busy - lv.cpu_server - lv.cpu_bench).max(0.0);
    lv.cpu_steal = (cpu1.steal - cpu0.steal) / dt;
    lv.core_steal_ms = (cpu1.core_steal - cpu0.core_steal) * 1e3;
    lv.core_irq_ms = (cpu1.core_irq - cpu0.core_irq) * 1e3;
}

/// Stops the server with every viewer still connected, and sees them told: `shutdown` and a
/// close frame (3 s at most for every viewer to close); then the server log's problems.
async fn shut_down(lv: &mut Level, server: &mut Server, stats: &[Arc<Stats>], tasks: &[JoinHandle<()>]) {
    eprintln!("nanopush-load: {} viewers: SIGTERM …", lv.viewers);
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
    for t in tasks {
        t.abort();
    }
    lv.log_problems = server.log_problems();
}
