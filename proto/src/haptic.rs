//! The iceoryx2 payloads of the haptic link between `nanopush serve` and the 1-DOF haptic bridge
//! (`nanopush-haptic`): plain `#[repr(C)]` data, no heap, one definition for both processes, and
//! the one iceoryx2 configuration both sides build in code (so neither searches for a config file
//! nor prints "No config file was loaded").
//!
//! Timing: both processes stamp samples with `CLOCK_MONOTONIC` ([`monotonic_ns`]), one clock for
//! the whole machine, so an age or a latency is a plain difference across the two processes.

#[cfg(feature = "ipc")]
use iceoryx2::prelude::ZeroCopySend;

#[cfg(feature = "ipc")]
mod link;
pub mod region;

#[cfg(feature = "ipc")]
pub use link::*;

/// Service the bridge publishes the handle's state on.
pub const HAPTIC_STATE_SERVICE: &str = "nanopush/haptic/state";
/// Service the server publishes the force to render on.
pub const FORCE_FEEDBACK_SERVICE: &str = "nanopush/haptic/force";
/// Node name of a bridge (as iceoryx2's node list shows it).
pub const BRIDGE_NODE_NAME: &str = "nanopush-haptic";
/// Node name of a server.
pub const SERVER_NODE_NAME: &str = "nanopush-serve";
/// Publishers each service allows: one bridge and one server at a time. A second bridge (or
/// server) is refused when it creates its publisher.
pub const MAX_PUBLISHERS: usize = 1;
/// Subscribers each service allows (the peer, plus benchmark and diagnostic readers).
pub const MAX_SUBSCRIBERS: usize = 4;
/// Nodes each service allows.
pub const MAX_NODES: usize = 8;
/// The bridge takes a server whose newest sample is older than this as silent (ns): checked
/// every device cycle, so at 1 kHz the force is zero within 5 ms of the server's last sample.
pub const STALE_NS: u64 = 4_000_000;

/// [`HapticState::buttons`]: the engage button (a press toggles haptic z-control).
pub const BUTTON_ENGAGE: u32 = 1;
/// [`HapticState::buttons`]: the clutch, held (the tip stays while the hand re-centres).
pub const BUTTON_CLUTCH: u32 = 2;

/// [`HapticState::flags`]: the bridge hears no server and renders zero force.
pub const STATE_SERVER_SILENT: u32 = 1;
/// [`HapticState::flags`]: the bridge has lost its device (an unplugged cable) and is reopening
/// it: the state carries no handle sample, only [`HapticState::faults`] and the rate, so that
/// the server shows the loss while it lasts.
pub const STATE_DEVICE_LOST: u32 = 2;

/// [`ForceFeedback::flags`]: haptic z-control is engaged (the hand moves the tip).
pub const FORCE_ENGAGED: u32 = 1;
/// [`ForceFeedback::flags`]: a push runs; the strategy owns z and the handle only feels.
pub const FORCE_PUSHING: u32 = 2;
/// [`ForceFeedback::flags`]: the clutch is in (the tip holds while the hand re-centres).
pub const FORCE_CLUTCHED: u32 = 4;

/// [`HapticState::device`]: the simulated handle and operator.
pub const DEVICE_SIM: u32 = 1;
/// [`HapticState::device`]: a serial device.
pub const DEVICE_SERIAL: u32 = 2;

/// The name of a [`HapticState::device`] code.
pub fn device_name(code: u32) -> &'static str {
    match code {
        DEVICE_SIM => "sim",
        DEVICE_SERIAL => "serial",
        _ => "unknown",
    }
}

/// What went wrong with the device so far, counted by the bridge and published in every
/// [`HapticState`] (so `/api/status`, `/metrics` and the page see it). Each counter names the
/// side at fault: the device, the cable between, or the bridge itself.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "ipc", derive(ZeroCopySend), type_name("nanopush::DeviceFaults1"))]
#[repr(C)]
pub struct DeviceFaults {
    /// Device: packets dropped for a bad checksum or cut short.
    pub bad_packets: u64,
    /// Device: answers that did not arrive within the answer deadline (the device overran).
    pub timeouts: u64,
    /// Device: jumps of the device's sequence number other than +1 (packets it sent that were
    /// lost).
    pub seq_gaps: u64,
    /// Device: states out of the device's physical range, dropped.
    pub out_of_range: u64,
    /// Bridge: times the device zeroed its force because the bridge fell silent (its watchdog).
    pub watchdog_trips: u64,
    /// Bridge: device cycles that started more than a period late.
    pub overruns: u64,
    /// Cable: times the device was lost (hang-up, I/O error, the path vanished).
    pub losses: u64,
    /// Cable: times the device was opened again after a loss.
    pub reopens: u64,
}

