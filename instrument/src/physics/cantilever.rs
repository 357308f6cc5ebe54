//! The cantilever: compliance matrix (Eq 10), measured deflection (Eq 11), lateral force from
//! the deflection (Eq 12), and the dynamic parameters of Sec 2.5.

use nalgebra::{Matrix2, Matrix3, Vector3};

/// Cantilever geometry and material, SI.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Cantilever {
    /// Normal stiffness `k_c` (N/m).
    pub k_c: f64,
    /// Width `L_x` (m).
    pub l_x: f64,
    /// Length `L_y` (m).
    pub l_y: f64,
    /// Tip height `L_z` (m).
    pub l_z: f64,
    /// Thickness `t_c` (m).
    pub t_c: f64,
    /// First flexural resonance `f_r` (Hz).
    pub f_r: f64,
    /// Quality factor in air `Q_c`.
    pub q_c: f64,
    /// Tilt `α` about the x axis (rad).
    pub tilt: f64,
}

impl Cantilever {
    /// `c₁ = 2L_z²/L_y² + t_c²/L_x²` (Eq 10).
    pub fn c1(&self) -> f64 {
        2.0 * self.l_z * self.l_z / (self.l_y * self.l_y) + self.t_c * self.t_c / (self.l_x * self.l_x)
    }
    /// `c₂ = 3L_z²/L_y²` (Eq 10).
    pub fn c2(&self) -> f64 {
        3.0 * self.l_z * self.l_z / (self.l_y * self.l_y)
    }
    /// `c₃ = 3L_z/(2L_y)` (Eq 10).
    pub fn c3(&self) -> f64 {
        1.5 * self.l_z / self.l_y
    }

    /// Eq 10: `ζ = C F`, `C = (1/k_c) [[c₁,0,0],[0,c₂,c₃],[0,c₃,1]]` (m/N), in the cantilever's
    /// own axes. Symmetric positive definite: `c₂ − c₃² = (3/4)L_z²/L_y² > 0`.
    pub fn compliance(&self) -> Matrix3<f64> {
        let (c1, c2, c3) = (self.c1(), self.c2(), self.c3());
        Matrix3::new(c1, 0.0, 0.0, 0.0, c2, c3, 0.0, c3, 1.0) / self.k_c
    }

    /// The y-z block of `C` (m/N).
    pub fn compliance_yz(&self) -> Matrix2<f64> {
        Matrix2::new(self.c2(), self.c3(), self.c3(), 1.0) / self.k_c
    }

    /// The y-z stiffness `K = C_yz⁻¹` (N/m): the exact inverse of the compliance, which the
    /// dynamics use (Eq 17's `k_y`, `k_z`, `k_yz` coupling terms are its first-order form).
    pub fn stiffness_yz(&self) -> Matrix2<f64> {
        let (c2, c3) = (self.c2(), self.c3());
        let det = c2 - c3 * c3;
        Matrix2::new(1.0, -c3, -c3, c2) * (self.k_c / det)
    }

    /// Sec 2.5: `k_y = k_c/c₂` (N/m): 1427 N/m for the paper's cantilever.
    pub fn k_y(&self) -> f64 {
        self.k_c / self.c2()
    }
    /// Sec 2.5: `k_z = k_c` (N/m).
    pub fn k_z(&self) -> f64 {
        self.k_c
    }
    /// Sec 2.5: `k_yz = k_c/c₃` (N/m; printed `k_xy`): 123.4 N/m for the paper's cantilever.
    pub fn k_yz(&self) -> f64 {
        self.k_c / self.c3()
    }

    /// Effective mass `m_c* = k_z/(4π² f_r²)` (kg) — the print omits the square (docs/errata.md item 8).
    pub fn effective_mass(&self) -> f64 {
        self.k_z() / (4.0 * std::f64::consts::PI.powi(2) * self.f_r * self.f_r)
    }

    /// Damping `b_y = b_z = 2π f_r m_c*/Q_c` (N·s/m), Sec 2.5.
    pub fn damping(&self) -> f64 {
        2.0 * std::f64::consts::PI * self.f_r * self.effective_mass() / self.q_c
    }

    /// Eq 10 applied: the deflection (m) under a force given in the cantilever's axes (N).
    pub fn deflection(&self, force: Vector3<f64>) -> Vector3<f64> {
        self.compliance() * force
    }

    /// Eq 11: the measured (normal) deflection `ζ_z = (c₃F_y + F_z)/k_c` (m).
    pub fn measured_deflection(&self, f_y: f64, f_z: f64) -> f64 {
        (self.c3() * f_y + f_z) / self.k_c
    }

