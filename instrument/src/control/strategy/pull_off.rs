//! Riding out the pull-off: what a reading saturated on the readout's rail means, by the side
//! it is on and what the tip is doing.
//!
//! After auto-parking detects the substrate (the snap-in), the tip adheres to it. As the stage
//! rises to the parking height the lever bends toward the substrate, the **pull side**
//! (`ζ < 0`, away from the push's side), until the contact and the meniscus let go. It bends at
//! most by the adhesion over its stiffness, and the tip hangs free once the stage has risen
//! ([`TipSample::release_distance`])
//!
//! `Δz_release = F_ad / k_c + L_t + δ_b + a₀`
//!
//! above the contact (the meniscus ruptures at the gap `L_t + δ_b`). A soft lever read with a
//! high gain saturates the readout on that side meanwhile: the reading then says only that the
//! lever is bent past the rail, which is what an operator expects until the tip snaps off. The
//! strategy allows the rise
//!
//! `Δz_allowed = 1.5 Δz_release + 10 nm`
//!
//! above the detected substrate ([`pull_off_rise`]; the margin covers the detection's few nm
//! and the noise). The rule for a saturated reading ([`judge`]):
//!
//! - on the **push side** (`ζ > 0`): an emergency in every phase (`deflection_limit`, straight
//!   up; in the retraction, already going up, it is recorded);
//! - on the **pull side**, ridden out while the tip moves up away from a contact: the tick of
//!   the z approach that detects the substrate (the snap-in is the detection), the rise to the
//!   parking height and on until the tip lets go (`let_go`), as long as the stage has risen at
//!   most `Δz_allowed` above the detected substrate, else the run fails with `still_held`; the
//!   back-off from the particle after a push and the retraction (bounded by their own lengths:
//!   100 nm, and the start height the plan sets above the tip's release from the particle);
//!   a reading still saturated on the pull side when the retraction ends is `still_held`;
//! - on the pull side anywhere else (travel, contact search, push, hold, coming back down to
//!   the parking height after letting go): an emergency, as before.
//!
//! A tip still held (the reading beyond the substrate threshold on the pull side, saturated or
//! not) when it reaches the parking height keeps rising until it lets go, then comes back down
//! to the parking height. It cannot snap in again there: the parking height is above where the
//! approach detected the substrate, and coming down the free branch is the approach's. If it
//! does, the run fails with `snapped_back`.

use crate::physics::force_curve::TipSample;

/// `Δz_allowed / Δz_release`.
pub const PULL_OFF_MARGIN: f64 = 1.5;

/// Added to the allowed rise (m).
pub const PULL_OFF_SLACK: f64 = 10e-9;

/// The rise above the detected substrate within which a reading saturated on the pull side is
/// ridden out (m): `1.5 Δz_release + 10 nm`.
pub fn pull_off_rise(tip: &TipSample) -> f64 {
    PULL_OFF_MARGIN * tip.release_distance() + PULL_OFF_SLACK
}

/// What the tip is doing, as far as a saturated reading is concerned.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Motion {
    /// The z approach's tick that detects the substrate.
    Detecting,
    /// Rising from the substrate after the snap-in (to the parking height, or until it lets
    /// go): bounded by [`pull_off_rise`].
    RisingOffSubstrate,
    /// Backing off from the particle, or retracting: bounded by their own lengths.
    LeavingParticle,
    /// Anything else.
    Other,
}

/// What a saturated reading calls for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Saturation {
    /// Expected: go on.
    RideOut,
    /// An emergency: `deflection_limit`, straight up.
    Emergency,
    /// Held past the rise the pull-off needs: `still_held`, straight up.
    HeldTooLong,
}

/// The rule of the module doc for a saturated reading with deflection signal `sig` (positive on
/// the push's side), while the tip is doing `motion`, `rise` (m) above the detected substrate.
pub fn judge(sig: f64, motion: Motion, rise: f64, allowed: f64) -> Saturation {
    if sig >= 0.0 {
        return Saturation::Emergency;
    }
    match motion {
        Motion::Detecting | Motion::LeavingParticle => Saturation::RideOut,
        Motion::RisingOffSubstrate if rise <= allowed => Saturation::RideOut,
        Motion::RisingOffSubstrate => Saturation::HeldTooLong,
        Motion::Other => Saturation::Emergency,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_push_side_is_an_emergency_whatever_the_tip_does() {
        for m in [
            Motion::Detecting,
            Motion::RisingOffSubstrate,
            Motion::LeavingParticle,
            Motion::Other,
        ] {
            assert_eq!(judge(9.9, m, 0.0, 1e-6), Saturation::Emergency, "{m:?}");
        }
    }

    #[test]
    fn the_pull_side_is_ridden_out_only_moving_up_and_within_the_allowed_rise() {
        assert_eq!(judge(-9.9, Motion::Detecting, 0.0, 50e-9), Saturation::RideOut);
        assert_eq!(
            judge(-9.9, Motion::RisingOffSubstrate, 50e-9, 50e-9),
            Saturation::RideOut
        );
        assert_eq!(
            judge(-9.9, Motion::RisingOffSubstrate, 50.1e-9, 50e-9),
            Saturation::HeldTooLong
        );
        assert_eq!(judge(-9.9, Motion::LeavingParticle, 1.0, 50e-9), Saturation::RideOut);
        assert_eq!(judge(-9.9, Motion::Other, 0.0, 50e-9), Saturation::Emergency);
    }
}
