//! Electrostatic force from the work-function (contact) potential, Eq 4.

use crate::numerics::dual::Real;

/// Vacuum permittivity ε₀ (F/m).
pub const EPSILON_0: f64 = 8.854_187_812_8e-12;

/// Elementary charge (C).
pub const ELEMENTARY_CHARGE: f64 = 1.602_176_634e-19;

/// Contact potential `U = (φ₁ − φ₂)/e` (V) from two work functions given in eV: with φ in eV
/// the division by `e` is the change of unit, so `U` is simply the difference.
pub fn contact_potential(phi1_ev: f64, phi2_ev: f64) -> f64 {
    phi1_ev - phi2_ev
}

/// One electrostatic pair: `U` and the shared area `S`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Electrostatic {
    /// Potential difference `U` (V).
    pub voltage: f64,
    /// Shared area `S` (m²): `4πR̃r₁` tip-particle, `4πRₐr₁` particle-substrate (Sec 2.2.3).
    pub area: f64,
    /// Interatomic cut-off `a₀` (m).
    pub a0: f64,
}

impl Electrostatic {
    /// Eq 4: `F_el(h) = −ε₀U²S/(2h²)` (N, attractive), with `h` clamped to `a₀` (docs/errata.md item 3).
    pub fn force<T: Real>(&self, h: T) -> T {
        let h = h.max_c(self.a0);
        -(T::cst(EPSILON_0 * self.voltage * self.voltage * self.area * 0.5) / (h * h))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn paper_figures() {
        // docs/errata.md: Rt = 30 nm, Ra = 250 nm, r1 = 1.7 nm, U = 0.25 V: 158 pN at 1 nm, 1.6 pN at 10 nm.
        let r_eff = 30e-9 * 250e-9 / 280e-9;
        let e = Electrostatic {
            voltage: 0.25,
            area: 4.0 * std::f64::consts::PI * r_eff * 1.7e-9,
            a0: 0.165e-9,
        };
        let f1: f64 = e.force(1e-9);
        let f10: f64 = e.force(10e-9);
        assert!((f1 + 158e-12).abs() < 1e-12, "{f1}");
        assert!((f10 + 1.58e-12).abs() < 0.02e-12, "{f10}");
        // 1/h² law: 100x weaker at 10x the distance.
        assert!((f1 / f10 - 100.0).abs() < 1e-9);
    }

    proptest::proptest! {
        #[test]
        fn electrostatic_is_finite_and_attractive(u in -10.0..10.0_f64, r in 1e-9..10e-6_f64, r1 in 0.0..100e-9_f64, h in -1e-9..1e-4_f64) {
            let e = Electrostatic { voltage: u, area: 4.0 * std::f64::consts::PI * r * r1, a0: 0.165e-9 };
            let f: f64 = e.force(h);
            proptest::prop_assert!(f.is_finite() && f <= 0.0);
        }
    }

    #[test]
    fn contact_potential_from_work_functions() {
        // Gold 5.1 eV against silicon 4.85 eV gives the paper's 0.25 V.
        assert!((contact_potential(5.1, 4.85) - 0.25).abs() < 1e-12);
    }
}
