//! Loop metrics, summed lock-free in the control loop and rendered as Prometheus text by a
//! non-real-time thread: fixed-bucket histograms of atomic counters (no allocation, no lock).

use std::fmt::Write as _;
use std::sync::atomic::{AtomicU64, Ordering::Relaxed};

use nanopush_proto::haptic::DeviceFaults;

use crate::haptic::metrics::HapticMetrics;
pub use crate::histogram::{BUCKETS, Histogram};

/// Everything the loop counts.
#[derive(Debug, Default)]
pub struct LoopMetrics {
    /// Lateness of each tick's start after its deadline (s).
    pub period_error: Histogram,
    /// Compute time of the physics phase (instrument step) (s).
    pub physics: Histogram,
    /// Compute time of the control phase (strategy, commands) (s).
    pub control: Histogram,
    /// Compute time of the publish phase (haptic, telemetry, recording) (s).
    pub publish: Histogram,
    /// Ticks run.
    pub ticks: AtomicU64,
    /// Ticks whose work ended after the next deadline.
    pub overruns: AtomicU64,
    /// Commands dropped because the loop's queue was full.
    pub dropped_commands: AtomicU64,
    /// Trace rows dropped because the recorder's queue was full (should stay 0).
    pub dropped_rows: AtomicU64,
    /// The haptic link.
    pub haptic: HapticMetrics,
    /// Records (push traces and summaries, scans) that could not be written.
    pub record_failures: AtomicU64,
    /// 1 when SCHED_FIFO was granted.
    pub realtime: AtomicU64,
    /// 1 while the loop's core polls instead of halting between ticks ([`crate::control_loop::no_halt`]).
    pub no_halt: AtomicU64,
}

/// Gauges and counters the network side keeps.
#[derive(Debug, Default)]
pub struct NetMetrics {
    /// Connected WebSocket clients.
    pub clients: AtomicU64,
    /// Telemetry frames clients skipped (broadcast lag), summed.
    pub dropped_frames: AtomicU64,
    /// Messages refused with an error.
    pub refused: AtomicU64,
    /// Telemetry messages sent, summed over clients.
    pub sent: AtomicU64,
}

/// Free and total bytes of the file system holding `dir` (statvfs), for the disk alert. Free
/// space records cannot be written to (a read-only mount, no permission) is none: 0, so that
/// the disk alert fires rather than a gauge that looks healthy until the first record fails.
pub fn disk_space(dir: &std::path::Path) -> Option<(f64, f64)> {
    use std::os::unix::ffi::OsStrExt;
    let path = std::ffi::CString::new(dir.as_os_str().as_bytes()).ok()?;
    let mut st: libc::statvfs = unsafe { std::mem::zeroed() };
    // SAFETY: a NUL-terminated path and a statvfs struct we own.
    if unsafe { libc::statvfs(path.as_ptr(), &mut st) } != 0 {
        return None;
    }
    let frag = st.f_frsize as f64;
    let free = if crate::data_dir::writable(dir) {
        st.f_bavail as f64 * frag
    } else {
        0.0
    };
    Some((free, st.f_blocks as f64 * frag))
}

/// Renders both sets as a Prometheus exposition; `now_ns` is `CLOCK_MONOTONIC` now; `disk` the
/// data directory's free and total bytes, when known.
pub fn render(l: &LoopMetrics, n: &NetMetrics, now_ns: u64, disk: Option<(f64, f64)>) -> String {
    let mut s = String::with_capacity(8192);
    l.period_error.render(
        &mut s,
        "nanopush_loop_period_error_seconds",
        "Lateness of each control tick after its absolute deadline.",
        true,
        None,
    );
    let name = "nanopush_loop_compute_seconds";
    let help = "Compute time per control tick, by phase.";
    l.physics.render(&mut s, name, help, true, Some(("phase", "physics")));
    l.control.render(&mut s, name, help, false, Some(("phase", "control")));
    l.publish.render(&mut s, name, help, false, Some(("phase", "publish")));
    let h = &l.haptic;
    h.latency.render(
        &mut s,
        "nanopush_haptic_latency_seconds",
        "End-to-end haptic latency the bridge measured: a device sample to the force computed from it, back at the device.",
        true,
        None,
    );
    let (free, total) = disk.unwrap_or((f64::NAN, f64::NAN));
    for (name, help, kind, v) in loop_scalars(l, free, total)
        .into_iter()
        .chain(haptic_scalars(h, now_ns))
        .chain(net_scalars(n))
    {
        let _ = writeln!(s, "# HELP {name} {help}");
        let _ = writeln!(s, "# TYPE {name} {kind}");
        let _ = writeln!(s, "{name} {v}");
    }
    device_faults(&mut s, h);
    s
}

