//! Friction with adhesion (Eq 6, 7) and the feasibility conditions of pushing (Eq 8, 9, 16).

/// Eq 6 / Eq 7: `f = μ (A + F_l)`, the friction (N) of a contact with adhesion force `A`
/// (`A_as = 4πRₐγ_L`, `A_ta = 2πR̃γ_L` when only the meniscus holds the surfaces together) and
/// external load `F_l`. The normal force `A + F_l` is clamped at 0: a contact pulled apart
/// carries no friction.
pub fn friction_limit(mu: f64, adhesion: f64, load: f64) -> f64 {
    mu * (adhesion + load).max(0.0)
}

/// Eq 8: the particle does not stick to the tip when `Rₐ > 0.5 R̃ sin β`.
pub fn no_sticking_to_tip(r_a: f64, r_eff: f64, beta: f64) -> bool {
    r_a > 0.5 * r_eff * beta.sin()
}

/// Eq 9: the lower bound on the static particle-substrate friction coefficient,
/// `μ_as^s ≥ R̃ cos β / (2Rₐ) = cos β / (2(1 + Rₐ/Rₜ))`.
///
/// For `Rₜ = 30 nm` it is `0.375 cos β` at `Rₐ = 10 nm` and `0.0146 cos β` at `Rₐ = 1 µm`
/// (the print swaps the two numbers, docs/errata.md item 6).
pub fn mu_lower_bound(r_a: f64, r_t: f64, beta: f64) -> f64 {
    beta.cos() / (2.0 * (1.0 + r_a / r_t))
}

/// Eq 16 (upper part, from `y* ≥ 0` in Eq 15): `μ_as^s ≤ (k_y cot α + k_z tan α)/(k_y − k_z)`.
///
/// 3.75 for `α = 15°`, `k_z = 8 N/m`, `k_y = 1427 N/m` (the print's 3.45 is an arithmetic slip,
/// docs/errata.md item 7). Infinite when `α = 0` or `k_y ≤ k_z`: then the denominator of Eq 15 stays
/// positive for every μ.
pub fn mu_upper_bound(k_y: f64, k_z: f64, alpha: f64) -> f64 {
    if alpha <= 0.0 || k_y <= k_z {
        return f64::INFINITY;
    }
    (k_y / alpha.tan() + k_z * alpha.tan()) / (k_y - k_z)
}

/// Where a friction coefficient sits against the Eq 16 window.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Feasibility {
    /// Eq 9 lower bound.
    pub lower: f64,
    /// Eq 16 upper bound.
    pub upper: f64,
    /// `lower ≤ μ ≤ upper`.
    pub satisfied: bool,
}

/// Checks `μ_as^s` against Eq 16: `cos β/(2(1+Rₐ/Rₜ)) ≤ μ ≤ (k_y cot α + k_z tan α)/(k_y − k_z)`.
pub fn feasibility(mu_s: f64, r_a: f64, r_t: f64, beta: f64, k_y: f64, k_z: f64, alpha: f64) -> Feasibility {
    let lower = mu_lower_bound(r_a, r_t, beta);
    let upper = mu_upper_bound(k_y, k_z, alpha);
    Feasibility {
        lower,
        upper,
        // At the upper bound itself (to rounding) Eq 15's denominator vanishes: not feasible.
        satisfied: mu_s >= lower && mu_s < upper * (1.0 - 1e-9),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn eq9_numbers_corrected() {
        let rt = 30e-9;
        assert!((mu_lower_bound(10e-9, rt, 0.0) - 0.375).abs() < 1e-12);
        assert!((mu_lower_bound(1000e-9, rt, 0.0) - 0.01456).abs() < 1e-4);
        // R̃ cos β / (2Rₐ) is the same expression.
        let (ra, b) = (250e-9, 0.5);
        let r_eff = rt * ra / (rt + ra);
        assert!((mu_lower_bound(ra, rt, b) - r_eff * b.cos() / (2.0 * ra)).abs() < 1e-15);
    }

    #[test]
    fn eq16_bound_is_3_75() {
        // (1427 cot 15° + 8 tan 15°)/1419 = (5325.63 + 2.14)/1419 = 3.7546.
        let a = 15f64.to_radians();
        let u = mu_upper_bound(1427.0, 8.0, a);
        assert!((u - 3.7546).abs() < 0.0001, "{u}");
        // By another route: the μ at which Eq 15's denominator
        // `k_y cos²α + k_z sin²α − μ sin α cos α (k_y − k_z)` vanishes.
        let (s, c) = a.sin_cos();
        let root = (1427.0 * c * c + 8.0 * s * s) / (s * c * (1427.0 - 8.0));
        assert!((u - root).abs() < 1e-12 * root, "{u} vs {root}");
        // No bound with no tilt, a negative one, or a lever no stiffer sideways than normally.
        assert_eq!(mu_upper_bound(1427.0, 8.0, 0.0), f64::INFINITY);
        assert_eq!(mu_upper_bound(1427.0, 8.0, -0.1), f64::INFINITY);
        assert_eq!(mu_upper_bound(8.0, 1427.0, a), f64::INFINITY);
        assert_eq!(mu_upper_bound(8.0, 8.0, a), f64::INFINITY);
    }

    #[test]
    fn eq16_window() {
        // The paper's lever and a 1 µm particle at β = 30°: 0.0126 ≤ μ < 3.7546.
        let f = |mu: f64| feasibility(mu, 1e-6, 30e-9, 30f64.to_radians(), 1427.0, 8.0, 15f64.to_radians());
        let w = f(0.3);
        assert_eq!(w.lower, mu_lower_bound(1e-6, 30e-9, 30f64.to_radians()));
        assert_eq!(w.upper, mu_upper_bound(1427.0, 8.0, 15f64.to_radians()));
        assert!((w.lower - 0.0126).abs() < 0.0001, "{}", w.lower);
        assert!(w.satisfied);
        assert!(f(w.lower).satisfied, "the lower bound itself is allowed");
        assert!(!f(0.99 * w.lower).satisfied);
        assert!(f(0.999 * w.upper).satisfied);
        assert!(!f(w.upper).satisfied, "on the upper bound y* diverges");
        assert!(
            !f(w.upper * (1.0 - 1e-9)).satisfied,
            "within 1e-9 of it, to rounding, too"
        );
        assert!(!f(1.001 * w.upper).satisfied);
        assert!(!f(5.0).satisfied);
    }

    #[test]
    fn friction_with_adhesion() {
        assert!((friction_limit(0.3, 905e-9, 100e-9) - 301.5e-9).abs() < 1e-15);
        assert_eq!(friction_limit(0.3, 10e-9, -20e-9), 0.0);
    }

    #[test]
    fn eq8_sharp_tip() {
        // "always correct" for a spherical tip: R̃ < Rₐ, so Rₐ > 0.5 R̃ sin β whenever Rₜ > 0.
        assert!(no_sticking_to_tip(10e-9, 30e-9 * 10e-9 / 40e-9, 1.5));
        // The boundary itself: 0.5 R̃ sin β against Rₐ.
        let beta = 30f64.to_radians();
        // 0.5 R̃ sin β = 1.0 nm for R̃ = 4 nm, β = 30°: just above passes, just below fails.
        assert!(no_sticking_to_tip(1.01e-9, 4.0e-9, beta));
        assert!(!no_sticking_to_tip(0.99e-9, 4.0e-9, beta));
        // Exactly on it (sin 90° = 1 exactly): Eq 8's inequality is strict.
        assert!(!no_sticking_to_tip(1e-9, 2e-9, std::f64::consts::FRAC_PI_2));
    }
}
