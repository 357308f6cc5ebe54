//! The settings of the haptic z-control law ([`super`]) and how a scene gives them.

use crate::scene::Scene;

/// The settings of the law, SI.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BilateralParams {
    /// Tip metres per handle metre (`g_p`).
    pub position_gain: f64,
    /// Hand newtons per tip newton (`g_f`), as asked: the one in force may be lower
    /// ([`Coupling::force_gain`](super::coupling::Coupling::force_gain)).
    pub force_gain: f64,
    /// The tip-sample pull-off force (N), which `g_f` maps to the hand.
    pub adhesion: f64,
    /// Height above the detected surface the tip parks at (m).
    pub park_gap: f64,
    /// Fastest the hand may move the tip's height (m/s).
    pub max_speed: f64,
    /// Speed of the automatic approach and retraction (m/s).
    pub approach_speed: f64,
    /// Deepest the lever may be pressed, as a deflection `ζ_max` (m).
    pub max_indent: f64,
    /// Highest the hand may take the tip above the detected surface (m).
    pub max_height: f64,
    /// Reading change that means the tip met the surface (V).
    pub substrate_threshold: f64,
    /// Reading at zero deflection (V).
    pub baseline: f64,
    /// Sensor gain (V/m).
    pub sensor_gain: f64,
    /// Deflection beyond which the tip is taken to touch the surface (m).
    pub contact_deflection: f64,
    /// Lever stiffness `k_z` (N/m).
    pub k_z: f64,
    /// Control tick (s).
    pub tick: f64,
    /// Longest the approach may search below its start (m).
    pub search_depth: f64,
}

impl Scene {
    /// The haptic z-control's settings from `[haptic]`, `[strategy]`, `[sensor]` and the lever,
    /// for a control tick of `tick` seconds. The force scaling maps the tip's adhesion (the
    /// pull-off scale, [`crate::physics::force_curve::TipSample::adhesion`]) to
    /// `haptic.pull_off_at_hand_n`.
    pub fn bilateral_params(&self, tick: f64) -> BilateralParams {
        let f = &self.file;
        let (h, st) = (&f.haptic, &f.strategy);
        let sensor = self.sensor();
        let ts = self.tip_sample();
        let safety_deflection = ((st.safety_limit_v - sensor.baseline) / sensor.gain).abs();
        BilateralParams {
            position_gain: h.nm_per_mm * 1e-9 / 1e-3,
            force_gain: h.pull_off_at_hand_n / ts.adhesion().max(1e-12),
            adhesion: ts.adhesion().max(1e-12),
            park_gap: h.park_gap_nm * 1e-9,
            max_speed: h.max_speed_nm_per_s * 1e-9,
            approach_speed: st.approach_speed_um_per_s * 1e-6,
            max_indent: 0.8 * safety_deflection,
            max_height: h.max_height_nm * 1e-9,
            substrate_threshold: st.substrate_threshold_mv * 1e-3,
            baseline: sensor.baseline,
            sensor_gain: sensor.gain,
            contact_deflection: (5.0 * sensor.noise_rms / sensor.gain.abs()).max(0.2e-9),
            k_z: ts.k_c,
            tick,
            search_depth: st.search_range_um * 1e-6 + st.start_height_um * 1e-6,
        }
    }
}
