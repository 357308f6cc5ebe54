//! The readout as the derivation sees it: gain, baseline, noise and the room to its rail.

use crate::control::estimator::ContactSide;
use crate::scene::Scene;

/// The readout as the plan sees it (V).
#[derive(Debug, Clone, Copy)]
pub(super) struct Readout {
    /// |gain| (V/m).
    pub(super) gain: f64,
    /// Sign of the gain: which way a push moves the reading.
    pub(super) sign: f64,
    /// The reading at rest (V).
    pub(super) baseline: f64,
    /// Noise RMS (V).
    pub(super) sigma: f64,
    /// Periodic perturbation amplitude (V).
    pub(super) pert: f64,
    /// From the baseline to the rail on the push side (V).
    pub(super) room: f64,
}

impl Readout {
    pub(super) fn of(scene: &Scene) -> Readout {
        let s = &scene.file.sensor;
        let sign = s.gain_v_per_nm.signum();
        Readout {
            gain: s.gain_v_per_nm.abs() * 1e9,
            sign,
            baseline: s.baseline_v,
            sigma: s.noise_rms_mv * 1e-3,
            pert: s.perturbation_mv * 1e-3,
            room: s.full_scale_v - sign * s.baseline_v,
        }
    }

    /// The reading of a deflection `ζ_z` (V).
    pub(super) fn volts(&self, deflection: f64) -> f64 {
        self.baseline + self.sign * self.gain * deflection
    }

    /// From the baseline to the rail on `side` (V): [`Readout::room`] on the push side.
    pub(super) fn room_on(&self, side: ContactSide) -> f64 {
        match side {
            ContactSide::Push => self.room,
            ContactSide::Pull => self.room + 2.0 * self.sign * self.baseline,
        }
    }
}
