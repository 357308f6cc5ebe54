//! The document of `nanopush scan --json`.

use serde::{Deserialize, Serialize};

/// A particle found in a scan (SI units).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LocatedParticle {
    /// Centre x (m).
    pub x: f64,
    /// Centre y (m).
    pub y: f64,
    /// Centre height (m): local substrate level + radius.
    pub z: f64,
    /// Apparent height above the local substrate (m).
    pub height: f64,
    /// Radius from the apparent height, `H/2` (m): the estimate, corrected for tip dilation.
    pub radius: f64,
    /// Radius from the width at half height through the tip model (m): the cross-check.
    pub radius_from_width: Option<f64>,
    /// Apparent base width (m).
    pub base_width: f64,
    /// Base width the tip model predicts for `radius` (m).
    pub expected_base_width: f64,
}

/// A scene particle inside the scanned square, located by a click at its true position.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ParticleCheck {
    /// The scene's particle id.
    pub id: u32,
    /// True centre x (m).
    pub x: f64,
    /// True centre y (m).
    pub y: f64,
    /// True radius (m).
    pub radius: f64,
    /// What localization found; `null` with `error` set when it found nothing.
    pub located: Option<LocatedParticle>,
    /// Why localization failed.
    pub error: Option<String>,
}

/// `nanopush scan --json`: one tapping-mode frame (SI units).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ScanReport {
    /// Always `"nanopush.scan"`.
    pub schema: String,
    /// [`crate::VERSION`].
    pub version: u32,
    /// Scene name.
    pub scene: String,
    /// The GSF file written.
    pub gsf: String,
    /// The PNG preview written.
    pub png: String,
    /// Pixels per line (= lines).
    pub pixels: usize,
    /// Side of the scanned square (m).
    pub size: f64,
    /// Pixel pitch (m).
    pub pixel: f64,
    /// Centre of the square, x (m).
    pub centre_x: f64,
    /// Centre of the square, y (m).
    pub centre_y: f64,
    /// Lowest recorded height (m).
    pub z_min: f64,
    /// Highest recorded height (m).
    pub z_max: f64,
    /// Time the frame takes at the scene's line rate (s).
    pub frame_time: f64,
    /// Tip apex radius (m).
    pub tip_radius: f64,
    /// Tip cone half-angle (rad).
    pub tip_half_angle: f64,
    /// Every particle found in the image.
    pub found: Vec<LocatedParticle>,
    /// The scene's particles inside the square, each located from its true position.
    pub particles: Vec<ParticleCheck>,
    /// The particle at `--locate`, when asked.
    pub located: Option<LocatedParticle>,
}
