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
use nanopush_haptic::device::{Device, DeviceError, DeviceFaults, DeviceKind};
use nanopush_haptic::latency::Histogram;
use nanopush_haptic::link::IpcLink;
use nanopush_haptic::operator::Script;
use nanopush_haptic::serial::{SerialDevice, negotiate_rate};
use nanopush_haptic::sim::SimDevice;
use nanopush_proto::haptic::{DEVICE_SERIAL, DEVICE_SIM, monotonic_ns};

/// Arguments of a bridge run.
#[derive(Args, Debug)]
pub struct RunArgs {
    /// The device: `sim` (a simulated handle and operator), `serial:PATH` (a 1-DOF device on a
    /// serial port), or `none` (publishes nothing).
    #[arg(long, default_value = "sim")]
    device: String,
    /// The simulated operator's script (`--device sim`): hold, sine, press, stiff-grip, loose-grip, let-go, tap, file:PATH.
    #[arg(long, default_value = "hold")]
    operator: String,
    /// Stop after this many seconds (default: when the script ends, or never).
    #[arg(long)]
    duration: Option<f64>,
    /// Write one CSV row per device cycle here.
    #[arg(long)]
    trace: Option<PathBuf>,
    /// Device cycle rate (Hz), in [500, 4000] (the link's 5 ms watchdogs need a sample per ms
    /// or two). A serial device runs slower when its declared rate or its baud rate cannot carry
    /// this one (never below 500 Hz: it is refused then, with the numbers).
    #[arg(long, default_value_t = 1000.0)]
    rate_hz: f64,
    /// Exit (code 3) when the device is lost (unplugged, I/O error) instead of reopening it:
    /// for supervisors that prefer a restart.
    #[arg(long)]
    exit_on_device_loss: bool,
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

/// The device loop's SCHED_FIFO priority, when granted: below the server's control loop (50).
const DEVICE_LOOP_PRIORITY: i32 = 45;

/// Asks for SCHED_FIFO priority [`DEVICE_LOOP_PRIORITY`] on `cpu` (clamped to the online cores);
/// says what was granted.
fn make_realtime(cpu: usize) {
    let core = nanopush_rt::resolve_core(Some(cpu));
    let pinned = nanopush_rt::pin_to_core(Some(cpu)).is_ok();
    let fifo = nanopush_rt::sched_fifo(DEVICE_LOOP_PRIORITY).is_ok();
    eprintln!(
        "nanopush-haptic: device loop {} core {core}, {}",
        if pinned { "pinned to" } else { "not pinned to" },
        if fifo {
            format!("SCHED_FIFO {DEVICE_LOOP_PRIORITY}")
        } else {
            "SCHED_OTHER (SCHED_FIFO refused)".to_string()
        }
    );
}

/// The trace's header.
const TRACE_HEADER: &str =
    "t_s,handle_m,handle_force_n,tip_z_m,tip_force_n,link,pc_damping,port_energy_j,raw_port_energy_j,holding\n";

fn trace_line(r: &CycleRow) -> String {
    format!(
        "{:.6},{:.9e},{:.6},{:.6e},{:.6e},{},{:.6},{:.6e},{:.6e},{}\n",
        r.t,
        r.handle,
        r.force,
        r.tip_z,
        r.tip_force,
        if r.link { "up" } else { "down" },
        r.pc_damping,
        r.port_energy,
        r.raw_port_energy,
        u8::from(r.holding)
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

fn open_device(kind: &DeviceKind, operator: &str, period: f64) -> Result<(Box<dyn Device>, u32), DeviceError> {
    open_device_within(kind, operator, period, Duration::from_secs(3))
}

/// [`open_device`], a serial device given at most `open_timeout` to answer its hello.
fn open_device_within(
    kind: &DeviceKind,
    operator: &str,
    period: f64,
    open_timeout: Duration,
) -> Result<(Box<dyn Device>, u32), DeviceError> {
    match kind {
        DeviceKind::Sim => {
            let script = Script::parse(operator).map_err(|e| DeviceError::BadSpec {
                given: format!("--operator {operator}"),
                why: e.to_string(),
            })?;
            Ok((Box::new(SimDevice::new(script, period)), DEVICE_SIM))
        }
        DeviceKind::Serial(path) => {
            let dev = SerialDevice::open_within(path, open_timeout)?;
            Ok((Box::new(dev), DEVICE_SERIAL))
        }
        DeviceKind::None => Err(DeviceError::BadSpec {
            given: "none".into(),
            why: "no device".into(),
        }),
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
    let over = || deadline_total.is_some_and(|d| started.elapsed() >= d);
    if kind == DeviceKind::None {
        // Publishes nothing: for tests of the server without a handle.
        while !STOP.load(Ordering::SeqCst) && !over() {
            std::thread::sleep(Duration::from_millis(10));
        }
        return Ok(String::new());
    }
    let (device, code) = open_device(&kind, &a.operator, 1.0 / a.rate_hz)?;
    let serial_arg = match &kind {
        DeviceKind::Serial(arg) => Some(arg.as_str()),
        _ => None,
    };
    let (rate_hz, slower) = negotiate_rate(&*device, serial_arg, a.rate_hz).map_err(anyhow::Error::msg)?;
    let period = 1.0 / rate_hz;
    let mut link = IpcLink::open()?;
    announce(&*device, rate_hz);
    if let Some(why) = slower {
        eprintln!("nanopush-haptic: {why}");
    }
    let trace = a.trace.clone().map(trace_writer).transpose()?;
    if !a.no_realtime {
        make_realtime(a.cpu);
    }
    let mut bridge = Bridge::new(device, bridge_config(a, code, rate_hz), monotonic_ns());
    let (log, logged) = mpsc::sync_channel::<String>(64);
    let logger = std::thread::spawn(move || {
        for line in logged {
            eprintln!("{line}");
        }
    });
    let step_ns = (period * 1e9).round() as u64;
    let reopen = Reopen {
        label: a.device.clone(),
        open: || open_device_within(&kind, &a.operator, period, REOPEN_OPEN_TIMEOUT).map(|(d, _)| d),
        negotiate: |d: &dyn Device| negotiate_rate(d, serial_arg, a.rate_hz),
        enabled: !a.exit_on_device_loss,
    };
    let tally = device_loop(
        &mut bridge,
        &mut link,
        step_ns,
        &log,
        trace.as_ref().map(|(tx, _)| tx),
        over,
        reopen,
    );
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
    let f = bridge.faults();
    let rate_hz = bridge.rate_hz();
    eprintln!(
        "nanopush-haptic: {} cycles at {rate_hz} Hz, {} samples dropped, {} overruns (the bridge's own), {} trace rows dropped; end-to-end latency {}; device faults: {} bad packets, {} late answers, {} sequence gaps, {} out of range; {} watchdog trips (the device heard nothing for 10 ms); cable: {} losses, {} reopens",
        tally.cycles,
        bridge.dropped(),
        f.overruns,
        tally.dropped_rows,
        tally.hist.summary(),
        f.bad_packets,
        f.timeouts,
        f.seq_gaps,
        f.out_of_range,
        f.watchdog_trips,
        f.losses,
        f.reopens,
    );
    let summary = if a.json {
        summary_json(&tally, bridge.dropped(), rate_hz, &f, bridge.lost())
    } else {
        String::new()
    };
    if let Some(why) = bridge.lost() {
        return Err(anyhow::Error::new(DeviceLostAtEnd {
            device: a.device.clone(),
            why: why.to_string(),
            summary,
        }));
    }
    Ok(summary)
}

/// The run ended with the device lost and not back (or `--exit-on-device-loss`): exit code 3.
#[derive(Debug, thiserror::Error)]
#[error("the device {device} was lost ({why}) and is not back")]
pub struct DeviceLostAtEnd {
    /// Which device.
    pub device: String,
    /// What the system said.
    pub why: String,
    /// The `--json` summary, printed all the same.
    pub summary: String,
}

/// Says which device runs at what rate, and that the bridge waits for the server.
fn announce(device: &dyn Device, rate_hz: f64) {
    let spec = device.spec();
    eprintln!(
        "nanopush-haptic: {} device ({} N, travel {:.0}..{:.0} mm) at {} Hz; waiting for nanopush serve",
        spec.name,
        spec.max_force,
        spec.travel[0] * 1e3,
        spec.travel[1] * 1e3,
        rate_hz
    );
}

/// The bridge's settings from the arguments, for a device of `code` cycling every `period` s.
fn bridge_config(a: &RunArgs, code: u32, rate_hz: f64) -> BridgeConfig {
    let period = 1.0 / rate_hz;
    BridgeConfig {
        rate_hz,
        local_model: !a.no_local_model,
        passivity: !a.no_passivity,
        device_code: code,
        // Checked every cycle: the cycle that sees `timeout − period` is within the time-out.
        stale_ns: ((a.server_timeout_ms * 1e-3 - period).max(period) * 1e9) as u64,
    }
}

/// What the device loop counted.
#[derive(Default)]
struct Tally {
    cycles: u64,
    dropped_rows: u64,
    max_force_seen: f64,
    /// End-to-end latencies, each measured once.
    hist: Histogram,
}

/// The device loop, from now until SIGINT/SIGTERM, the device's end or `over()`: one
/// [`Bridge::cycle`] per deadline, the link's changes and the faults said through `log` (never
/// written to stderr from here, each attributed to the device, the cable, the bridge or the
/// server) and each row offered to `trace` (dropped and counted when it is full). A lost device
/// (a cable fault) is reopened with `reopen`, backing off, while nothing is published (the
/// server sees the link down); without `reopen` the loop ends there.
fn device_loop<O, N>(
    bridge: &mut Bridge<Box<dyn Device>>,
    link: &mut IpcLink,
    mut step_ns: u64,
    log: &mpsc::SyncSender<String>,
    trace: Option<&mpsc::SyncSender<CycleRow>>,
    over: impl Fn() -> bool,
    mut reopen: Reopen<O, N>,
) -> Tally
where
    O: FnMut() -> Result<Box<dyn Device>, DeviceError>,
    N: Fn(&dyn Device) -> Result<(f64, Option<String>), String>,
{
    let sleeper = spin_sleep::SpinSleeper::default();
    let mut deadline = monotonic_ns();
    let mut tally = Tally::default();
    let mut last_latency = 0u64;
    let mut was_up = false;
    let mut watch = FaultWatch::new(bridge.faults());
    while !STOP.load(Ordering::SeqCst) {
        if wait_for(&sleeper, &mut deadline, step_ns) {
            bridge.count_overrun();
        }
        let row = bridge.cycle_timed(monotonic_ns(), monotonic_ns, link);
        tally.cycles += 1;
        tally.max_force_seen = tally.max_force_seen.max(row.force.abs());
        if row.latency_ns != last_latency && row.latency_ns != 0 {
            tally.hist.record(row.latency_ns);
            last_latency = row.latency_ns;
        }
        if row.link != was_up {
            say_link_change(bridge, &row, log);
            was_up = row.link;
        }
        if let Some(tx) = trace
            && tx.try_send(row).is_err()
        {
            tally.dropped_rows += 1;
        }
        watch.every_second(monotonic_ns(), bridge.faults(), bridge.last_error(), log);
        if let Some(why) = bridge.lost().map(str::to_string) {
            let _ = log.try_send(format!(
                "nanopush-haptic: cable: {} was lost ({why}): force zeroed{}",
                reopen.label,
                if reopen.enabled {
                    "; reopening it by its path"
                } else {
                    ""
                }
            ));
            if !reopen.enabled || !reopen_device(bridge, link, &mut reopen, &mut step_ns, log, &over) {
                break;
            }
            deadline = monotonic_ns();
            continue;
        }
        if bridge.device.finished() || over() {
            break;
        }
        deadline = next_deadline(deadline, bridge.last_force().filter(|_| row.link), step_ns);
    }
    tally
}

/// How a lost device is opened again: its name for the log, the opening, the rate negotiation,
/// and whether to try at all (not with `--exit-on-device-loss`).
struct Reopen<O, N> {
    label: String,
    open: O,
    negotiate: N,
    enabled: bool,
}

/// How long one reopening attempt waits for the device's hello answer: short, so a signal ends
/// the back-off promptly.
const REOPEN_OPEN_TIMEOUT: Duration = Duration::from_millis(500);

/// The first wait between attempts to reopen a lost device; it doubles up to [`REOPEN_MAX`].
pub const REOPEN_FIRST: Duration = Duration::from_millis(100);
/// The longest wait between attempts to reopen a lost device.
pub const REOPEN_MAX: Duration = Duration::from_secs(2);

/// Reopens the lost device with back-off until it answers (true) or the run ends (false).
/// Meanwhile a state without a handle sample, flagged lost, goes out every 10 ms, so the server
/// shows the loss while it lasts. A device that answers but cannot be used (another version,
/// implausible limits, too slow) is the device's fault, not the cable's, and is said so; one that
/// carries another rate changes the cycle's rate, said so.
fn reopen_device<O, N>(
    bridge: &mut Bridge<Box<dyn Device>>,
    link: &mut IpcLink,
    reopen: &mut Reopen<O, N>,
    step_ns: &mut u64,
    log: &mpsc::SyncSender<String>,
    over: &impl Fn() -> bool,
) -> bool
where
    O: FnMut() -> Result<Box<dyn Device>, DeviceError>,
    N: Fn(&dyn Device) -> Result<(f64, Option<String>), String>,
{
    let lost_at = Instant::now();
    let mut wait = REOPEN_FIRST;
    let mut said = None::<String>;
    let mut say_once = |why: String| {
        if said.as_deref() != Some(&why) {
            let _ = log.try_send(why.clone());
            said = Some(why);
        }
    };
    while !STOP.load(Ordering::SeqCst) && !over() {
        bridge.publish_lost(monotonic_ns(), link);
        match (reopen.open)() {
            Ok(device) => match (reopen.negotiate)(&*device) {
                Ok((rate_hz, why)) => {
                    if rate_hz != bridge.rate_hz() {
                        bridge.set_rate(rate_hz);
                        *step_ns = (1e9 / rate_hz).round() as u64;
                        let _ = log.try_send(format!(
                            "nanopush-haptic: device: the reopened device runs at {rate_hz} Hz{}",
                            why.map(|w| format!(" ({w})")).unwrap_or_default()
                        ));
                    }
                    bridge.replace_device(device);
                    let _ = log.try_send(format!(
                        "nanopush-haptic: cable: {} is back after {:.1} s; the force ramps in",
                        reopen.label,
                        lost_at.elapsed().as_secs_f64()
                    ));
                    return true;
                }
                Err(why) => say_once(format!(
                    "nanopush-haptic: device: the reopened device cannot be used: {why}; trying again"
                )),
            },
            Err(e @ DeviceError::Protocol { .. }) => {
                say_once(format!("nanopush-haptic: device: reopening failed: {e}; trying again"))
            }
            Err(e) => say_once(format!("nanopush-haptic: cable: reopening failed: {e}; trying again")),
        }
        let until = Instant::now() + wait;
        while Instant::now() < until && !STOP.load(Ordering::SeqCst) && !over() {
            std::thread::sleep(Duration::from_millis(10));
            bridge.publish_lost(monotonic_ns(), link);
        }
        wait = (wait * 2).min(REOPEN_MAX);
    }
    false
}

/// Says, at most once a second, which faults were counted since the last time, by side.
struct FaultWatch {
    last: DeviceFaults,
    next_ns: u64,
}

impl FaultWatch {
    fn new(now: DeviceFaults) -> FaultWatch {
        FaultWatch {
            last: now,
            next_ns: monotonic_ns() + 1_000_000_000,
        }
    }

    fn every_second(&mut self, now_ns: u64, f: DeviceFaults, why: Option<&str>, log: &mpsc::SyncSender<String>) {
        if now_ns < self.next_ns {
            return;
        }
        self.next_ns = now_ns + 1_000_000_000;
        let d = |a: u64, b: u64| a.saturating_sub(b);
        let l = self.last;
        let device = [
            (d(f.bad_packets, l.bad_packets), "bad packets"),
            (d(f.timeouts, l.timeouts), "late answers (the device overran)"),
            (d(f.seq_gaps, l.seq_gaps), "sequence gaps"),
            (d(f.out_of_range, l.out_of_range), "states out of range"),
        ];
        let said: Vec<String> = device
            .iter()
            .filter(|(n, _)| *n > 0)
            .map(|(n, what)| format!("{n} {what}"))
            .collect();
        if !said.is_empty() {
            let reason = why.map(|w| format!("; the latest: {w}")).unwrap_or_default();
            let _ = log.try_send(format!(
                "nanopush-haptic: device fault: {} in the last second{reason}",
                said.join(", ")
            ));
        }
        let trips = d(f.watchdog_trips, l.watchdog_trips);
        let overruns = d(f.overruns, l.overruns);
        if overruns > 0 {
            let _ = log.try_send(format!(
                "nanopush-haptic: bridge fault: {overruns} late cycles in the last second"
            ));
        }
        if trips > 0 {
            let _ = log.try_send(format!(
                "nanopush-haptic: bridge fault: the device's watchdog zeroed its force {trips} times in the last second (it heard no valid packet for {} ms: the bridge stalled or packets were lost on the line); the force ramps in again",
                nanopush_haptic::serial::DEVICE_SILENCE_MS
            ));
        }
        self.last = f;
    }
}

/// Sleeps (then spins) until `deadline`. Returns whether the cycle started more than a period
/// late (an overrun), in which case the schedule starts again from now.
fn wait_for(sleeper: &spin_sleep::SpinSleeper, deadline: &mut u64, step_ns: u64) -> bool {
    let now = monotonic_ns();
    if *deadline > now {
        sleeper.sleep(Duration::from_nanos(*deadline - now));
    } else if now - *deadline > step_ns {
        *deadline = now;
        return true;
    }
    false
}

/// Hands the logger thread the line that says the server came or went at `row`.
fn say_link_change(bridge: &Bridge<Box<dyn Device>>, row: &CycleRow, log: &mpsc::SyncSender<String>) {
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
}

/// The `--json` summary: cycles, the rate, drops, overruns, the largest force, the latency
/// quantiles, the device's faults by side, and whether the device was lost at the end.
fn summary_json(t: &Tally, dropped_samples: u64, rate_hz: f64, f: &DeviceFaults, lost: Option<&str>) -> String {
    format!(
        "{}\n",
        serde_json::json!({
            "cycles": t.cycles,
            "rate_hz": rate_hz,
            "dropped_samples": dropped_samples,
            "overruns": f.overruns,
            "dropped_rows": t.dropped_rows,
            "max_force_n": t.max_force_seen,
            "latency_ns": {
                "samples": t.hist.count(),
                "p50": t.hist.quantile(0.5),
                "p99": t.hist.quantile(0.99),
                "p999": t.hist.quantile(0.999),
                "max": t.hist.max(),
            },
            "device_faults": faults_json(f),
            "device_lost": lost,
        })
    )
}

/// The device's faults as JSON by name, with each name's side (as `/api/status` shows them).
pub fn faults_json(f: &DeviceFaults) -> serde_json::Value {
    let mut out = serde_json::Map::new();
    for ((name, _), n) in DeviceFaults::KINDS.iter().zip(f.counts()) {
        out.insert((*name).into(), n.into());
    }
    let sides = DeviceFaults::KINDS.iter().map(|(n, s)| ((*n).to_string(), (*s).into()));
    out.insert("side".into(), serde_json::Map::from_iter(sides).into());
    out.into()
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

    /// docs/haptics.md, "Two processes": the device cycle runs at 0.5-4 kHz (1 kHz by default) and the
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

    /// docs/benchmarks.md, "Haptic latency (`nanopush-haptic-latency`)": "the device cycle locks 30 µs after the server's tick". A server
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
