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
//! behaviour before `server/src/no_halt.rs`). `--alternate PHASE_S` runs the server so and, from this
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

mod alternate;
mod clients;
mod stats;

use std::process::{Child, Command, Stdio};
use std::sync::atomic::{AtomicBool, Ordering::Relaxed};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use nanopush_e2e::{bin, workspace};

use alternate::{SERVER_PID, give_back_at_the_end};
use clients::{Load, run_load};
use stats::{Regime, Regimes, Sample, Window, compare, cpu_jiffies, gaps, quantile, window};

const TOKEN: &str = "nanopush-soak-operator";
const VIEWERS: usize = 500;
const LORISES: usize = 50;

/// The server, sent SIGTERM and waited for when dropped, however long it takes: not killed
/// outright, which would leave its loop's core polling (`nanopush_e2e::stop`).
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

/// The body of a GET of `path` from the server, whatever its status; empty when it does not
/// answer.
fn get(addr: &str, path: &str) -> String {
    nanopush_e2e::client::get(addr, path)
        .map(|(_, body)| String::from_utf8_lossy(&body).into_owned())
        .unwrap_or_default()
}

/// Series `name` of the server's `/metrics` now (NaN when missing).
fn metric(addr: &str, name: &str) -> f64 {
    value(&get(addr, "/metrics"), name)
}