    /// Eq 12: the change of lateral force from a change of measured deflection, assuming the
    /// normal force constant: `ΔF_y = k_c Δζ_z / c₃` (N).
    pub fn lateral_force_change(&self, d_zeta_z: f64) -> f64 {
        self.k_c * d_zeta_z / self.c3()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    pub(crate) fn paper() -> Cantilever {
        Cantilever {
            k_c: 8.0,
            l_x: 50e-6,
            l_y: 155e-6,
            l_z: 6.7e-6,
            t_c: 2.4e-6,
            f_r: 138e3,
            q_c: 100.0,
            tilt: 15f64.to_radians(),
        }
    }

    /// docs/model.md's reason the default scene is quasi-static ("The pushing dynamics (Eq 17)"):
    /// the lever's lateral mode (the stiff axis of `K = C_yz⁻¹`, the larger eigenvalue
    /// `(a+d)/2 + √(((a−d)/2)² + b²)` by hand) rings at `√(λ/m_c*)/2π` = 3.7 MHz, and with the
    /// paper's `b_y = b_z` (the model damps both axes alike) its quality factor `√(λ m_c*)/b_y` is
    /// ≈ 2700 (= Q_c √(λ/k_z), 2677).
    #[test]
    fn the_default_levers_lateral_mode_has_its_documented_frequency_and_q() {
        let c = crate::scene::Scene::default_scene().cantilever();
        let k = c.stiffness_yz();
        let (a, b, d) = (k[(0, 0)], k[(0, 1)], k[(1, 1)]);
        let lateral = 0.5 * (a + d) + (0.25 * (a - d).powi(2) + b * b).sqrt();
        let m = c.effective_mass();
        let f = (lateral / m).sqrt() / (2.0 * std::f64::consts::PI);
        let q = (lateral * m).sqrt() / c.damping();
        assert!((f - 3.7e6).abs() < 0.05e6, "lateral mode at {f:e} Hz");
        assert!((q - 2700.0).abs() < 50.0, "Q {q}");
        assert!((q / (c.q_c * (lateral / c.k_z()).sqrt()) - 1.0).abs() < 1e-12);
    }

    #[test]
    fn paper_stiffnesses() {
        // docs/errata.md item 9.
        let c = paper();
        assert!((c.c2() - 0.005605).abs() < 1e-6);
        assert!((c.c3() - 0.06484).abs() < 1e-5);
        assert!((c.k_y() - 1427.0).abs() < 1.0, "{}", c.k_y());
        assert!((c.k_yz() - 123.4).abs() < 0.1, "{}", c.k_yz());
    }

    #[test]
    fn paper_c1_by_hand() {
        // c₁ = 2L_z²/L_y² + t_c²/L_x² = 2(6.7/155)² + (2.4/50)² = 0.0037370 + 0.002304 = 0.0060410,
        // the x-x compliance (Eq 10) times k_c: an x force of 1 µN bends the tip 0.755 nm.
        let c = paper();
        assert!((c.c1() - 0.0060410).abs() < 1e-7, "{}", c.c1());
        let d = c.deflection(Vector3::new(1e-6, 0.0, 0.0));
        assert!(
            (d.x - 0.0060410e-6 / 8.0).abs() < 2e-14 && d.y == 0.0 && d.z == 0.0,
            "{d}"
        );
    }

    #[test]
    fn effective_mass_uses_f_squared() {
        let c = paper();
        let m = c.effective_mass();
        // The resonance of m* on k_z is f_r.
        let f = (c.k_z() / m).sqrt() / (2.0 * std::f64::consts::PI);
        assert!((f - c.f_r).abs() < 1e-6 * c.f_r);
    }

    #[test]
    fn damping_by_hand() {
        // b = 2π f_r m*/Q_c = 2π · 138 kHz · 10.64 ng / 100 = 92.26 nN·s/m.
        let c = paper();
        assert!((c.damping() - 9.226e-8).abs() < 0.002e-8, "{}", c.damping());
        // Equivalently the damping ratio of the normal mode is 1/(2Q).
        let zeta = c.damping() / (2.0 * (c.k_z() * c.effective_mass()).sqrt());
        assert!((zeta - 0.005).abs() < 1e-12);
    }

    #[test]
    fn stiffness_inverts_compliance() {
        let c = paper();
        let i = c.stiffness_yz() * c.compliance_yz();
        assert!((i - Matrix2::identity()).abs().max() < 1e-12);
    }

    #[test]
    fn eq11_eq12_round_trip() {
        let c = paper();
        let z0 = c.measured_deflection(0.0, 5e-9);
        let z1 = c.measured_deflection(100e-9, 5e-9);
        assert!((c.lateral_force_change(z1 - z0) - 100e-9).abs() < 1e-18);
        // Eq 11 is the third row of Eq 10.
        let d = c.deflection(Vector3::new(0.0, 100e-9, 5e-9));
        assert!((d.z - z1).abs() < 1e-24);
    }

    proptest! {
        #[test]
        fn compliance_is_symmetric_positive_definite(
            k in 0.01..500.0_f64, lx in 1e-6..1000e-6_f64, ly in 5e-6..5000e-6_f64,
            lz in 0.5e-6..100e-6_f64, t in 0.05e-6..50e-6_f64,
        ) {
            let c = Cantilever { k_c: k, l_x: lx, l_y: ly, l_z: lz, t_c: t, f_r: 1e5, q_c: 100.0, tilt: 0.2 };
            let m = c.compliance();
            prop_assert!((m - m.transpose()).abs().max() == 0.0);
            prop_assert!(m.cholesky().is_some(), "not SPD: {}", m);
            let e = m.symmetric_eigenvalues();
            prop_assert!(e.iter().all(|&v| v > 0.0 && v.is_finite()));
        }
    }
}
