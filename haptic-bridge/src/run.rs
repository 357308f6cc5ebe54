//! The bridge process's main loop: a device cycle on an absolute-deadline schedule (sleep, then
//! spin the last stretch), SCHED_FIFO and a core of its own when the system grants them, a trace
//! written by another thread, and a clean end: zero force, then exit.
//!
//! - [`signals`]: SIGINT and SIGTERM end the run;
//! - [`schedule`]: the real-time request and the cycle's deadlines, locked to the server's tick;
//! - [`open`]: opening the device, and again after it was lost;
//! - [`device_loop`]: the loop of device cycles and what it counted;
//! - [`fault_watch`]: the faults, said at most once a second by side;
//! - [`trace`]: the `--trace` CSV's writer thread;
//! - [`summary`]: the `--json` summary.

mod device_loop;
mod fault_watch;
mod open;
mod schedule;
mod signals;
mod summary;
mod trace;

use std::path::PathBuf;
use std::sync::mpsc;
use std::time::{Duration, Instant};

use anyhow::{Context, bail};
use clap::Args;
use nanopush_haptic::bridge::{Bridge, BridgeConfig};
use nanopush_haptic::device::{Device, DeviceKind};
use nanopush_haptic::link::IpcLink;
use nanopush_haptic::serial::negotiate_rate;
use nanopush_proto::haptic::monotonic_ns;

use device_loop::device_loop;
use open::{REOPEN_OPEN_TIMEOUT, Reopen, open_device, open_device_within};
use schedule::make_realtime;
use signals::{catch_signals, stopped};
use summary::{end_line, summary_json};
use trace::trace_writer;

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
        while !stopped() && !over() {
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
    eprintln!("{}", end_line(&tally, bridge.dropped(), rate_hz, &f));
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

#[cfg(test)]
mod tests {
    use super::*;

    /// docs/haptics.md, "Two processes": the device cycle runs at 0.5-4 kHz (1 kHz by default) and the
    /// bridge zeroes its force within 5 ms of a silent server by default: `--rate-hz` is
    /// accepted in [500, 4000] Hz and refused just outside.
    #[test]
    fn the_device_rate_and_the_server_timeout_have_documented_ranges() {
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
}
