//! An assembly's report: `nanopush assemble` writes it as `DIR/summary.json` (and prints it with
//! `--json`), and the server sends its parts as the assembly goes. SI throughout.

use serde::{Deserialize, Serialize};

/// The whole report.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AssemblySummary {
    /// `nanopush.assembly`.
    pub schema: String,
    /// [`crate::VERSION`].
    pub version: u32,
    /// `filled` (every site within its tolerance by the last full frame), `incomplete`,
    /// `refused` (before anything moved) or `stopped`; in the server's record while the
    /// assembly runs, `running` (and so left by a server killed in the middle).
    pub outcome: String,
    /// Why it was refused.
    pub refusal: Option<String>,
    /// The pattern's name (its file, or the generator's text).
    pub pattern: String,
    /// Each site, in the pattern's order.
    pub sites: Vec<SiteSummary>,
    /// Each move made, in order.
    pub moves: Vec<MoveSummary>,
    /// Wall time (s).
    pub wall_time: f64,
    /// Simulated time of the pushes (s).
    pub push_time: f64,
    /// Simulated time of the scans at the scene's line rate, full frames and local ones (s).
    pub scan_time: f64,
    /// Hidden, from the simulation: a pushed particle that went through another.
    pub violations: Vec<String>,
}

/// One site at the end.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SiteSummary {
    /// The site (m).
    pub target: [f64; 2],
    /// Its tolerance (m).
    pub tolerance: f64,
    /// The scene id of the particle on it, or of the last one sent to it.
    pub particle: Option<u32>,
    /// Where the last full frame shows it (m).
    pub measured: Option<[f64; 2]>,
    /// Hidden, from the simulation: where it truly is (m).
    pub true_position: Option<[f64; 2]>,
    /// Hidden: its true distance from the target (m).
    pub error: Option<f64>,
    /// `filled`, `missed`, `unreachable` or `refused`.
    pub status: String,
    /// Why it is not filled.
    pub reason: Option<String>,
}

/// One move as it was made.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MoveSummary {
    /// `fill`, `clear` (a particle the pattern does not need, out of the way) or `park` (a
    /// particle to place later, aside for now).
    pub purpose: String,
    /// The site it fills.
    pub site: Option<usize>,
    /// The particle's scene id.
    pub particle: Option<u32>,
    /// Where it was (m).
    pub from: [f64; 2],
    /// Where it was sent (m).
    pub to: [f64; 2],
    /// `ok`, `missed`, `not_found`, a push's failure code, or why the move could not be made.
    pub outcome: String,
    /// Its distance from the target, as the scan after measured it (m).
    pub error: Option<f64>,
    /// Pushes made (the first and its corrections).
    pub pushes: u32,
    /// Simulated time of its pushes (s).
    pub push_time: f64,
}
