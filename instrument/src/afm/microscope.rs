//! The instrument interface: what the strategy, the scans and the server need from a microscope,
//! whichever it is — move the tip, hold Z or let the controller hold the force, read the
//! deflection, scan a frame, withdraw — and what it can and cannot do ([`Capabilities`]).
//!
//! Two backends implement it: the simulated AFM ([`super::SimulatedMicroscope`]) and a real
//! controller over its TCP interface (the `nanopush-nanonis` crate). The callers adapt to the
//! capabilities: a force loop never runs faster than [`Capabilities::feed_rate_hz`], and a push
//! that needs the controller's own Z feedback is not offered where there is none.

use crate::scan::HeightImage;

/// What a backend can do, as it reports it.
#[derive(Debug, Clone, PartialEq)]
pub struct Capabilities {
    /// Which backend, for people: e.g. `simulated AFM` or `Nanonis 127.0.0.1:6501`.
    pub backend: String,
    /// How often it delivers a new reading of the deflection (Hz): the fastest a force loop on
    /// top of it can be closed.
    pub feed_rate_hz: f64,
    /// The controller holds the normal force itself (its own Z feedback at a set point).
    pub z_closed_locally: bool,
    /// It has a scan engine that images a frame on its own.
    pub scan_engine: bool,
    /// Nothing that moves the tip or changes Z will be sent.
    pub read_only: bool,
}

/// A scan frame: the imaged rectangle and its pixels (SI).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ScanFrame {
    /// Centre x (m).
    pub centre_x: f64,
    /// Centre y (m).
    pub centre_y: f64,
    /// Width (m).
    pub width: f64,
    /// Height (m).
    pub height: f64,
    /// Pixels per line.
    pub pixels: usize,
    /// Lines.
    pub lines: usize,
}

/// The travel the controller allows, and the user's own limits within it (SI).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Limits {
    /// x range `[min, max]` (m).
    pub x: [f64; 2],
    /// y range (m).
    pub y: [f64; 2],
    /// z range of the scanner (m).
    pub z: [f64; 2],
    /// The fastest XY speed the backend will be asked for (m/s).
    pub max_speed: f64,
}

impl Limits {
    /// Whether `(x, y)` lies inside the XY travel.
    pub fn contains_xy(&self, x: f64, y: f64) -> bool {
        x >= self.x[0] && x <= self.x[1] && y >= self.y[0] && y <= self.y[1]
    }

    /// The XY travel in words, for messages: `x in [a, b] µm, y in [c, d] µm`.
    pub fn xy_text(&self) -> String {
        format!(
            "x in [{:.4}, {:.4}] µm, y in [{:.4}, {:.4}] µm",
            self.x[0] * 1e6,
            self.x[1] * 1e6,
            self.y[0] * 1e6,
            self.y[1] * 1e6
        )
    }
}

/// One reading, as fresh as the backend gives it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sample {
    /// The backend's own clock (s).
    pub t: f64,
    /// The tip: x, y, z (m).
    pub tip: [f64; 3],
    /// Normal deflection (V).
    pub normal: f64,
    /// Lateral deflection (V), where the backend has it.
    pub lateral: Option<f64>,
}

/// Why a backend could not do what it was asked.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MicroscopeError {
    /// The backend cannot do it at all (a capability it lacks).
    #[error("{backend} cannot {what}")]
    Unsupported {
        /// The backend.
        backend: String,
        /// What was asked.
        what: String,
    },
    /// The backend is read-only.
    #[error("read-only: {what} was not sent (it would move the tip or change Z)")]
    ReadOnly {
        /// What was refused.
        what: String,
    },
    /// Outside the controller's or the user's limits; nothing was sent.
    #[error("{what} is outside the limits; allowed: {allowed}")]
    OutOfLimits {
        /// The command and its value.
        what: String,
        /// The allowed range.
        allowed: String,
    },
    /// The controller answered with an error, or an answer that does not fit the request.
    #[error("{command}: {message}")]
    Controller {
        /// The command that failed.
        command: String,
        /// The controller's own words, or what was wrong with its answer.
        message: String,
    },
    /// The link to the controller failed (time-out, closed, unreachable).
    #[error("{command}: {message}")]
    Link {
        /// The command in flight.
        command: String,
        /// What happened.
        message: String,
    },
    /// The simulated instrument could not go on.
    #[error("{0}")]
    Simulation(String),
    /// Stopped on request.
    #[error("{0}: stopped")]
    Cancelled(String),
}

/// A microscope behind the instrument interface.
///
/// Motions are started, then followed with [`Microscope::poll`] until they arrive, so a caller
/// can watch the deflection during a push and stop at once. Every implementation withdraws the
/// tip on [`Microscope::withdraw`] whatever state it is in, and it is always safe to call.
pub trait Microscope {
    /// What it can do.
    fn capabilities(&self) -> Capabilities;

    /// Its XY and Z travel.
    fn limits(&mut self) -> Result<Limits, MicroscopeError>;

    /// Starts the tip moving in a straight line to `(x, y)` (m) at `speed` (m/s).
    fn start_move(&mut self, x: f64, y: f64, speed: f64) -> Result<(), MicroscopeError>;

    /// Stops a motion where the tip is.
    fn stop_move(&mut self) -> Result<(), MicroscopeError>;

    /// Waits for the next reading (at most one feed period) and returns it with whether the
    /// motion started last has arrived.
    fn poll(&mut self) -> Result<(Sample, bool), MicroscopeError>;

    /// Lets the controller's own Z feedback hold the normal deflection at `setpoint` (V).
    fn hold_force(&mut self, setpoint: f64) -> Result<(), MicroscopeError>;

    /// Images a frame: the one given, or the frame and pixels the backend already has.
    fn scan(&mut self, frame: Option<&ScanFrame>) -> Result<HeightImage, MicroscopeError>;

    /// The frame the backend scans when none is given.
    fn current_frame(&mut self) -> Result<ScanFrame, MicroscopeError>;

    /// Takes the tip away from the surface (feedback off, Z to its safe end).
    fn withdraw(&mut self) -> Result<(), MicroscopeError>;

    /// A flag that, once set, ends a scan in progress early (with
    /// [`MicroscopeError::Cancelled`]); a backend whose scans are instant may ignore it.
    fn set_cancel(&mut self, _cancel: std::sync::Arc<std::sync::atomic::AtomicBool>) {}
}
