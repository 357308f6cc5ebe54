//! Reference problems with published or exact solutions, to show that the methods and their
//! error estimates are honest.

use super::problem::Problem;

/// A linear stiff system `y' = A y`, `A = [[−1000, 999], [0, −1]]` (eigenvalues −1000, −1),
/// started on the slow eigenvector `(1, 1)`: the exact solution is `y = (e^{−t}, e^{−t})`.
/// Linear and autonomous, so no method suffers order reduction on it: the observed order of
/// convergence is the classical order.
pub struct LinearStiff;

impl LinearStiff {
    /// Initial value.
    pub const Y0: [f64; 2] = [1.0, 1.0];
    /// Exact solution at `t`.
    pub fn exact(t: f64) -> [f64; 2] {
        let e = (-t).exp();
        [e, e]
    }
}

impl Problem for LinearStiff {
    fn len(&self) -> usize {
        2
    }
    fn mass(&self, _i: usize) -> f64 {
        1.0
    }
    fn rhs(&self, _t: f64, y: &[f64], out: &mut [f64]) {
        out[0] = -1000.0 * y[0] + 999.0 * y[1];
        out[1] = -y[1];
    }
    fn jacobian(&self, _t: f64, _y: &[f64], jac: &mut [f64]) {
        jac[..4].copy_from_slice(&[-1000.0, 0.0, 999.0, -1.0]);
    }
}

/// Van der Pol's oscillator in Hairer & Wanner's stiff scaling (*Solving ODEs II*, Sec IV.1 and
/// their test set): `y₁' = y₂`, `y₂' = ((1 − y₁²)y₂ − y₁)/ε`, `ε = 10⁻⁶` (μ = 10⁶ in the unscaled
/// form), `y(0) = (2, 0)`.
pub struct VanDerPol {
    /// `ε`.
    pub eps: f64,
}

impl VanDerPol {
    /// Initial value.
    pub const Y0: [f64; 2] = [2.0, 0.0];
    /// End time of the published reference.
    pub const T_END: f64 = 2.0;
    /// Published reference at `t = 2` for `ε = 10⁻⁶` (Hairer's test set, computed with RADAU5
    /// at tolerance 1e-18).
    pub const REFERENCE: [f64; 2] = [1.706_167_732_170_483, -0.892_809_701_024_797_5];
}

impl Problem for VanDerPol {
    fn len(&self) -> usize {
        2
    }
    fn mass(&self, _i: usize) -> f64 {
        1.0
    }
    fn rhs(&self, _t: f64, y: &[f64], out: &mut [f64]) {
        out[0] = y[1];
        out[1] = ((1.0 - y[0] * y[0]) * y[1] - y[0]) / self.eps;
    }
    fn jacobian(&self, _t: f64, y: &[f64], jac: &mut [f64]) {
        jac[0] = 0.0;
        jac[1] = (-2.0 * y[0] * y[1] - 1.0) / self.eps;
        jac[2] = 1.0;
        jac[3] = (1.0 - y[0] * y[0]) / self.eps;
    }
}

/// Robertson's chemical kinetics (Hairer & Wanner, Sec IV.1; test set "ROBER"):
/// `y₁' = −0.04y₁ + 10⁴y₂y₃`, `y₂' = 0.04y₁ − 10⁴y₂y₃ − 3·10⁷y₂²`, `y₃' = 3·10⁷y₂²`,
/// `y(0) = (1, 0, 0)`, integrated to `t = 10¹¹`.
pub struct Robertson;

impl Robertson {
    /// Initial value.
    pub const Y0: [f64; 3] = [1.0, 0.0, 0.0];
    /// End time of the published reference.
    pub const T_END: f64 = 1e11;
    /// Published reference at `t = 10¹¹` (the IVP test set of Mazzia et al.).
    pub const REFERENCE: [f64; 3] = [
        0.208_334_014_970_125_5e-7,
        0.833_336_077_033_471_3e-13,
        0.999_999_979_166_505,
    ];
}

impl Problem for Robertson {
    fn len(&self) -> usize {
        3
    }
    fn mass(&self, _i: usize) -> f64 {
        1.0
    }
    fn rhs(&self, _t: f64, y: &[f64], out: &mut [f64]) {
        let r1 = 0.04 * y[0];
        let r2 = 1e4 * y[1] * y[2];
        let r3 = 3e7 * y[1] * y[1];
        out[0] = -r1 + r2;
        out[1] = r1 - r2 - r3;
        out[2] = r3;
    }
    fn jacobian(&self, _t: f64, y: &[f64], jac: &mut [f64]) {
        // Column-major: column j is ∂f/∂y_j.
        jac[..9].copy_from_slice(&[
            -0.04,
            0.04,
            0.0,
            1e4 * y[2],
            -1e4 * y[2] - 6e7 * y[1],
            6e7 * y[1],
            1e4 * y[1],
            -1e4 * y[1],
            0.0,
        ]);
    }
    fn scale(&self, i: usize) -> f64 {
        // y₁ ends at 2e-8 and y₂ lives around 1e-5..1e-13: the absolute tolerances must sit far
        // below those values for the published digits to be reachable.
        if i == 1 { 1e-12 } else { 1e-6 }
    }
}

/// Prothero & Robinson's problem, made nonlinear: `y' = λ(y − φ) + φ' + (y − φ)²` with
/// `φ(t) = sin(t) + cos(2t)`, `y(0) = φ(0)`: the exact solution is `y = φ(t)` for any `λ`
/// (Prothero & Robinson, Math. Comp. 28, 1974; Hairer & Wanner, *Solving ODEs II*, Sec IV.15).
/// Time-dependent through `φ`, so a method that drops `∂f/∂t` or evaluates its stages at the
/// wrong times loses its order on it, unlike on an autonomous problem.
pub struct ProtheroRobinson {
    /// `λ` (negative: the larger `|λ|`, the stiffer).
    pub lambda: f64,
}

impl ProtheroRobinson {
    /// `φ(t)`, the exact solution.
    pub fn phi(t: f64) -> f64 {
        t.sin() + (2.0 * t).cos()
    }
    fn dphi(t: f64) -> f64 {
        t.cos() - 2.0 * (2.0 * t).sin()
    }
    fn ddphi(t: f64) -> f64 {
        -t.sin() - 4.0 * (2.0 * t).cos()
    }
}

impl Problem for ProtheroRobinson {
    fn len(&self) -> usize {
        1
    }
    fn mass(&self, _i: usize) -> f64 {
        1.0
    }
    fn rhs(&self, t: f64, y: &[f64], out: &mut [f64]) {
        let e = y[0] - Self::phi(t);
        out[0] = self.lambda * e + Self::dphi(t) + e * e;
    }
    fn jacobian(&self, t: f64, y: &[f64], jac: &mut [f64]) {
        jac[0] = self.lambda + 2.0 * (y[0] - Self::phi(t));
    }
    /// `∂f/∂t = −(λ + 2e) φ' + φ''`, `e = y − φ`.
    fn time_derivative(&self, t: f64, y: &[f64], out: &mut [f64]) {
        let e = y[0] - Self::phi(t);
        out[0] = -(self.lambda + 2.0 * e) * Self::dphi(t) + Self::ddphi(t);
    }
}

/// The largest relative component error of `y` against `reference`.
pub fn max_relative_error(y: &[f64], reference: &[f64]) -> f64 {
    y.iter()
        .zip(reference)
        .map(|(a, b)| ((a - b) / b.abs().max(1e-300)).abs())
        .fold(0.0, f64::max)
}
