//! The bridge process's main loop: a device cycle on an absolute-deadline schedule (sleep, then
//! spin the last stretch), SCHED_FIFO and a core of its own when the system grants them, a trace
//! written by another thread, and a clean end: zero force, then exit.

use std::io::Write;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc;
use std::time::{Duration, Instant};

use anyhow::{Context, bail};
use clap::Args;
use nanopush_haptic::bridge::{Bridge, BridgeConfig, CycleRow};
use nanopush_haptic::device::{Device, DeviceKind};
use nanopush_haptic::latency::Histogram;
use nanopush_haptic::link::IpcLink;
use nanopush_haptic::operator::Script;
use nanopush_haptic::sim::SimDevice;
use nanopush_proto::haptic::{DEVICE_SERIAL, DEVICE_SIM, monotonic_ns};

/// Arguments of a bridge run.
#[derive(Args, Debug)]
pub struct RunArgs {
    /// The device: `sim` (a simulated handle and operator), `serial:PATH` (a 1-DOF device on a
    /// serial port), or `none` (publishes nothing).
    #[arg(long, default_value = "sim")]
    device: String,
    /// The simulated operator's script (`--device sim`): hold, sine, press, file:PATH.
    #[arg(long, default_value = "hold")]
    operator: String,
    /// Stop after this many seconds (default: when the script ends, or never).
    #[arg(long)]
    duration: Option<f64>,
    /// Write one CSV row per device cycle here.
    #[arg(long)]
    trace: Option<PathBuf>,
    /// Device cycle rate (Hz), in [500, 4000] (the link's 5 ms watchdogs need a sample per ms
    /// or two).
    #[arg(long, default_value_t = 1000.0)]
    rate_hz: f64,
    /// Hold the server's force between its samples instead of rendering its local linear model.
    #[arg(long)]
    no_local_model: bool,
    /// Observe the port's energy but do not let the passivity controller act.
    #[arg(long)]
    no_passivity: bool,
    /// Do not ask for SCHED_FIFO and a core.
    #[arg(long)]
    no_realtime: bool,
    /// CPU core for the device loop (default: the first; the server's loop takes the last).
    #[arg(long, default_value_t = 0)]
    cpu: usize,
    /// Print a JSON summary (cycles, drops, latency) on stdout at the end.
    #[arg(long)]
    json: bool,
    /// The force is zeroed within this long of the server's last sample (ms), in [2, 1000].
    #[arg(long, default_value_t = 5.0)]
    server_timeout_ms: f64,
}

static STOP: AtomicBool = AtomicBool::new(false);

extern "C" fn on_signal(_: libc::c_int) {
    STOP.store(true, Ordering::SeqCst);
}

/// SIGINT and SIGTERM end the loop (the force is zeroed before the process exits). The bridge's
/// iceoryx2 node installs no handlers of its own (`SignalHandlingMode::Disabled`).
fn catch_signals() {
    // SAFETY: the handler only stores to an atomic, which is async-signal-safe.
    unsafe {
        libc::signal(libc::SIGINT, on_signal as *const () as libc::sighandler_t);
        libc::signal(libc::SIGTERM, on_signal as *const () as libc::sighandler_t);
    }
}

/// Asks for SCHED_FIFO priority 45 (below the server's loop) on `cpu`; says what was granted.
fn make_realtime(cpu: usize) {
    // SAFETY: plain libc calls on the calling thread with valid, initialized arguments.
    unsafe {
        let ncpu = libc::sysconf(libc::_SC_NPROCESSORS_ONLN).max(1) as usize;
        let mut set: libc::cpu_set_t = std::mem::zeroed();
        libc::CPU_SET(cpu.min(ncpu - 1), &mut set);
        let pinned = libc::sched_setaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &set) == 0;
        let param = libc::sched_param { sched_priority: 45 };
        let fifo = libc::pthread_setschedparam(libc::pthread_self(), libc::SCHED_FIFO, &param) == 0;
        eprintln!(
            "nanopush-haptic: device loop {} core {}, {}",
            if pinned { "pinned to" } else { "not pinned to" },
            cpu.min(ncpu - 1),
            if fifo {
                "SCHED_FIFO 45"
            } else {
                "SCHED_OTHER (SCHED_FIFO refused)"
            }
        );
    }
}

