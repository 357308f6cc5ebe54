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
    /// Device cycle rate (Hz), in [100, 4000].
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

/// The next cycle's deadline: `free` (the bridge's own clock) or, with a live server, locked to
/// the server's tick — `PHASE_LEAD_NS` after the server's next force sample is due (its period is
/// the bridge's, or a multiple of it). Without this the handle's sample waits up to a server
/// period before the server reads it and the force waits up to a device period before it is
/// rendered: 1-2 ms end to end at 1 kHz instead of ~1 ms.
fn next_deadline(free: Instant, server: Option<nanopush_proto::haptic::ForceFeedback>, step: Duration) -> Instant {
    let Some(f) = server else { return free };
    let now_ns = monotonic_ns();
    let now = Instant::now();
    let step_ns = step.as_nanos() as u64;
    let mut at = f.time_ns + PHASE_LEAD_NS;
    if at <= now_ns {
        at += (now_ns - at) / step_ns * step_ns + step_ns;
    }
    let locked = now + Duration::from_nanos(at - now_ns);
    // Never more than a period away, and never sooner than half a period from the free clock.
    if locked > now + step || locked + step / 2 < free {
        free
    } else {
        locked
    }
}

/// Runs the bridge; returns the summary to print.
pub fn run(a: &RunArgs) -> anyhow::Result<String> {
    if !(a.rate_hz.is_finite() && (100.0..=4000.0).contains(&a.rate_hz)) {
        bail!("--rate-hz {} is out of range; allowed: [100, 4000] Hz", a.rate_hz);
    }
    if let Some(d) = a.duration
        && !(d.is_finite() && d > 0.0 && d <= 1e6)
    {
        bail!("--duration {d} is out of range; allowed: (0, 1e6] s");
    }
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
    };
    let mut bridge = Bridge::new(device, cfg, monotonic_ns());
    let sleeper = spin_sleep::SpinSleeper::default();
    let step = Duration::from_secs_f64(period);
    let mut deadline = Instant::now();
    let mut hist = Histogram::default();
    let (mut cycles, mut overruns, mut dropped_rows, mut last_latency) = (0u64, 0u64, 0u64, 0u64);
    let mut was_up = false;
    let mut max_force_seen: f64 = 0.0;
    while !STOP.load(Ordering::SeqCst) {
        let now = Instant::now();
        if deadline > now {
            sleeper.sleep(deadline - now);
        } else if now - deadline > step {
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
            eprintln!(
                "nanopush-haptic: server {} at t = {:.3} s",
                if row.link { "live" } else { "silent: force zeroed" },
                row.t
            );
            was_up = row.link;
        }
        if let Some((tx, _)) = &trace
            && tx.try_send(row).is_err()
        {
            dropped_rows += 1;
        }
        if cycles % (a.rate_hz as u64 / 10).max(1) == 0 {
            link.cleanup_dead_nodes();
        }
        if bridge.device.finished() || deadline_total.is_some_and(|d| started.elapsed() >= d) {
            break;
        }
        deadline = next_deadline(deadline + step, bridge.last_force().filter(|_| row.link), step);
    }
    bridge.close();
    drop(link);
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