impl DeviceFaults {
    /// Each counter's name and the side at fault (`device`, `bridge`, `cable`), in the order of
    /// [`DeviceFaults::counts`]: the one list the bridge's summary, `/api/status` and `/metrics`
    /// name the counters by.
    pub const KINDS: [(&'static str, &'static str); 8] = [
        ("bad_packets", "device"),
        ("timeouts", "device"),
        ("seq_gaps", "device"),
        ("out_of_range", "device"),
        ("watchdog_trips", "bridge"),
        ("overruns", "bridge"),
        ("losses", "cable"),
        ("reopens", "cable"),
    ];

    /// The counters in [`DeviceFaults::KINDS`] order.
    pub fn counts(&self) -> [u64; 8] {
        [
            self.bad_packets,
            self.timeouts,
            self.seq_gaps,
            self.out_of_range,
            self.watchdog_trips,
            self.overruns,
            self.losses,
            self.reopens,
        ]
    }
}

impl std::ops::Add for DeviceFaults {
    type Output = DeviceFaults;
    fn add(self, b: DeviceFaults) -> DeviceFaults {
        DeviceFaults {
            bad_packets: self.bad_packets + b.bad_packets,
            timeouts: self.timeouts + b.timeouts,
            seq_gaps: self.seq_gaps + b.seq_gaps,
            out_of_range: self.out_of_range + b.out_of_range,
            watchdog_trips: self.watchdog_trips + b.watchdog_trips,
            overruns: self.overruns + b.overruns,
            losses: self.losses + b.losses,
            reopens: self.reopens + b.reopens,
        }
    }
}

/// The handle's state, bridge → server, every device cycle.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[cfg_attr(feature = "ipc", derive(ZeroCopySend), type_name("nanopush::HapticState4"))]
#[repr(C)]
pub struct HapticState {
    /// Sequence number (increments by one per device cycle).
    pub seq: u64,
    /// `CLOCK_MONOTONIC` when the handle was read (ns).
    pub time_ns: u64,
    /// Handle position (m), positive up.
    pub position: f64,
    /// Handle velocity (m/s).
    pub velocity: f64,
    /// The force rendered in the previous cycle (N), positive up, after every clamp.
    pub force: f64,
    /// The device's force limit (N).
    pub max_force: f64,
    /// Damping the passivity controller adds now (N·s/m); 0 when it is idle.
    pub pc_damping: f64,
    /// Energy the operator has put into the teleoperator through the port (J), as the
    /// passivity observer counts it.
    pub port_energy: f64,
    /// Newest end-to-end latency (ns): a device sample → the force the server computed from it,
    /// back at the device; 0 when none is known yet.
    pub latency_ns: u64,
    /// Device samples dropped so far (non-finite or outside the travel).
    pub dropped: u64,
    /// The bridge's process id.
    pub pid: u32,
    /// Buttons: [`BUTTON_ENGAGE`], [`BUTTON_CLUTCH`].
    pub buttons: u32,
    /// `STATE_*` bits ([`STATE_SERVER_SILENT`]).
    pub flags: u32,
    /// `DEVICE_*` code.
    pub device: u32,
    /// The device cycle's rate (Hz), as negotiated with the device.
    pub rate_hz: f64,
    /// The device's faults so far.
    pub faults: DeviceFaults,
    /// The largest stiffness the device declares it renders stably (N/m), at `spec_rate_hz`.
    pub max_stiffness: f64,
    /// The largest damping the device renders stably (N·s/m).
    pub max_damping: f64,
    /// The rate the device's limits are declared for (Hz).
    pub spec_rate_hz: f64,
    /// The damping cap of the passivity controller (N·s/m): a damper at it is *pinned*.
    pub pc_cap: f64,
    /// Energy the operator has put in through the raw port since the force went live (J): the
    /// force rendered times the handle's displacement, `−Σ f[n−1]·Δx[n]`, with no model
    /// subtracted (Hannaford & Ryu's observer of the port itself).
    pub raw_port_energy: f64,
}

/// The force to render, server → bridge, every control tick: a local linear model of the
/// environment at the hand (the UNC nanoManipulator's approach), rendered by the bridge at its
/// own rate between server ticks:
///
/// ```text
/// F(x) = force + stiffness · clamp(x − anchor, −half_range, +half_range)
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[cfg_attr(feature = "ipc", derive(ZeroCopySend), type_name("nanopush::ForceFeedback3"))]
#[repr(C)]
pub struct ForceFeedback {
    /// Sequence number (the server's tick count).
    pub seq: u64,
    /// `CLOCK_MONOTONIC` when the force was computed (ns).
    pub time_ns: u64,
    /// `seq` of the [`HapticState`] the force was computed from; `u64::MAX` when none.
    pub state_seq: u64,
    /// Force at the hand at `anchor` (N), positive up: scaled, ramped and saturated by the
    /// server; the bridge clamps again to its device's limit.
    pub force: f64,
    /// `dF/dx` at the hand (N/m); ≤ 0 for a spring the hand presses into; 0 for a held force.
    pub stiffness: f64,
    /// Handle position the model is taken at (m).
    pub anchor: f64,
    /// Half-width of the handle range the model holds in (m).
    pub half_range: f64,
    /// The tip force `k_z ζ_z` from the measured deflection (N), positive repulsive.
    pub tip_force: f64,
    /// Tip height above the detected substrate (m); NaN when no substrate was detected yet.
    pub tip_z: f64,
    /// Engagement ramp, 0 (no force) to 1 (full force).
    pub gain: f64,
    /// 1 when the force is live, 0 to release the handle (no server state, shutdown).
    pub active: u32,
    /// `FORCE_*` bits.
    pub flags: u32,
    /// The virtual coupling's damper (N·s/m, ≥ 0), rendered by the bridge as `−damping · v`
    /// with the device's measured velocity while the model has a stiffness.
    pub damping: f64,
}

