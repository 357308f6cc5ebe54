//! What crosses between the control loop and the rest of the server: commands in, events and
//! trace rows out.

use crate::haptic::HapticCommand;
use nanopush_instrument::control::{Leg, Prepared, StrategyParams};

/// A push prepared off the loop (localization, model prediction, plan), ready to run.
#[derive(Debug, Clone)]
pub struct PushJob {
    /// Run number (for the record's name).
    pub run: u64,
    /// Particle id.
    pub particle: u32,
    /// The legs, in order.
    pub legs: Vec<Leg>,
    /// The substrate's slope as the scan before the push measured it (`∂z/∂x, ∂z/∂y`).
    pub slope: (f64, f64),
    /// The model prediction and geometry.
    pub prepared: Prepared,
    /// The strategy's settings for this particle (the plan's, where the scene sets none).
    pub params: StrategyParams,
}

/// What the network side asks of the loop.
#[derive(Debug)]
pub enum LoopCommand {
    /// Start a push.
    Push(Box<PushJob>),
    /// Stop the running push, for this reason: the tip retracts.
    Stop(StopReason),
    /// Finish: stop any push, retract, release the haptic force, end the thread.
    Shutdown,
    /// Haptic z-control.
    Haptic(HapticCommand),
}

/// Why a push was stopped: the words its `run_done` failure gives (a disconnect is not the
/// operator's Stop).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StopReason {
    /// The lease holder pressed Stop (or sent `stop`).
    Operator,
    /// The lease holder's connection closed while its push ran.
    HolderDisconnected,
}

impl StopReason {
    /// The reason in words, as `run_done`'s `failure` says it after `stopped: `.
    pub fn words(self) -> &'static str {
        match self {
            StopReason::Operator => "stop requested by the operator",
            StopReason::HolderDisconnected => "the lease holder disconnected",
        }
    }
}

/// The loop's outcome for a push whose legs all ran: not yet a verdict. The scan after the push
/// judges the move (`server/src/push/judge.rs`), which keeps the instrument busy until then.
pub const PUSHED: &str = "pushed";

/// What the loop reports back.
#[derive(Debug, Clone, PartialEq)]
pub enum LoopEvent {
    /// A push ended.
    RunDone {
        /// Run number.
        run: u64,
        /// Particle.
        particle: u32,
        /// [`PUSHED`] or a failure code.
        outcome: &'static str,
        /// The failure in words.
        failure: Option<String>,
        /// Estimated final centre (m).
        estimate: [f64; 2],
        /// True final centre (m), from the simulator, for the record.
        truth: [f64; 2],
        /// Legs run.
        legs: usize,
    },
}

/// One trace row for the recorder.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum RecordMsg {
    /// A push begins.
    Begin {
        /// Run number.
        run: u64,
        /// Particle.
        particle: u32,
    },
    /// One tick of it.
    Row {
        /// Leg (1-based).
        leg: u32,
        /// Time (s).
        t: f64,
        /// Phase.
        phase: &'static str,
        /// Stage (m).
        stage: [f64; 3],
        /// Reading (V).
        volts: f64,
        /// Estimated displacement of this leg (m).
        estimate: f64,
    },
    /// It ended (its summary follows as a [`LoopEvent::RunDone`]).
    End {
        /// Run number.
        run: u64,
    },
}