/// The trace's header.
const TRACE_HEADER: &str = "t_s,handle_m,handle_force_n,tip_z_m,tip_force_n,link,pc_damping,port_energy_j\n";

fn trace_line(r: &CycleRow) -> String {
    format!(
        "{:.6},{:.9e},{:.6},{:.6e},{:.6e},{},{:.6},{:.6e}\n",
        r.t,
        r.handle,
        r.force,
        r.tip_z,
        r.tip_force,
        if r.link { "up" } else { "down" },
        r.pc_damping,
        r.port_energy
    )
}

/// Starts the trace writer thread: rows arrive through a bounded channel (the device loop never
/// blocks on the disk; a full channel drops the row and counts it).
fn trace_writer(
    path: PathBuf,
) -> anyhow::Result<(mpsc::SyncSender<CycleRow>, std::thread::JoinHandle<std::io::Result<()>>)> {
    let file = std::fs::File::create(&path).with_context(|| format!("creating the trace {}", path.display()))?;
    let (tx, rx) = mpsc::sync_channel::<CycleRow>(1 << 14);
    let handle = std::thread::spawn(move || {
        let mut w = std::io::BufWriter::new(file);
        w.write_all(TRACE_HEADER.as_bytes())?;
        for row in rx {
            w.write_all(trace_line(&row).as_bytes())?;
        }
        w.flush()
    });
    Ok((tx, handle))
}

fn open_device(kind: &DeviceKind, operator: &str, period: f64) -> anyhow::Result<(Box<dyn Device>, u32)> {
    match kind {
        DeviceKind::Sim => {
            let script = Script::parse(operator)?;
            Ok((Box::new(SimDevice::new(script, period)), DEVICE_SIM))
        }
        DeviceKind::Serial(path) => {
            let dev = nanopush_haptic::serial::SerialDevice::open(path)?;
            Ok((Box::new(dev), DEVICE_SERIAL))
        }
        DeviceKind::None => bail!("no device"),
    }
}

/// How long after the server's force sample the device cycle runs (ns): the bridge reads the
/// handle just after the server has ticked, so its sample waits one server period, not two.
pub const PHASE_LEAD_NS: u64 = 30_000;

/// The next cycle's deadline (monotonic ns) after the one at `prev`: one period on, nudged
/// toward the server's tick when a server is live — a quarter of the phase error per cycle, at
/// most a tenth of a period — so that the device cycle settles `PHASE_LEAD_NS` after the server's
/// force sample. The period never changes by more than that nudge: a late server sample never
/// makes the bridge skip a cycle. Without the lock the handle's sample waits up to a server
/// period before the server reads it and the force up to a device period before it is
/// rendered: 1-2 ms end to end at 1 kHz instead of ~1 ms.
pub fn next_deadline(prev: u64, server: Option<nanopush_proto::haptic::ForceFeedback>, step_ns: u64) -> u64 {
    let free = prev + step_ns;
    let Some(f) = server else { return free };
    let step = step_ns as i64;
    let want = ((f.time_ns + PHASE_LEAD_NS) % step_ns) as i64;
    let have = (free % step_ns) as i64;
    // The phase error wrapped to [−step/2, step/2).
    let err = (want - have + step + step / 2).rem_euclid(step) - step / 2;
    let nudge = (err / 4).clamp(-step / 10, step / 10);
    (free as i64 + nudge) as u64
}

/// The arguments' ranges (refused before anything starts).
fn check(a: &RunArgs) -> anyhow::Result<()> {
    if !(a.rate_hz.is_finite() && (500.0..=4000.0).contains(&a.rate_hz)) {
        bail!("--rate-hz {} is out of range; allowed: [500, 4000] Hz", a.rate_hz);
    }
    if let Some(d) = a.duration
        && !(d.is_finite() && d > 0.0 && d <= 1e6)
    {
        bail!("--duration {d} is out of range; allowed: (0, 1e6] s");
    }
    if !(a.server_timeout_ms.is_finite() && (2.0..=1000.0).contains(&a.server_timeout_ms)) {
        bail!(
            "--server-timeout-ms {} is out of range; allowed: [2, 1000] ms",
            a.server_timeout_ms
        );
    }
    Ok(())
}

