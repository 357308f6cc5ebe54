//! The device loop: one bridge cycle per deadline until a signal, the device's end or the
//! run's; what it counted; the link's changes, the faults and a lost device said through the log.

use std::sync::mpsc;

use nanopush_haptic::bridge::{Bridge, CycleRow};
use nanopush_haptic::device::{Device, DeviceError};
use nanopush_haptic::latency::Histogram;
use nanopush_haptic::link::IpcLink;
use nanopush_proto::haptic::monotonic_ns;

use super::fault_watch::FaultWatch;
use super::open::{Reopen, reopen_device};
use super::schedule::{next_deadline, wait_for};
use super::signals::stopped;

/// What the device loop counted.
#[derive(Default)]
pub struct Tally {
    /// Device cycles run.
    pub cycles: u64,
    /// Trace rows dropped (the writer's channel was full).
    pub dropped_rows: u64,
    /// Largest |force| written to the device (N).
    pub max_force_seen: f64,
    /// End-to-end latencies, each measured once.
    pub hist: Histogram,
}

/// The device loop, from now until SIGINT/SIGTERM, the device's end or `over()`: one
/// [`Bridge::cycle`] per deadline, the link's changes and the faults said through `log` (never
/// written to stderr from here, each attributed to the device, the cable, the bridge or the
/// server) and each row offered to `trace` (dropped and counted when it is full). A lost device
/// (a cable fault) is reopened with `reopen`, backing off, while nothing is published (the
/// server sees the link down); without `reopen` the loop ends there.
pub fn device_loop<O, N>(
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
    while !stopped() {
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