/// The bridge's device faults, one labelled counter family: each kind with the side at fault.
fn device_faults(s: &mut String, h: &HapticMetrics) {
    let name = "nanopush_haptic_device_faults_total";
    let _ = writeln!(
        s,
        "# HELP {name} Faults of the haptic device as the bridge counted them, by kind and the side at fault (device, bridge, cable)."
    );
    let _ = writeln!(s, "# TYPE {name} counter");
    for ((kind, side), n) in DeviceFaults::KINDS.iter().zip(&h.device_faults) {
        let _ = writeln!(s, "{name}{{kind=\"{kind}\",side=\"{side}\"}} {}", n.load(Relaxed));
    }
}

/// A scalar family: name, help, type and value.
type Scalar = (&'static str, &'static str, &'static str, f64);

/// The loop's and the records' counters and gauges, and the data directory's space.
fn loop_scalars(l: &LoopMetrics, free: f64, total: f64) -> [Scalar; 9] {
    [
        (
            "nanopush_record_write_failures_total",
            "Records (push traces and summaries, scans) that could not be written.",
            "counter",
            l.record_failures.load(Relaxed) as f64,
        ),
        (
            "nanopush_data_dir_free_bytes",
            "Free bytes (for unprivileged users) on the file system of the data directory; 0 when records cannot be written there (read-only mount, no permission).",
            "gauge",
            free,
        ),
        (
            "nanopush_data_dir_size_bytes",
            "Size of the file system of the data directory.",
            "gauge",
            total,
        ),
        (
            "nanopush_loop_ticks_total",
            "Control ticks run.",
            "counter",
            l.ticks.load(Relaxed) as f64,
        ),
        (
            "nanopush_loop_overruns_total",
            "Ticks whose work ended after the next deadline.",
            "counter",
            l.overruns.load(Relaxed) as f64,
        ),
        (
            "nanopush_loop_dropped_commands_total",
            "Commands dropped because the loop's queue was full.",
            "counter",
            l.dropped_commands.load(Relaxed) as f64,
        ),
        (
            "nanopush_record_dropped_rows_total",
            "Trace rows dropped because the recorder fell behind.",
            "counter",
            l.dropped_rows.load(Relaxed) as f64,
        ),
        (
            "nanopush_loop_realtime",
            "1 when the loop thread runs SCHED_FIFO.",
            "gauge",
            l.realtime.load(Relaxed) as f64,
        ),
        (
            "nanopush_loop_no_halt",
            "1 while the control loop's core polls instead of halting between ticks.",
            "gauge",
            l.no_halt.load(Relaxed) as f64,
        ),
    ]
}

/// The haptic link's gauges and counters; the link's age is −1 before any sample.
fn haptic_scalars(h: &HapticMetrics, now_ns: u64) -> [Scalar; 19] {
    let last = h.last_ns.load(Relaxed);
    let age = if last == 0 {
        -1.0
    } else {
        now_ns.saturating_sub(last) as f64 * 1e-9
    };
    [
        (
            "nanopush_haptic_link_age_seconds",
            "Time since the last haptic sample (-1 when none has arrived).",
            "gauge",
            age,
        ),
        (
            "nanopush_haptic_samples_total",
            "Haptic samples received.",
            "counter",
            h.samples.load(Relaxed) as f64,
        ),
        (
            "nanopush_haptic_link_up",
            "1 while handle samples arrive (0 when down or off).",
            "gauge",
            (h.link_name() == "up") as u8 as f64,
        ),
        (
            "nanopush_haptic_enabled",
            "1 when the server runs with a haptic link (--haptic sim or external).",
            "gauge",
            h.enabled.load(Relaxed) as u8 as f64,
        ),
        (
            "nanopush_haptic_engaged",
            "1 while haptic z-control is engaged (any phase but off).",
            "gauge",
            (h.phase_name() != "off") as u8 as f64,
        ),
        (
            "nanopush_haptic_handle_meters",
            "Handle position (NaN while the link is down: unknown).",
            "gauge",
            h.live_handle_m(),
        ),
        (
            "nanopush_haptic_force_newtons",
            "Force rendered at the hand (NaN while the link is down: unknown).",
            "gauge",
            h.live_force_n(),
        ),
        (
            "nanopush_haptic_pc_damping",
            "Damping the passivity controller adds now (N s/m).",
            "gauge",
            h.pc_damping(),
        ),
        (
            "nanopush_haptic_raw_port_energy_joules",
            "Energy the hand has put in through the raw port since the force went live (force rendered times handle displacement); below minus the stored-energy bound the loop was active.",
            "gauge",
            h.raw_port_energy(),
        ),
        (
            "nanopush_haptic_stored_energy_bound_joules",
            "The most the tip-sample environment can give back at the hand (half the pull-off squared over the felt stiffness).",
            "gauge",
            h.stored_energy_bound(),
        ),
        (
            "nanopush_haptic_felt_stiffness_newtons_per_meter",
            "The contact's stiffness felt at the hand with the scales in force.",
            "gauge",
            f64::from_bits(h.scales.felt_stiffness.load(Relaxed)),
        ),
        (
            "nanopush_haptic_max_stiffness_newtons_per_meter",
            "The device's renderable region's edge at its rate and the measured delay (0 before a device is known).",
            "gauge",
            f64::from_bits(h.scales.max_stiffness.load(Relaxed)),
        ),
        (
            "nanopush_haptic_scale_limited",
            "Why the force scale in force is below the one asked: 0 not, 1 the renderable region, 2 energy bounding.",
            "gauge",
            h.scales.limit.load(Relaxed) as f64,
        ),
        (
            "nanopush_haptic_energy_bounds_total",
            "Times the force scale was halved because the passivity damper stayed at its cap for more than 50 ms.",
            "counter",
            h.energy_bounds.load(Relaxed) as f64,
        ),
        (
            "nanopush_haptic_pc_active_samples_total",
            "Handle samples with the passivity controller acting.",
            "counter",
            h.pc_active_samples.load(Relaxed) as f64,
        ),
        (
            "nanopush_haptic_restarts_total",
            "Restarts of the supervised bridge (--haptic sim).",
            "counter",
            h.restarts.load(Relaxed) as f64,
        ),
        (
            "nanopush_haptic_dropped_samples_total",
            "Device samples the bridge dropped (not finite, outside the travel).",
            "counter",
            h.dropped_samples.load(Relaxed) as f64,
        ),
        (
            "nanopush_haptic_rejected_samples_total",
            "Bridge samples the server rejected (not finite, out of range).",
            "counter",
            h.rejected_samples.load(Relaxed) as f64,
        ),
        (
            "nanopush_haptic_link_downs_total",
            "Times the haptic link went down.",
            "counter",
            h.link_downs.load(Relaxed) as f64,
        ),
    ]
}

/// The network side's gauges and counters.
fn net_scalars(n: &NetMetrics) -> [Scalar; 4] {
    [
        (
            "nanopush_clients",
            "Connected WebSocket clients.",
            "gauge",
            n.clients.load(Relaxed) as f64,
        ),
        (
            "nanopush_dropped_frames_total",
            "Frames (telemetry, events, scan lines) slow clients skipped.",
            "counter",
            n.dropped_frames.load(Relaxed) as f64,
        ),
        (
            "nanopush_refused_messages_total",
            "Client messages answered with an error.",
            "counter",
            n.refused.load(Relaxed) as f64,
        ),
        (
            "nanopush_telemetry_sent_total",
            "Telemetry messages sent, summed over clients.",
            "counter",
            n.sent.load(Relaxed) as f64,
        ),
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_exposition_names_every_family_once() {
        let l = LoopMetrics::default();
        l.physics.record(3e-6);
        let text = render(&l, &NetMetrics::default(), 1, disk_space(std::path::Path::new("/")));
        assert_eq!(
            text.matches("# TYPE nanopush_loop_compute_seconds histogram").count(),
            1
        );
        assert!(text.contains("nanopush_loop_compute_seconds_bucket{phase=\"physics\",le=\"3e-6\"} 1"));
        assert!(text.contains("nanopush_haptic_link_age_seconds -1"));
        assert!(text.contains("nanopush_record_write_failures_total 0"));
        let free: f64 = text
            .lines()
            .find_map(|l| l.strip_prefix("nanopush_data_dir_free_bytes "))
            .unwrap()
            .parse()
            .unwrap();
        assert!(free > 0.0);
    }
}