/// Runs the bridge; returns the summary to print.
pub fn run(a: &RunArgs) -> anyhow::Result<String> {
    check(a)?;
    let kind: DeviceKind = a.device.parse()?;
    if a.device != "sim" && a.operator != "hold" {
        bail!(
            "--operator {} drives the simulated device only (--device sim)",
            a.operator
        );
    }
    catch_signals();
    let started = Instant::now();
    let deadline_total = a.duration.map(Duration::from_secs_f64);
    if kind == DeviceKind::None {
        // Publishes nothing: for tests of the server without a handle.
        while !STOP.load(Ordering::SeqCst) && deadline_total.is_none_or(|d| started.elapsed() < d) {
            std::thread::sleep(Duration::from_millis(10));
        }
        return Ok(String::new());
    }
    let period = 1.0 / a.rate_hz;
    let (device, code) = open_device(&kind, &a.operator, period)?;
    let mut link = IpcLink::open()?;
    let spec = device.spec();
    eprintln!(
        "nanopush-haptic: {} device ({} N, travel {:.0}..{:.0} mm) at {} Hz; waiting for nanopush serve",
        spec.name,
        spec.max_force,
        spec.travel[0] * 1e3,
        spec.travel[1] * 1e3,
        a.rate_hz
    );
    let trace = a.trace.clone().map(trace_writer).transpose()?;
    if !a.no_realtime {
        make_realtime(a.cpu);
    }
    let cfg = BridgeConfig {
        rate_hz: a.rate_hz,
        local_model: !a.no_local_model,
        passivity: !a.no_passivity,
        device_code: code,
        // Checked every cycle: the cycle that sees `timeout − period` is within the time-out.
        stale_ns: ((a.server_timeout_ms * 1e-3 - period).max(period) * 1e9) as u64,
    };
    let mut bridge = Bridge::new(device, cfg, monotonic_ns());
    let (log, logged) = mpsc::sync_channel::<String>(64);
    let logger = std::thread::spawn(move || {
        for line in logged {
            eprintln!("{line}");
        }
    });
    let sleeper = spin_sleep::SpinSleeper::default();
    let step_ns = (period * 1e9).round() as u64;
    let mut deadline = monotonic_ns();
    let mut hist = Histogram::default();
    let (mut cycles, mut overruns, mut dropped_rows, mut last_latency) = (0u64, 0u64, 0u64, 0u64);
    let mut was_up = false;
    let mut max_force_seen: f64 = 0.0;
    while !STOP.load(Ordering::SeqCst) {
        let now = monotonic_ns();
        if deadline > now {
            sleeper.sleep(Duration::from_nanos(deadline - now));
        } else if now - deadline > step_ns {
            overruns += 1;
            deadline = now;
        }
        let row = bridge.cycle(monotonic_ns(), &mut link);
        cycles += 1;
        max_force_seen = max_force_seen.max(row.force.abs());
        if row.latency_ns != last_latency && row.latency_ns != 0 {
            hist.record(row.latency_ns);
            last_latency = row.latency_ns;
        }
        if row.link != was_up {
            // Said by the logger thread: no writes to stderr from the device loop.
            let said = if row.link {
                format!("nanopush-haptic: server live at t = {:.3} s", row.t)
            } else {
                let age = bridge
                    .last_force()
                    .map_or(f64::NAN, |f| monotonic_ns().saturating_sub(f.time_ns) as f64 * 1e-6);
                format!(
                    "nanopush-haptic: server silent at t = {:.3} s (its last sample {age:.1} ms old): force zeroed",
                    row.t
                )
            };
            let _ = log.try_send(said);
            was_up = row.link;
        }
        if let Some((tx, _)) = &trace
            && tx.try_send(row).is_err()
        {
            dropped_rows += 1;
        }
        if bridge.device.finished() || deadline_total.is_some_and(|d| started.elapsed() >= d) {
            break;
        }
        deadline = next_deadline(deadline, bridge.last_force().filter(|_| row.link), step_ns);
    }
    bridge.close();
    drop(link);
    drop(log);
    let _ = logger.join();
    if let Some((tx, handle)) = trace {
        drop(tx);
        match handle.join() {
            Ok(r) => r.context("writing the trace")?,
            Err(_) => bail!("the trace writer panicked"),
        }
    }
    eprintln!(
        "nanopush-haptic: {cycles} cycles, {} samples dropped, {overruns} overruns, {dropped_rows} trace rows \
         dropped; end-to-end latency {}",
        bridge.dropped(),
        hist.summary()
    );
    Ok(if a.json {
        format!(
            "{}\n",
            serde_json::json!({
                "cycles": cycles,
                "dropped_samples": bridge.dropped(),
                "overruns": overruns,
                "dropped_rows": dropped_rows,
                "max_force_n": max_force_seen,
                "latency_ns": {
                    "samples": hist.count(),
                    "p50": hist.quantile(0.5),
                    "p99": hist.quantile(0.99),
                    "p999": hist.quantile(0.999),
                    "max": hist.max(),
                },
            })
        )
    } else {
        String::new()
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use nanopush_proto::haptic::ForceFeedback;

    /// The lock pulls the device cycle to 30 µs after the server's tick within a few dozen
    /// cycles, keeps the period within a tenth of itself, and never skips a cycle.
    #[test]
    fn the_cycle_locks_to_the_servers_tick_without_skipping() {
        let step = 1_000_000u64;
        // The server publishes at 0.6 ms past each millisecond (plus jitter).
        let server = |k: u64| ForceFeedback {
            time_ns: k * step + 600_000 + (k % 7) * 5_000,
            ..Default::default()
        };
        let mut d = 0u64;
        for k in 0..100u64 {
            let next = next_deadline(d, Some(server(k)), step);
            let period = next - d;
            assert!((900_000..=1_100_000).contains(&period), "period {period} at {k}");
            d = next;
        }
        let phase = d % step;
        assert!((600_000..700_000).contains(&phase), "phase {phase}");
        // Without a server, the free clock.
        assert_eq!(next_deadline(5, None, step), 5 + step);
    }

    /// README, "Two processes": the device cycle runs at 0.5-4 kHz (1 kHz by default) and the
    /// bridge zeroes its force within 5 ms of a silent server by default: `--rate-hz` is
    /// accepted in [500, 4000] Hz and refused just outside.
    #[test]
    fn the_device_rate_is_500_to_4000_hz_1000_by_default_and_the_server_timeout_5_ms() {
        use clap::Parser;
        #[derive(Parser)]
        struct Cli {
            #[command(flatten)]
            run: RunArgs,
        }
        let parse = |args: &[&str]| {
            Cli::try_parse_from(std::iter::once("nanopush-haptic").chain(args.iter().copied()))
                .unwrap()
                .run
        };
        let d = parse(&[]);
        assert_eq!((d.rate_hz, d.server_timeout_ms), (1000.0, 5.0));
        assert_eq!((d.device.as_str(), d.operator.as_str()), ("sim", "hold"));
        check(&d).unwrap();
        for ok in ["500", "4000"] {
            check(&parse(&["--rate-hz", ok])).unwrap();
        }
        for bad in ["499", "4001"] {
            let e = check(&parse(&["--rate-hz", bad])).unwrap_err();
            assert!(e.to_string().contains("allowed: [500, 4000] Hz"), "{e}");
        }
    }

    /// README, "Latency": "the device cycle locks 30 µs after the server's tick". A server
    /// publishing at 0.6 ms past each millisecond, without jitter: the cycle settles at 0.63 ms
    /// (to the nanosecond the quarter-step nudge leaves), at 1, 2 and 4 kHz.
    #[test]
    fn the_cycle_locks_30_us_after_the_servers_tick() {
        assert_eq!(PHASE_LEAD_NS, 30_000);
        for step in [1_000_000u64, 500_000, 250_000] {
            let server = |k: u64| ForceFeedback {
                time_ns: k * 1_000_000 + 600_000,
                ..Default::default()
            };
            let mut d = 123_456u64;
            for k in 0..200u64 {
                d = next_deadline(d, Some(server(k * step / 1_000_000)), step);
            }
            let phase = (d % step) as i64;
            let want = ((600_000 + PHASE_LEAD_NS) % step) as i64;
            assert!(
                (phase - want).abs() < 10,
                "phase {phase} ns at a {step} ns cycle, want {want}"
            );
        }
    }
}
