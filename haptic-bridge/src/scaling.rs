//! Bilateral scaling between the tip (nm, nN) and the haptic handle (mm, N).
//!
//! Position: `z_tip = z_handle · position_gain` (a handle travel of 1 mm moves the tip
//! `position_gain` metres). Force: `F_hand = F_tip · force_gain`, saturated at the device's
//! peak force so a contact spike (a snap-in or a pull-off) never kicks the operator's hand.

use crate::device::clamp_force;

/// Why a scaling was rejected.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ScalingError {
    /// A gain or limit is not a positive finite number.
    #[error("{name} = {value} must be a positive finite number")]
    NotPositive {
        /// Parameter name.
        name: &'static str,
        /// Value given.
        value: f64,
    },
}

/// The scaling of one bilateral axis.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Scaling {
    /// Tip metres per handle metre.
    pub position_gain: f64,
    /// Handle newtons per tip newton.
    pub force_gain: f64,
    /// Largest force the device renders (N).
    pub peak_force: f64,
}

impl Scaling {
    /// A checked scaling.
    pub fn new(position_gain: f64, force_gain: f64, peak_force: f64) -> Result<Scaling, ScalingError> {
        for (name, value) in [
            ("position_gain", position_gain),
            ("force_gain", force_gain),
            ("peak_force", peak_force),
        ] {
            if !(value.is_finite() && value > 0.0) {
                return Err(ScalingError::NotPositive { name, value });
            }
        }
        Ok(Scaling {
            position_gain,
            force_gain,
            peak_force,
        })
    }

    /// The default: 1 mm of handle is 10 nm of tip; 1 nN at the tip is 0.1 N in the hand; a
    /// desktop 1-DOF device renders up to 3 N.
    pub fn default_device() -> Scaling {
        Scaling {
            position_gain: 10e-9 / 1e-3,
            force_gain: 0.1 / 1e-9,
            peak_force: 3.0,
        }
    }

    /// Tip displacement (m) for a handle displacement (m).
    pub fn tip_position(&self, handle: f64) -> f64 {
        handle * self.position_gain
    }

    /// Handle displacement (m) that corresponds to a tip displacement (m).
    pub fn handle_position(&self, tip: f64) -> f64 {
        tip / self.position_gain
    }

    /// Force rendered to the hand (N) for a tip force (N): scaled, then clamped to the peak
    /// force as a device clamps it ([`clamp_force`]: NaN is rendered as no force).
    pub fn hand_force(&self, tip_force: f64) -> f64 {
        clamp_force(tip_force * self.force_gain, self.peak_force)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn default_scaling() {
        let s = Scaling::default_device();
        assert!((s.tip_position(1e-3) - 10e-9).abs() < 1e-20);
        assert!((s.handle_position(10e-9) - 1e-3).abs() < 1e-15);
        assert!((s.hand_force(1e-9) - 0.1).abs() < 1e-12);
        // A 50 nN pull-off would be 5 N: saturated at 3 N.
        assert_eq!(s.hand_force(-50e-9), -3.0);
        assert_eq!(s.hand_force(f64::NAN), 0.0);
    }

    #[test]
    fn rejects_bad_gains() {
        assert!(matches!(
            Scaling::new(0.0, 1.0, 1.0),
            Err(ScalingError::NotPositive {
                name: "position_gain",
                ..
            })
        ));
        assert!(Scaling::new(1.0, f64::INFINITY, 1.0).is_err());
        assert!(Scaling::new(1e-5, 1e8, 3.0).is_ok());
    }
}