/// The value of series `name` (with its labels, if any) in a Prometheus exposition, NaN when
/// missing.
fn value(text: &str, name: &str) -> f64 {
    nanopush_e2e::metrics::series(text, name).unwrap_or(f64::NAN)
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
    let rss = nanopush_e2e::procfs::status_field(&format!("/proc/{pid}/status"), "VmRSS").unwrap_or(0);
    (fds, rss)
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

/// The command line.
struct Opts {
    /// The load's length (s).
    secs: f64,
    /// The clients kept off the loop's core, the load at nice 19, the operator at SCHED_FIFO 10.
    confined: bool,
    server_args: Vec<&'static str>,
    /// `--alternate`'s phase length (s).
    alternate: Option<f64>,
}

/// The options from the command line; exits 2 with the usage on a bad one.
fn parse_args() -> Opts {
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
    Opts {
        secs,
        confined,
        server_args,
        alternate,
    }
}

/// The loop core's PM QoS setting and its value as found: an alternating run sets it and gives
/// it back. Found polling, the core could not halt in the "cores may halt" regime: the comparison
/// would compare nothing, and an alternating run exits 2 (a server killed with SIGKILL leaves it
/// so until the next one).
fn loop_core_setting(loop_cpu: usize, alternating: bool) -> (String, String) {
    let setting = nanopush_e2e::pm_qos_setting(loop_cpu);
    let original = std::fs::read_to_string(&setting).map_or_else(|_| "0".into(), |v| v.trim().to_string());
    if alternating && original == "n/a" {
        eprintln!(
            "--alternate: core {loop_cpu} already polls ({setting} is n/a: a server still running, or one killed \
             with SIGKILL; see /run/nanopush/no-halt-cpu{loop_cpu}). Stop the server, or give the core back with \
             `echo 0 > {setting}`, and start again."
        );
        std::process::exit(2);
    }
    (setting, original)
}

/// Starts `nanopush serve` (no haptic link, room for the load's clients, `server_args`), its pid
/// kept for the signal handler; its stdout piped (its address comes first).
fn spawn_server(server_args: &[&str]) -> Child {
    let child = Command::new(bin("nanopush"))
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
        .args(server_args)
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .expect("starting nanopush serve");
    SERVER_PID.store(child.id() as i32, Relaxed);
    child
}

/// What is run, and what the server was granted.
fn print_header(secs: f64, confined: bool, loop_cpu: usize, addr: &str) {
    println!(
        "nanopush soak ({} build): {VIEWERS} viewers, 1 operator at 10 Hz, {LORISES} slowloris sockets, 1 garbage client, {secs} s; clients {}",
        if cfg!(debug_assertions) { "debug" } else { "release" },
        if confined {
            format!("confined (off the loop's core {loop_cpu}, load at nice 19, the operator probe at SCHED_FIFO 10)")
        } else {
            "unconfined (every core, ordinary threads)".to_string()
        }
    );
    let status: serde_json::Value = serde_json::from_str(&get(addr, "/api/status")).unwrap_or_default();
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
}

/// A reading every second, for the whole run, on a thread of its own.
struct Sampler {
    samples: Arc<Mutex<Vec<Sample>>>,
    sampling: Arc<AtomicBool>,
    thread: std::thread::JoinHandle<()>,
}

impl Sampler {
    /// Starts reading the server's loop counters at `addr` and the `ncpu` CPUs' times.
    fn start(addr: &str, ncpu: usize) -> Sampler {
        let samples = Arc::new(Mutex::new(Vec::<Sample>::new()));
        let sampling = Arc::new(AtomicBool::new(true));
        let thread = {
            let (samples, sampling, addr) = (samples.clone(), sampling.clone(), addr.to_string());
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
        Sampler {
            samples,
            sampling,
            thread,
        }
    }

    /// Stops reading: every sample taken.
    fn stop(self) -> Vec<Sample> {
        self.sampling.store(false, Relaxed);
        let _ = self.thread.join();
        self.samples.lock().unwrap().clone()
    }
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

/// The report: the operator's commands and telemetry gaps, the viewers' frames, the slowloris
/// sockets and garbage, the server's footprint, and the loop's overruns in each window (each
/// regime's seconds apart in an alternating run), loaded against idle.
fn report(
    load: &Load,
    footprints: [(usize, u64); 3],
    spans: [(&str, Instant, Instant); 3],
    readings: (&[Sample], &Regimes, bool),
    loop_cpu: usize,
) {
    let (samples, regimes, alternating) = readings;
    let [before, during, after] = footprints;
    let (sent, answered, arrivals) = (load.sent, load.answered, &load.arrivals);
    println!("operator: {sent} commands sent, {answered} answered");
    print_gaps("", &gaps(arrivals, |_, _| true));
    let dropped = load.dropped;
    println!(
        "viewers: {} telemetry frames received, {dropped} skipped by a lagging client while the operator ran; slowloris sockets closed by the server: {}; garbage messages sent: {}",
        load.frames, load.closed, load.junk
    );
    println!(
        "server fds / RSS: before {} / {} kB, under load {} / {} kB, 10 s after {} / {} kB",
        before.0, before.1, during.0, during.1, after.0, after.1
    );
    // Every second, or (alternating) the seconds of one regime.
    let regime_names: Vec<(String, Option<Regime>)> = if alternating {
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
            print_gaps(suffix, &gaps(arrivals, keep));
        }
        let w: Vec<Window> = spans
            .iter()
            .map(|&(name, from, to)| {
                let w = window(samples, from, to, loop_cpu, keep);
                print_window(&format!("{name}{suffix}"), &w);
                w
            })
            .collect();
        println!(
            "loop overruns loaded against idle{suffix}: {}",
            compare(&w[1], &[&w[0], &w[2]])
        );
    }
}

fn main() {
    let o = parse_args();
    let ncpu = std::thread::available_parallelism().map_or(1, |n| n.get());
    let loop_cpu = ncpu - 1;
    let (setting, original) = loop_core_setting(loop_cpu, o.alternate.is_some());
    let mut child = spawn_server(&o.server_args);
    // The server is started first: it inherits this process's CPUs.
    let confined = o.confined && ncpu > 1 && avoid_cpu(loop_cpu, ncpu);
    let addr = nanopush_e2e::listening_addr(&mut child)
        .unwrap_or_else(|first| panic!("nanopush serve did not start: its first line {first:?}"));
    let server = Proc(child);
    let pid = server.0.id();
    print_header(o.secs, confined, loop_cpu, &addr);

    // An alternating run: this process cycles the three regimes from the start to the end, so
    // that the host's own ups and downs fall on every regime alike.
    let regimes = Arc::new(Mutex::new(Regimes::default()));
    let alternating = Arc::new(AtomicBool::new(o.alternate.is_some()));
    let _give_back = o.alternate.map(|_| give_back_at_the_end(&setting, &original));
    let alternator = o.alternate.map(|phase| {
        alternate::alternate(
            phase,
            setting.clone(),
            original.clone(),
            regimes.clone(),
            alternating.clone(),
        )
    });
    if let Some(phase) = o.alternate {
        println!(
            "alternating every {phase} s: {}, and so on (set by this process)",
            Regime::ALL.map(Regime::name).join(", then ")
        );
    }
    let sampler = Sampler::start(&addr, ncpu);

    // Idle: the loop alone, before and after the load, each window half as long as the load (at
    // least a minute): the idle rate is then measured over as many ticks as the loaded one.
    let idle_window = Duration::from_secs_f64((o.secs / 2.0).max(60.0));
    std::thread::sleep(Duration::from_secs(2));
    let idle0 = Instant::now();
    std::thread::sleep(idle_window);
    let idle0_end = Instant::now();
    let before = footprint(pid);
    let load = run_load(&addr, o.secs, confined, pid);
    std::thread::sleep(Duration::from_secs(10));
    let after = footprint(pid);
    let idle1 = Instant::now();
    std::thread::sleep(idle_window);
    let idle1_end = Instant::now();
    let samples = sampler.stop();
    alternating.store(false, Relaxed);
    if let Some(a) = alternator {
        let _ = a.join();
    }
    let regimes = regimes.lock().unwrap().clone();

    let spans = [
        ("idle before", idle0, idle0_end),
        ("under the load", load.span.0, load.span.1),
        ("idle after", idle1, idle1_end),
    ];
    report(
        &load,
        [before, load.during, after],
        spans,
        (&samples, &regimes, o.alternate.is_some()),
        loop_cpu,
    );
    drop(server);
}
