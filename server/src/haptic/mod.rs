//! The server's end of the haptic link (`--haptic sim|external|none`): the iceoryx2 ports the
//! control loop uses, the link's state for `/api/status` and `/metrics` (atomics written by the
//! loop), and the supervisor that runs a simulated bridge as a child under `--haptic sim`.
//!
//! Liveness: the control loop watches the age of the newest handle sample every tick (down
//! within `--haptic-timeout-ms`, 5 ms by default: 5 missed samples at 1 kHz); the supervisor looks for dead nodes a few times
//! a second off the real-time thread and removes their resources, so a bridge killed with SIGKILL
//! leaves nothing behind for the next one.

pub mod api;
pub mod link;
pub mod metrics;
pub mod supervisor;

use std::path::PathBuf;

pub use api::HapticCommand;
pub use link::{DEFAULT_TIMEOUT_MS, LINK_DOWN, LINK_OFF, LINK_UP, ServerLink};
pub use metrics::HapticMetrics;
pub use supervisor::Supervisor;

/// How the server gets its handle.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum HapticMode {
    /// No haptic link at all.
    None,
    /// Waits for a bridge started separately (a real device).
    External,
    /// Spawns and supervises `nanopush-haptic --device sim --operator hold` (this binary).
    Sim(PathBuf),
}
