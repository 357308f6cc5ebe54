//! The document of `nanopush accuracy --json`.

use serde::{Deserialize, Serialize};

/// One method at one tolerance on one problem.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AccuracyPoint {
    /// `push` (the scene), `van-der-pol` or `robertson`.
    pub problem: String,
    /// `rodas4`, `rodas5p`, `trbdf2` or `implicit-euler`, or a peer solver's name.
    pub method: String,
    /// Relative tolerance.
    pub rtol: f64,
    /// Final-time error: m for the push (largest position error), relative for the classical
    /// problems (largest component); `null` when the run failed.
    pub final_error: Option<f64>,
    /// Trajectory L2 error of the push (m); `null` for the classical problems.
    pub trajectory_error: Option<f64>,
    /// The error estimated without the reference: the largest difference from the same method's
    /// runs at finer tolerances (same units), skipping runs that agree to rounding (the same
    /// steps); `null` at the finest tolerance and where no finer run differs.
    pub estimated_error: Option<f64>,
    /// The finer tolerance whose run gave `estimated_error`.
    #[serde(default)]
    pub estimate_rtol: Option<f64>,
    /// Median wall time (s).
    pub wall_time: f64,
    /// Accepted steps.
    pub steps: u64,
    /// Rejected steps.
    pub rejected: u64,
    /// Why the run failed, when it did.
    pub failure: Option<String>,
}

/// What leaving out inertia costs: the scene as given against all DOFs dynamic.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct QuasiStaticCost {
    /// Simulated window (s).
    pub duration: f64,
    /// Largest difference of particle y and ζ_z at the end (m); `null` if the full model failed.
    pub final_difference: Option<f64>,
    /// Wall time of the scene as given (s).
    pub reduced_wall_time: f64,
    /// Wall time of the full model (s).
    pub full_wall_time: f64,
    /// Steps of the full model.
    pub full_steps: u64,
    /// Why the full model failed, when it did.
    pub failure: Option<String>,
}

/// One model's push as the reduction comparison sees it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PushOutcome {
    /// `stuck`, `slides`, `rolls`, `stick-slip` or `stick-roll`.
    pub regime: String,
    /// Jumps of the particle's offset behind the stage (more than 0.05 nm between two samples).
    pub jumps: usize,
    /// Shearing time `t*` (s); `null` if the particle never slipped on the substrate.
    pub shearing_time: Option<f64>,
    /// Friction phase sampled at the end.
    pub final_phase: String,
    /// Mean offset behind the stage `s − y` over the tail (m).
    pub settled_y: f64,
    /// Its spread, max − min, over the tail (m).
    pub y_spread: f64,
    /// Mean `ζ_z` over the tail (m).
    pub zeta_z: f64,
    /// Its spread over the tail (m).
    pub zeta_z_spread: f64,
    /// Accepted steps.
    pub steps: u64,
    /// Wall time (s).
    pub wall_time: f64,
}

/// The reduced and the full model on one rotation setting.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ReductionRow {
    /// Whether the particle may rotate.
    pub rotation: bool,
    /// The quasi-static reduction (particle and cantilever at force balance).
    pub reduced: PushOutcome,
    /// The full model (every DOF dynamic); `null` when it failed.
    pub full: Option<PushOutcome>,
    /// The full model at a 100× finer tolerance; `null` when it failed or was not run.
    pub full_fine: Option<PushOutcome>,
    /// Why a full-model run failed, when one did.
    pub failure: Option<String>,
    /// Whether both do the same thing (`regime`).
    pub regime_agrees: Option<bool>,
    /// `|t*_reduced − t*_full|` (s); `null` unless both shear.
    pub shearing_time_error: Option<f64>,
    /// `settled_y` reduced − full (m).
    pub settled_y_error: Option<f64>,
    /// `zeta_z` reduced − full (m).
    pub zeta_z_error: Option<f64>,
}

/// `nanopush accuracy --json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AccuracyReport {
    /// Always `"nanopush.accuracy"`.
    pub schema: String,
    /// [`crate::VERSION`].
    pub version: u32,
    /// Scene name.
    pub scene: String,
    /// Simulated push duration (s).
    pub duration: f64,
    /// Difference between the reference (Rodas4, rtol 1e-12) and its cross-check (TR-BDF2,
    /// rtol 1e-10) at the end (m).
    pub reference_crosscheck: f64,
    /// Repetitions per point (the wall time is their median).
    pub repetitions: usize,
    /// All points.
    pub points: Vec<AccuracyPoint>,
    /// The cost of the quasi-static reduction.
    pub quasi_static_cost: Option<QuasiStaticCost>,
    /// The quasi-static reduction against the full model, rotation off and on (empty with
    /// `--no-full-model`).
    #[serde(default)]
    pub reduction: Vec<ReductionRow>,
    /// Our default method against the best peer solver at equal error.
    pub equal_error: Vec<EqualError>,
}

/// Time to reach an error, for our default method and the fastest peer.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EqualError {
    /// Problem.
    pub problem: String,
    /// Target error (relative).
    pub error: f64,
    /// Our default method (chosen by the tolerance) at the point that reached the target.
    pub ours: String,
    /// Its least wall time over the tolerances that reached the target (s); `null` if none did.
    pub ours_time: Option<f64>,
    /// The fastest peer that reached the target.
    pub best_peer: Option<String>,
    /// Its wall time (s).
    pub best_peer_time: Option<f64>,
    /// `best_peer_time / ours_time`: above 1 means ours is faster.
    pub ratio: Option<f64>,
}