impl ForceFeedback {
    /// The force of the local model at handle position `x` (N), before the device's clamp;
    /// zero when the force is not live or a number is not finite.
    pub fn force_at(&self, x: f64) -> f64 {
        if self.active == 0 {
            return 0.0;
        }
        let r = if self.half_range.is_finite() {
            self.half_range.abs()
        } else {
            0.0
        };
        let dx = (x - self.anchor).clamp(-r, r);
        let f = self.force + if dx.is_finite() { self.stiffness * dx } else { 0.0 };
        if f.is_finite() { f } else { 0.0 }
    }
}

/// `CLOCK_MONOTONIC` now (ns): the clock both processes stamp samples with.
pub fn monotonic_ns() -> u64 {
    let mut ts = libc::timespec { tv_sec: 0, tv_nsec: 0 };
    // SAFETY: clock_gettime writes the timespec we pass; CLOCK_MONOTONIC is always available on
    // Linux.
    unsafe {
        libc::clock_gettime(libc::CLOCK_MONOTONIC, &mut ts);
    }
    ts.tv_sec as u64 * 1_000_000_000 + ts.tv_nsec as u64
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn payloads_are_plain_data_of_a_stable_size() {
        // Ten 8-byte fields and four 4-byte ones, then the rate, the eight fault counters and
        // the five of the device's limits and the raw port.
        assert_eq!(std::mem::size_of::<DeviceFaults>(), 8 * 8);
        assert_eq!(std::mem::size_of::<HapticState>(), 10 * 8 + 4 * 4 + 8 + 8 * 8 + 5 * 8);
        // Ten 8-byte fields, two 4-byte ones, the coupling's damper.
        assert_eq!(std::mem::size_of::<ForceFeedback>(), 10 * 8 + 2 * 4 + 8);
    }

    #[test]
    fn the_local_model_holds_within_its_range_and_is_zero_when_inactive() {
        let f = ForceFeedback {
            force: 0.5,
            stiffness: -1000.0,
            anchor: 0.01,
            half_range: 0.001,
            active: 1,
            ..Default::default()
        };
        assert!((f.force_at(0.0095) - 1.0).abs() < 1e-12);
        // Beyond the range the model's force holds at its edge.
        assert!((f.force_at(0.0) - 1.5).abs() < 1e-12);
        assert!((f.force_at(0.02) - (-0.5)).abs() < 1e-12);
        assert_eq!(f.force_at(f64::NAN), 0.5);
        assert_eq!(ForceFeedback { active: 0, ..f }.force_at(0.0095), 0.0);
        assert_eq!(
            ForceFeedback {
                force: f64::INFINITY,
                ..f
            }
            .force_at(0.01),
            0.0
        );
    }

    /// `CLOCK_MONOTONIC` read as a `Duration` by the standard library, an independent
    /// conversion to nanoseconds.
    fn clock_as_duration() -> std::time::Duration {
        let mut ts = libc::timespec { tv_sec: 0, tv_nsec: 0 };
        // SAFETY: clock_gettime writes the timespec we pass.
        unsafe {
            libc::clock_gettime(libc::CLOCK_MONOTONIC, &mut ts);
        }
        std::time::Duration::new(ts.tv_sec as u64, ts.tv_nsec as u32)
    }

    /// The stamps are `CLOCK_MONOTONIC` in nanoseconds, seconds and all: read between two
    /// readings of the clock through `Duration` (a test that only asked for an increase would
    /// take `sec + 1e9`, `sec / 1e9` or a constant for `sec * 1e9`).
    #[test]
    fn the_monotonic_clock_is_clock_monotonic_in_nanoseconds() {
        let before = clock_as_duration().as_nanos();
        let a = monotonic_ns();
        let b = monotonic_ns();
        let after = clock_as_duration().as_nanos();
        assert!(
            before <= u128::from(a) && a <= b && u128::from(b) <= after,
            "{before} {a} {b} {after}"
        );
    }

    #[test]
    fn device_codes_have_names() {
        assert_eq!(device_name(DEVICE_SIM), "sim");
        assert_eq!(device_name(DEVICE_SERIAL), "serial");
        assert_eq!(device_name(0), "unknown");
        assert_eq!(device_name(7), "unknown");
    }
}
