//! The closed-form kinetic steady state of pushing, **Eq 18**.
//!
//! Assumptions of the paper: pure sliding (no rolling, `θ̈ = 0`, so `f_as = f_ta`), tip-particle
//! indentation `h ≈ 0`, kinetic friction at both contacts. Derivation of the printed `F_ta`:
//! with `f_ta = F_ta cos β/(1 + sin β)` (from `f_as = f_ta` and `f_as = F_ta cos β − f_ta sin β`)
//! and `F_as = F_ta sin β + μ_ta^k(A_ta + F_ta) cos β`, Eq 6 `f_as = μ_as^k(A_as + F_as)` gives
//!
//! `F_ta = μ_as^k(μ_ta^k cos β A_ta + A_as) / (cos β/(1+sin β) − μ_as^k(μ_ta^k cos β + sin β))`
//!
//! exactly as printed (the print's `μ_k` is `μ_as^k`). Note the derivation uses two different
//! expressions for `f_ta` (the torque balance and the kinetic law); we keep the paper's result.
//! The remaining lines are linear in `(y, ζ_y, ζ_z)`; substituting Eq 17's
//! `F_y^c = k_y cos α y − F_ta cos β + f_ta sin γ`, `F_z^c = k_z sin α y − F_ta sin β − f_ta cos γ`
//! (`γ = β − α`, an angle: not the surface energy `γ_L`, docs/errata.md item 10) gives
//! `ζ_y = a_y y + b_y`, `ζ_z = a_z y + b_z` and `y = (ζ_y, ζ_z)·(P, Q)`, solved in closed form.
//! The last line `z = δ(β̃)` is the JKR indentation (Eq 5) under the normal load at the
//! corrected contact angle `β̃`, `P_z = F_ta sin β̃ + f_ta cos β̃ + A_lr` (load plus the
//! long-range attraction that holds the particle down; the JKR adhesion is inside Eq 5).

use crate::physics::contact::jkr::Jkr;

/// Inputs of Eq 18 (SI, angles in rad).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SteadyInputs {
    /// `k_y = k_c/c₂` (N/m).
    pub k_y: f64,
    /// `k_z = k_c` (N/m).
    pub k_z: f64,
    /// `k_yz = k_c/c₃` (N/m).
    pub k_yz: f64,
    /// Tilt `α`.
    pub alpha: f64,
    /// Contact angle `β`.
    pub beta: f64,
    /// `μ_as^k`.
    pub mu_as_k: f64,
    /// `μ_ta^k`.
    pub mu_ta_k: f64,
    /// `A_as` (N).
    pub adhesion_as: f64,
    /// `A_ta` (N).
    pub adhesion_ta: f64,
    /// The long-range part of `A_as` (N): the load the JKR indentation sees on top of `F_as`
    /// (the JKR adhesion itself is inside Eq 5, so it is not added again).
    pub attraction_as: f64,
    /// `Rₐ` (m).
    pub r_a: f64,
}

impl SteadyInputs {
    /// The inputs for a scene's pushing parameters (what `nanopush model` and the sweeps use).
    pub fn from_params(p: &crate::physics::pushing::PushParams) -> SteadyInputs {
        let c = &p.cantilever;
        SteadyInputs {
            k_y: c.k_y(),
            k_z: c.k_z(),
            k_yz: c.k_yz(),
            alpha: c.tilt,
            beta: p.beta,
            mu_as_k: p.mu_as_k,
            mu_ta_k: p.mu_ta_k,
            adhesion_as: p.adhesion_as(),
            adhesion_ta: p.adhesion_ta(),
            attraction_as: p.attraction_as(),
            r_a: p.r_a,
        }
    }
}

