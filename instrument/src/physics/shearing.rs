//! The static-friction phase of pushing and its shearing point (Eq 14, 15).

use crate::physics::friction::friction_limit;

/// The static phase of Eq 14: the particle follows the stage until the cantilever's load
/// exceeds the static friction. `y` is the stage travel since contact (m).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StaticPhase {
    /// `k_y = k_c/c₂` (N/m).
    pub k_y: f64,
    /// `k_z = k_c` (N/m).
    pub k_z: f64,
    /// Tilt `α` (rad).
    pub alpha: f64,
    /// Static particle-substrate friction coefficient `μ_as^s`.
    pub mu_s: f64,
    /// Particle-substrate adhesion `A_as` (N).
    pub adhesion: f64,
}

/// The forces of Eq 14 at one stage travel `y`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StaticForces {
    /// `F_y^c = k_y y cos α` (N).
    pub f_y: f64,
    /// `F_z^c = k_z y sin α` (N).
    pub f_z: f64,
    /// Friction demand `f_as = F_y^c cos α + F_z^c sin α` (N).
    pub friction: f64,
    /// Normal load `F_as = F_y^c sin α − F_z^c cos α` (N).
    pub load: f64,
    /// Static friction limit `μ_as^s (F_as + A_as)` (N).
    pub limit: f64,
}

impl StaticPhase {
    /// Eq 14 at travel `y` (with `ζ_y ≈ y cos α`, `ζ_z ≈ y sin α`).
    pub fn forces(&self, y: f64) -> StaticForces {
        let (s, c) = self.alpha.sin_cos();
        let f_y = self.k_y * y * c;
        let f_z = self.k_z * y * s;
        let friction = f_y * c + f_z * s;
        let load = f_y * s - f_z * c;
        StaticForces {
            f_y,
            f_z,
            friction,
            load,
            limit: friction_limit(self.mu_s, self.adhesion, load),
        }
    }

    /// Eq 15, the shearing point (m):
    /// `y* = μ_as^s A_as / (k_y cos²α + k_z sin²α − μ_as^s sin α cos α (k_y − k_z))`,
    /// with `A_as = 4πRₐγ_L` in the paper. `None` when the denominator is not positive: the
    /// friction grows at least as fast as the push and the particle cannot be pushed (Eq 16),
    /// or when there is no adhesion (`A ≤ 0`: the static phase of Eq 14 has no extent). At the
    /// Eq 16 bound itself the denominator is a rounding residue (a y* of 1.5·10⁷ m): a
    /// denominator below 10⁻⁹ of the stiffness terms `k_y cos²α + k_z sin²α` counts as zero.
    pub fn shearing_point(&self) -> Option<f64> {
        let (s, c) = self.alpha.sin_cos();
        let stiffness = self.k_y * c * c + self.k_z * s * s;
        let den = stiffness - self.mu_s * s * c * (self.k_y - self.k_z);
        (den > 1e-9 * stiffness && self.adhesion > 0.0).then(|| self.mu_s * self.adhesion / den)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn paper() -> StaticPhase {
        StaticPhase {
            k_y: 1427.0,
            k_z: 8.0,
            alpha: 15f64.to_radians(),
            mu_s: 0.3,
            adhesion: 4.0 * std::f64::consts::PI * 1e-6 * 0.072,
        }
    }

    #[test]
    fn y_star_is_the_papers_value() {
        let y = paper().shearing_point().unwrap();
        assert!((y - 0.2215e-9).abs() < 0.001e-9, "{y}");
    }

    #[test]
    fn at_y_star_the_demand_meets_the_limit() {
        let p = paper();
        let y = p.shearing_point().unwrap();
        let f = p.forces(y);
        assert!((f.friction - f.limit).abs() < 1e-12 * f.limit);
        let before = p.forces(0.5 * y);
        assert!(before.friction < before.limit);
        let after = p.forces(1.5 * y);
        assert!(after.friction > after.limit);
    }

    #[test]
    fn above_eq16_bound_no_shearing() {
        let mut p = paper();
        p.mu_s = 3.8;
        assert!(p.shearing_point().is_none());
        p.mu_s = 3.7;
        assert!(p.shearing_point().is_some());
    }

    /// Eq 15 from its limit cases, each argued from Eq 14 alone, not from Eq 15's formula:
    /// - α = 0: the lever pushes straight along y with `k_y` and adds no load, so the particle
    ///   shears when `k_y y = μA`;
    /// - α = 90°: the push is the normal stiffness `k_z` alone (and again no load), `k_z y = μA`;
    /// - `k_y = k_z = k`: the lever's force `k y` points along the travel whatever α is, so it
    ///   adds no load and `k y = μA` at every angle;
    /// - no friction: shearing at once (`y* = 0`), and `y*` grows linearly in μ for small μ with
    ///   the slope `A/(k_y cos²α + k_z sin²α)` (the friction demand per unit travel).
    #[test]
    fn eq15_limit_cases() {
        let base = paper();
        let mu_a = base.mu_s * base.adhesion;
        let at = |alpha: f64| StaticPhase { alpha, ..base }.shearing_point().unwrap();
        assert!((at(0.0) - mu_a / base.k_y).abs() < 1e-12 * at(0.0));
        let vertical = at(std::f64::consts::FRAC_PI_2);
        assert!((vertical - mu_a / base.k_z).abs() < 1e-9 * vertical, "{vertical:e}");
        for deg in [5.0, 15.0, 40.0, 75.0] {
            let iso = StaticPhase {
                k_z: base.k_y,
                alpha: f64::to_radians(deg),
                ..base
            };
            let y = iso.shearing_point().unwrap();
            assert!((y - mu_a / base.k_y).abs() < 1e-12 * y, "{deg}°: {y:e}");
        }
        // No friction, no static phase; no adhesion, none either (Eq 14 has no extent).
        let none = StaticPhase { mu_s: 0.0, ..base }.shearing_point();
        assert!(none.is_none_or(|y| y == 0.0), "{none:?}");
        assert_eq!(StaticPhase { adhesion: 0.0, ..base }.shearing_point(), None);
        let (s, c) = base.alpha.sin_cos();
        let slope = base.adhesion / (base.k_y * c * c + base.k_z * s * s);
        for mu in [1e-3, 1e-4] {
            let y = StaticPhase { mu_s: mu, ..base }.shearing_point().unwrap();
            assert!((y / mu - slope).abs() < 2.0 * mu * slope, "μ = {mu}: {:e}", y / mu);
        }
    }

    /// Exactly at the Eq 16 bound the denominator is a rounding residue (y* would come out as
    /// 1.5·10⁷ m): no shearing.
    #[test]
    fn at_the_eq16_bound_no_shearing() {
        let mut p = paper();
        let (s, c) = p.alpha.sin_cos();
        p.mu_s = (p.k_y * c / s + p.k_z * s / c) / (p.k_y - p.k_z);
        assert!(p.shearing_point().is_none(), "{:?}", p.shearing_point());
        // A denominator under 10⁻⁹ of the stiffness terms is the bound: 10⁻¹² inside it, no y*.
        let bound = p.mu_s;
        p.mu_s = bound * (1.0 - 1e-12);
        assert!(p.shearing_point().is_none(), "{:?}", p.shearing_point());
        // Just inside, a finite (large) y*: the bound is not widened beyond rounding.
        p.mu_s = bound * (1.0 - 1e-6);
        let y = p.shearing_point().expect("inside the window");
        assert!(y > 1e-6 && y.is_finite(), "{y}");
    }
}
