//! The iceoryx2 payloads of the haptic link between `nanopush serve` and the 1-DOF haptic bridge
//! (`nanopush-haptic`): plain `#[repr(C)]` data, no heap, one definition for both processes.

use iceoryx2::prelude::ZeroCopySend;

/// Service the bridge publishes the handle's state on.
pub const HAPTIC_STATE_SERVICE: &str = "nanopush/haptic/state";
/// Service the server publishes the force to render on.
pub const FORCE_FEEDBACK_SERVICE: &str = "nanopush/haptic/force";

/// The haptic handle's state, bridge → server, at the device rate.
#[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend)]
#[type_name("nanopush::HapticState")]
#[repr(C)]
pub struct HapticState {
    /// Sequence number (increments by one per sample).
    pub seq: u64,
    /// Bridge clock, monotonic (ns).
    pub time_ns: u64,
    /// Handle position (m), positive up.
    pub position: f64,
    /// Handle velocity (m/s).
    pub velocity: f64,
}

/// The force the bridge should render, server → bridge, every control tick.
#[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend)]
#[type_name("nanopush::ForceFeedback")]
#[repr(C)]
pub struct ForceFeedback {
    /// Sequence number (the server's tick count).
    pub seq: u64,
    /// Server clock since start (ns).
    pub time_ns: u64,
    /// Tip force `k_z ζ_z` (N), positive repulsive (pushing the tip up); the bridge scales it.
    pub force: f64,
    /// Tip height above the detected substrate (m), for the bridge's display.
    pub tip_z: f64,
    /// 1 when the force is live, 0 to release the handle (start-up, shutdown).
    pub active: u32,
    /// Padding to a multiple of 8 bytes.
    pub reserved: u32,
}