/// The steady state of Eq 18.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SteadyState {
    /// Tip-particle normal force `F_ta` (N).
    pub normal_ta: f64,
    /// Tip-particle friction `f_ta = f_as` (N).
    pub friction_ta: f64,
    /// Particle-substrate normal load `F_as = F_ta sin β + μ_ta^k(A_ta + F_ta) cos β` (N), the
    /// derivation's; with it Eq 6 holds, `f_as = μ_as^k(A_as + F_as)`. (It used the torque
    /// balance's `f_ta` in place of the kinetic law's until a test read Eq 6 backwards.)
    pub load_as: f64,
    /// Particle `y` (m): its settling offset behind the stage (Fig 7, 10-13).
    pub y: f64,
    /// `ζ_y` (m).
    pub zeta_y: f64,
    /// `ζ_z` (m): the measured deflection of Figs 10-13.
    pub zeta_z: f64,
    /// `Δy` (m).
    pub delta_y: f64,
    /// `Δz` (m).
    pub delta_z: f64,
    /// Corrected contact angle `β̃` (rad).
    pub beta_tilde: f64,
    /// `F_z = k_y ζ_y sin α − k_z ζ_z cos α` (N).
    pub f_z: f64,
    /// Particle `z = −δ(β̃)` (m), JKR.
    pub z: f64,
}

/// Why Eq 18 has no steady state.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum SteadyError {
    /// `cos β/(1+sin β) ≤ μ_as^k(μ_ta^k cos β + sin β)`: friction grows faster than the push.
    #[error(
        "no kinetic steady state: cos β/(1+sin β) = {lhs:.4} ≤ μ_as^k(μ_ta^k cos β + sin β) = {rhs:.4} (the particle jams under the tip)"
    )]
    Jammed {
        /// `cos β/(1+sin β)`.
        lhs: f64,
        /// `μ_as^k(μ_ta^k cos β + sin β)`.
        rhs: f64,
    },
    /// `1 − a_y P − a_z Q = 0`: the linear system of Eq 18 is singular for these angles.
    #[error("Eq 18 is singular for this tilt and contact angle")]
    Singular,
}

