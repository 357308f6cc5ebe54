//! Opening the device, and again after it was lost (a cable fault), with back-off.

use std::sync::mpsc;
use std::time::{Duration, Instant};

use nanopush_haptic::bridge::Bridge;
use nanopush_haptic::device::{Device, DeviceError, DeviceKind};
use nanopush_haptic::link::IpcLink;
use nanopush_haptic::operator::Script;
use nanopush_haptic::serial::SerialDevice;
use nanopush_haptic::sim::SimDevice;
use nanopush_proto::haptic::{DEVICE_SERIAL, DEVICE_SIM, monotonic_ns};

use super::signals::stopped;

/// Opens the device of `kind` (a serial device given 3 s to answer its hello): the device, and
/// its code for the link.
pub fn open_device(kind: &DeviceKind, operator: &str, period: f64) -> Result<(Box<dyn Device>, u32), DeviceError> {
    open_device_within(kind, operator, period, Duration::from_secs(3))
}

/// [`open_device`], a serial device given at most `open_timeout` to answer its hello.
pub fn open_device_within(
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

/// How a lost device is opened again: its name for the log, the opening, the rate negotiation,
/// and whether to try at all (not with `--exit-on-device-loss`).
pub struct Reopen<O, N> {
    /// The device as given (`--device`), for the log.
    pub label: String,
    /// Opens it again.
    pub open: O,
    /// The rate it can run at, and why it is slower than asked, if it is.
    pub negotiate: N,
    /// Whether to try at all.
    pub enabled: bool,
}

/// How long one reopening attempt waits for the device's hello answer: short, so a signal ends
/// the back-off promptly.
pub const REOPEN_OPEN_TIMEOUT: Duration = Duration::from_millis(500);

/// The first wait between attempts to reopen a lost device; it doubles up to [`REOPEN_MAX`].
pub const REOPEN_FIRST: Duration = Duration::from_millis(100);
/// The longest wait between attempts to reopen a lost device.
pub const REOPEN_MAX: Duration = Duration::from_secs(2);

/// Reopens the lost device with back-off until it answers (true) or the run ends (false).
/// Meanwhile a state without a handle sample, flagged lost, goes out every 10 ms, so the server
/// shows the loss while it lasts. A device that answers but cannot be used (another version,
/// implausible limits, too slow) is the device's fault, not the cable's, and is said so; one that
/// carries another rate changes the cycle's rate, said so.
pub fn reopen_device<O, N>(
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
    while !stopped() && !over() {
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
        while Instant::now() < until && !stopped() && !over() {
            std::thread::sleep(Duration::from_millis(10));
            bridge.publish_lost(monotonic_ns(), link);
        }
        wait = (wait * 2).min(REOPEN_MAX);
    }
    false
}
