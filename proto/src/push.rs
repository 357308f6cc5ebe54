//! `nanopush push --json`: one manipulation run (Sec 2.1 strategy, Sec 3 force control), SI.

use serde::{Deserialize, Serialize};

/// A push's tolerance when the user gives none (nm): `ok` within 25 nm of the target, on the
/// command line, in the server and in the page.
pub const TOLERANCE_NM: f64 = 25.0;

/// The allowed range of a push's tolerance (nm), on the command line, in the server and in the
/// page.
pub const TOLERANCE_RANGE_NM: (f64, f64) = (1.0, 100_000.0);

/// A particle located in a scan.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct LocatedParticle {
    /// Centre x (m).
    pub x: f64,
    /// Centre y (m).
    pub y: f64,
    /// Radius estimated from the scan, corrected for tip dilation (m).
    pub radius: f64,
}

/// One straight push of a run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LegReport {
    /// Where the controller believed the particle was (m).
    pub from: [f64; 2],
    /// Where it was asked to go (m).
    pub to: [f64; 2],
    /// `ok`, or the failure's code (`no_substrate`, `no_contact`, `particle_lost`,
    /// `deflection_limit`, `no_separation`, `still_held`, `snapped_back`, `timeout`, `unphysical`,
    /// `stopped`).
    pub outcome: String,
    /// The failure in words, if any.
    pub failure: Option<String>,
    /// Contact-search step at which `ζ_set` was reached (Fig 9).
    pub contact_step: Option<u32>,
    /// Detected particle-substrate separation `t*` (s).
    pub t_star: Option<f64>,
    /// The controller's estimate of the distance pushed (m).
    pub estimated_distance: f64,
    /// The distance the particle really moved along the push (m), from the simulator.
    pub true_distance: f64,
    /// Of that, what it moved before the push phase, during the contact search (m), from the
    /// simulator: a search that pushes the particle without the reading reaching `ζ_set`
    /// shows here (and in `failure`).
    #[serde(default)]
    pub search_distance: f64,
    /// Stage travel during the push (m).
    pub push_travel: f64,
    /// Model prediction used by the estimator: settled lag `δ° = s − y` (m).
    pub settle_offset: f64,
    /// Model prediction: particle shift during the retraction (m).
    pub retract_shift: f64,
    /// The tip ended retracted.
    pub retracted: bool,
    /// The attempt the leg belongs to: 1 for the first push, 2 and on for the corrections
    /// made after a scan found the particle outside the tolerance.
    #[serde(default = "first_attempt")]
    pub attempt: u32,
}

fn first_attempt() -> u32 {
    1
}

/// The whole run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PushReport {
    /// `"push"`.
    pub schema: String,
    /// [`crate::VERSION`].
    pub version: u32,
    /// Scene name.
    pub scene: String,
    /// Particle id.
    pub particle: u32,
    /// Loop closure: `xy`, `z` or `xyz`.
    pub control: String,
    /// The particle as the first scan located it.
    pub located_before: LocatedParticle,
    /// The particle as the scan after the run located it (None if not found).
    pub located_after: Option<LocatedParticle>,
    /// Target position (m).
    pub target: [f64; 2],
    /// Legs, in order; the run stops at the first failed leg.
    pub legs: Vec<LegReport>,
    /// The move's outcome: `ok` when the scan after the push found the particle within
    /// `tolerance` of the target, `missed` when it found it further away after every attempt,
    /// `not_found` when it did not find it, or the failed leg's code.
    #[serde(default)]
    pub outcome: String,
    /// The tolerance the outcome was judged with (m).
    #[serde(default)]
    pub tolerance: f64,
    /// The distance between the particle, as the scan after the push located it, and the
    /// target (m).
    #[serde(default)]
    pub measured_error: Option<f64>,
    /// Pushes made: the first and the corrections.
    #[serde(default)]
    pub attempts: u32,
    /// A `missed` move that was not corrected because the stage's edge cut the last push short
    /// of the retraction's drag (and would cut a correction the same way): by how much (m).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cut_short: Option<f64>,
    /// What the strategy plan warned of (hand-set values that cannot work, risks).
    #[serde(default)]
    pub warnings: Vec<String>,
    /// The particle's true final position (m), from the simulator.
    pub final_position: [f64; 2],
    /// Distance between the true final position and the target (m).
    pub final_error: f64,
    /// Simulated time (s).
    pub simulated_time: f64,
    /// Wall time (s).
    pub wall_time: f64,
}