/// Eq 18: the kinetic steady state, or why there is none.
pub fn steady_state(i: &SteadyInputs, jkr_as: &Jkr) -> Result<SteadyState, SteadyError> {
    let (sb, cb) = i.beta.sin_cos();
    let (sa, ca) = i.alpha.sin_cos();
    let gamma = i.beta - i.alpha;
    let (sg, cg) = gamma.sin_cos();
    let lhs = cb / (1.0 + sb);
    let rhs = i.mu_as_k * (i.mu_ta_k * cb + sb);
    if lhs - rhs <= 0.0 {
        return Err(SteadyError::Jammed { lhs, rhs });
    }
    let normal_ta = i.mu_as_k * (i.mu_ta_k * cb * i.adhesion_ta + i.adhesion_as) / (lhs - rhs);
    let friction_ta = normal_ta * cb / (1.0 + sb);
    // F_as as the derivation has it (the tip's load through the kinetic law at the tip), the
    // load with which Eq 6's kinetic law gives back f_as = f_ta for the printed F_ta.
    let load_as = normal_ta * sb + i.mu_ta_k * (i.adhesion_ta + normal_ta) * cb;
    // ζ_y = y cos α − (F_y^c/k_y + F_z^c/k_yz), ζ_z = y sin α − (F_z^c/k_z + F_y^c/k_yz).
    let gy = normal_ta * cb - friction_ta * sg; // −(F_y^c − k_y cos α y)
    let gz = normal_ta * sb + friction_ta * cg; // −(F_z^c − k_z sin α y)
    let a_y = -i.k_z * sa / i.k_yz;
    let b_y = gy / i.k_y + gz / i.k_yz;
    let a_z = -i.k_y * ca / i.k_yz;
    let b_z = gz / i.k_z + gy / i.k_yz;
    let sbcb = sb * cb;
    // y = ζ_y cos α + ζ_z sin α + (ζ_y sin α − ζ_z cos α) sin β cos β.
    let pp = ca + sa * sbcb;
    let qq = sa - ca * sbcb;
    let den = 1.0 - a_y * pp - a_z * qq;
    if den.abs() < 1e-12 {
        return Err(SteadyError::Singular);
    }
    let y = (b_y * pp + b_z * qq) / den;
    let zeta_y = a_y * y + b_y;
    let zeta_z = a_z * y + b_z;
    let lever = zeta_y * sa - zeta_z * ca;
    let delta_y = lever * sbcb;
    let delta_z = lever * sb * sb;
    let beta_tilde = ((i.r_a * sb + delta_z) / (i.r_a * cb - delta_y)).atan();
    let f_z = i.k_y * zeta_y * sa - i.k_z * zeta_z * ca;
    let (sbt, cbt) = beta_tilde.sin_cos();
    let p_z = normal_ta * sbt + friction_ta * cbt + i.attraction_as;
    let z = -jkr_as.indentation_from_load(p_z).unwrap_or(0.0);
    Ok(SteadyState {
        normal_ta,
        friction_ta,
        load_as,
        y,
        zeta_y,
        zeta_z,
        delta_y,
        delta_z,
        beta_tilde,
        f_z,
        z,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn paper() -> SteadyInputs {
        let r_eff = 30e-9 * 1e-6 / (1e-6 + 30e-9);
        SteadyInputs {
            k_y: 1427.0,
            k_z: 8.0,
            k_yz: 123.4,
            alpha: 15f64.to_radians(),
            beta: 30f64.to_radians(),
            mu_as_k: 0.2,
            mu_ta_k: 0.2,
            adhesion_as: 4.0 * std::f64::consts::PI * 1e-6 * 0.072,
            adhesion_ta: 2.0 * std::f64::consts::PI * r_eff * 0.072,
            attraction_as: 4.0 * std::f64::consts::PI * 1e-6 * 0.072,
            r_a: 1e-6,
        }
    }

    fn jkr() -> Jkr {
        Jkr::new(
            1e-6,
            crate::physics::contact::jkr::contact_modulus(3.4e9, 0.34, 169e9, 0.27),
            0.0,
        )
    }

    #[test]
    fn satisfies_its_own_equations() {
        let i = paper();
        let s = steady_state(&i, &jkr()).unwrap();
        let (sb, cb) = i.beta.sin_cos();
        let (sa, ca) = i.alpha.sin_cos();
        let (sg, cg) = (i.beta - i.alpha).sin_cos();
        // Torque balance and the kinetic law as derived.
        let f_as = s.normal_ta * cb - s.friction_ta * sb;
        assert!((f_as - s.friction_ta).abs() < 1e-12 * s.friction_ta);
        let f_as_kin = i.mu_as_k * (i.adhesion_as + s.normal_ta * sb + i.mu_ta_k * (i.adhesion_ta + s.normal_ta) * cb);
        assert!((f_as_kin - s.friction_ta).abs() < 1e-9 * s.friction_ta);
        // The ζ lines.
        let fyc = i.k_y * ca * s.y - s.normal_ta * cb + s.friction_ta * sg;
        let fzc = i.k_z * sa * s.y - s.normal_ta * sb - s.friction_ta * cg;
        assert!((s.zeta_y - (s.y * ca - (fyc / i.k_y + fzc / i.k_yz))).abs() < 1e-18);
        assert!((s.zeta_z - (s.y * sa - (fzc / i.k_z + fyc / i.k_yz))).abs() < 1e-18);
        assert!((s.y - (s.zeta_y * ca + s.zeta_z * sa + s.delta_y)).abs() < 1e-18);
        assert!(s.z < 0.0 && s.z.is_finite());
    }

    #[test]
    fn paper_scene_magnitudes() {
        // F_ta ≈ 410 nN, f_ta ≈ 237 nN for the Sec 5 parameters (hand calculation).
        let s = steady_state(&paper(), &jkr()).unwrap();
        assert!((s.normal_ta - 410e-9).abs() < 2e-9, "{}", s.normal_ta);
        assert!((s.friction_ta - 236.7e-9).abs() < 1e-9);
        assert!(s.y > 0.0 && s.y < 50e-9, "y = {}", s.y);
    }

    /// Eq 18 solved independently, so that a flipped sign of the contact-angle correction `Δy`
    /// shows: Eq 18's three linear lines, written
    /// again from the paper (Eq 17's `F_y^c`, `F_z^c`; `ζ_y`, `ζ_z` and `y = ζ_y cos α +
    /// ζ_z sin α + Δy`, `Δy = (ζ_y sin α − ζ_z cos α) sin β cos β`), are solved as one 3×3
    /// system by LU — a different route from the closed-form substitution — and `y`, `ζ_y`,
    /// `ζ_z` must agree to 1e-9, at the paper's angles and at two others.
    #[test]
    fn the_linear_lines_solved_directly_agree() {
        for (alpha_deg, beta_deg) in [(15.0, 30.0), (5.0, 60.0), (35.0, 20.0)] {
            let mut i = paper();
            i.alpha = f64::to_radians(alpha_deg);
            i.beta = f64::to_radians(beta_deg);
            let s = steady_state(&i, &jkr()).unwrap();
            let (sa, ca) = i.alpha.sin_cos();
            let (sb, cb) = i.beta.sin_cos();
            let (sg, cg) = (i.beta - i.alpha).sin_cos();
            let (fn_, ft) = (s.normal_ta, s.friction_ta);
            // Unknowns (y, ζ_y, ζ_z). F_y^c = k_y ca y + cy, F_z^c = k_z sa y + cz.
            let (cy, cz) = (-fn_ * cb + ft * sg, -fn_ * sb - ft * cg);
            // ζ_y − y ca + F_y^c/k_y + F_z^c/k_yz = 0
            let r1 = [-ca + ca + i.k_z * sa / i.k_yz, 1.0, 0.0, -(cy / i.k_y + cz / i.k_yz)];
            // ζ_z − y sa + F_z^c/k_z + F_y^c/k_yz = 0
            let r2 = [-sa + sa + i.k_y * ca / i.k_yz, 0.0, 1.0, -(cz / i.k_z + cy / i.k_yz)];
            // y − ζ_y ca − ζ_z sa − (ζ_y sa − ζ_z ca) sb cb = 0
            let r3 = [1.0, -ca - sa * sb * cb, -sa + ca * sb * cb, 0.0];
            let a = nalgebra::Matrix3::new(r1[0], r1[1], r1[2], r2[0], r2[1], r2[2], r3[0], r3[1], r3[2]);
            let b = nalgebra::Vector3::new(r1[3], r2[3], r3[3]);
            let x = a.lu().solve(&b).expect("regular");
            let close = |got: f64, want: f64, what: &str| {
                assert!(
                    (got - want).abs() <= 1e-9 * want.abs().max(1e-12),
                    "α {alpha_deg}°, β {beta_deg}°: {what} {got:e} against the direct solve {want:e}"
                )
            };
            close(s.y, x[0], "y");
            close(s.zeta_y, x[1], "ζ_y");
            close(s.zeta_z, x[2], "ζ_z");
        }
        // And the paper scene's figures themselves (Fig 10-13's settled values at α 15°, β 30°).
        let s = steady_state(&paper(), &jkr()).unwrap();
        assert!((s.y - 6.57e-9).abs() < 0.01e-9, "y = {:e}", s.y);
    }

    /// The outputs the linear lines do not fix, each from a relation of its own: `F_as` from
    /// Eq 6's kinetic law read backwards (`f_as = μ_as^k(A_as + F_as)`), `Δz = Δy tan β` (the
    /// contact point moves along the particle's radius at β), `β̃` as the angle of the moved
    /// contact point seen from the particle's centre, `F_z` from the lever's axes, and `z` as the
    /// indentation at which the JKR contact carries `P_z` (Eq 5).
    #[test]
    fn the_other_outputs_by_their_own_relations() {
        let i = paper();
        let j = jkr();
        let s = steady_state(&i, &j).unwrap();
        let rel = |a: f64, b: f64| (a - b).abs() / b.abs();
        assert!(
            rel(s.load_as, s.friction_ta / i.mu_as_k - i.adhesion_as) < 1e-9,
            "F_as {:e}",
            s.load_as
        );
        assert!(s.delta_y != 0.0 && rel(s.delta_z, s.delta_y * i.beta.tan()) < 1e-12);
        let (sa, ca) = i.alpha.sin_cos();
        let (sb, cb) = i.beta.sin_cos();
        assert!(rel(s.delta_y, (s.zeta_y * sa - s.zeta_z * ca) * sb * cb) < 1e-12);
        let contact = nalgebra::Vector2::new(i.r_a * cb - s.delta_y, i.r_a * sb + s.delta_z);
        assert!((s.beta_tilde - contact.y.atan2(contact.x)).abs() < 1e-15);
        assert!(s.beta_tilde != i.beta);
        assert!(rel(s.f_z, i.k_y * s.zeta_y * sa - i.k_z * s.zeta_z * ca) < 1e-12);
        let p_z = s.normal_ta * s.beta_tilde.sin() + s.friction_ta * s.beta_tilde.cos() + i.attraction_as;
        let carried = j.load_from_indentation(-s.z).unwrap();
        assert!(
            s.z < 0.0 && rel(carried, p_z) < 1e-9,
            "JKR carries {carried:e} N at z = {:e}, P_z = {p_z:e}",
            s.z
        );
    }

    /// The inputs a scene gives Eq 18: the paper's values by hand for the default scene
    /// (`k_y`, `k_yz` from Eq 10's c₂, c₃; `A_as = 4πRₐγ_L`, `A_ta = 2πR̃γ_L` once van der
    /// Waals is left out).
    #[test]
    fn inputs_from_the_default_scene() {
        let text = crate::scene::DEFAULT_SCENE.replace("van_der_waals = true", "van_der_waals = false");
        let p = crate::scene::Scene::parse("test", &text).unwrap().push_params();
        let got = SteadyInputs::from_params(&p);
        let want = paper();
        let rel = |a: f64, b: f64| (a - b).abs() / b.abs();
        assert!(got.k_z == 8.0 && rel(got.r_a, 1e-6) < 1e-12);
        assert!(
            rel(got.k_y, want.k_y) < 1e-3 && rel(got.k_yz, want.k_yz) < 1e-3,
            "{got:?}"
        );
        assert!(rel(got.alpha, want.alpha) < 1e-12 && rel(got.beta, want.beta) < 1e-12);
        assert_eq!((got.mu_as_k, got.mu_ta_k), (0.2, 0.2));
        assert!(rel(got.adhesion_as, want.adhesion_as) < 1e-9 && rel(got.adhesion_ta, want.adhesion_ta) < 1e-9);
        assert!(rel(got.attraction_as, want.attraction_as) < 1e-9);
    }

    #[test]
    fn jams_at_high_friction() {
        let mut i = paper();
        i.mu_as_k = 1.2;
        assert!(matches!(steady_state(&i, &jkr()), Err(SteadyError::Jammed { .. })));
    }

    /// A coupling that makes Eq 18's linear system singular is refused, not divided by: with
    /// α = 0 the determinant is `1 − (k_y/k_yz) sin β cos β`, zero (to rounding) at
    /// `k_yz = k_y sin β cos β`. Beside it, 1 % off, the system solves.
    #[test]
    fn a_singular_coupling_is_refused() {
        let mut i = paper();
        i.alpha = 0.0;
        i.k_yz = i.k_y * i.beta.sin() * i.beta.cos();
        assert!(matches!(steady_state(&i, &jkr()), Err(SteadyError::Singular)));
        i.k_yz *= 1.01;
        let s = steady_state(&i, &jkr()).unwrap();
        assert!(s.y.is_finite() && s.y.abs() > 0.0, "{s:?}");
    }
}
