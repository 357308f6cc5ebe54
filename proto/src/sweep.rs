//! The document of `nanopush sweep --json`.

use serde::{Deserialize, Serialize};

/// `nanopush sweep --json`: a summary of one sweep (or one shard of it). Lengths in m; the
/// parameter's values in its user unit (`unit`), as on the command line.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SweepReport {
    /// Always `"nanopush.sweep"`.
    pub schema: String,
    /// [`crate::VERSION`].
    pub version: u32,
    /// Scene name.
    pub scene: String,
    /// `alpha`, `beta`, `mu_as` or `radius`.
    pub param: String,
    /// The parameter's unit (`deg`, `nm`, or empty).
    pub unit: String,
    /// The paper's figure the sweep reproduces.
    pub figure: u32,
    /// Lower bound.
    pub from: f64,
    /// Upper bound.
    pub to: f64,
    /// Points in the whole sweep.
    pub steps: usize,
    /// This shard, from 0.
    pub shard: usize,
    /// Number of shards.
    pub shards: usize,
    /// Global index of this shard's first point.
    pub first_index: usize,
    /// Points computed by this shard.
    pub points: usize,
    /// Whether the particle's rotation was off (pure sliding, Eq 18's assumption).
    pub pure_sliding: bool,
    /// Eq 18 (pure sliding, closed form) over the points where it has a steady state.
    pub eq18: SeriesSummary,
    /// The dynamic model (Eq 17) settled over the tail of each push.
    pub dynamic: SeriesSummary,
    /// Parameter values of the points flagged unstable (stick-slip, or a wide tail).
    pub unstable: Vec<f64>,
    /// Parameter values where the particle never sheared within the run.
    pub stuck: Vec<f64>,
    /// Parameter values where Eq 18 has no steady state (the particle jams).
    pub eq18_missing: Vec<f64>,
    /// Failed points: value and error.
    pub failed: Vec<FailedPoint>,
    /// Wall time of the whole command (s).
    pub wall_time: f64,
    /// Worker threads used.
    pub threads: usize,
    /// CSV written, if any.
    pub csv: Option<String>,
    /// SVG written, if any (only for an unsharded sweep).
    pub svg: Option<String>,
}

/// Extremes of `y` and `ζ_z` over a sweep; every field `null` when no point has a value.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SeriesSummary {
    /// Points with a value.
    pub points: usize,
    /// Smallest particle `y` (m).
    pub y_min: Option<f64>,
    /// Largest particle `y` (m).
    pub y_max: Option<f64>,
    /// Parameter value of the smallest `y` (the optimum of Fig 11).
    pub y_argmin: Option<f64>,
    /// Smallest `ζ_z` (m).
    pub zeta_z_min: Option<f64>,
    /// Largest `ζ_z` (m).
    pub zeta_z_max: Option<f64>,
}

/// A point that failed.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FailedPoint {
    /// Global index.
    pub index: usize,
    /// Parameter value.
    pub value: f64,
    /// Why.
    pub error: String,
}
