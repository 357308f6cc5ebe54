//! A scalar that is either `f64` or a forward-mode dual number.
//!
//! The pushing model's right-hand side is written once, generic over [`Real`]; evaluating it on
//! [`Dual`] numbers seeded with a unit tangent gives one exact column of the Jacobian (no finite
//! differences, no truncation error). Only the operations the model needs are provided.
//!
//! Kept rather than the `num-dual` crate: the model's Jacobian pass on [`DualN`] takes 220 ns
//! (9 lanes) and 237 ns (13 lanes) against the crate's `DualSVec64` at 372 ns and 489 ns
//! (`benches/dual.rs`, one run on 2026-11-26, docs/own-or-crate.md): the crate keeps its lanes in
//! an `Option` and branches on it in every operation. The scalar [`Dual`] ties with `Dual64`
//! (16.2 ns against 17.0 ns through the long-range forces, 15.5 ns against 14.7 ns through JKR) and
//! stays with its lanes version: same rules, bit-identical results (num-dual's `sqrt` gives NaN
//! where a zero tangent meets the infinite slope at 0, and its `powf`, `ln` and `atan2` round
//! differently).

// Lane loops index several arrays at once.
#![allow(clippy::needless_range_loop)]

use std::ops::{Add, AddAssign, Div, Mul, Neg, Sub};

/// The scalar operations the physics needs, for `f64` and [`Dual`].
pub trait Real:
    Copy
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + Div<Output = Self>
    + Neg<Output = Self>
    + AddAssign
    + Add<f64, Output = Self>
    + Sub<f64, Output = Self>
    + Mul<f64, Output = Self>
    + Div<f64, Output = Self>
    + PartialOrd
{
    /// A constant (zero derivative).
    fn cst(v: f64) -> Self;
    /// The value, without derivative.
    fn re(self) -> f64;
    /// Square root.
    fn sqrt(self) -> Self;
    /// Natural logarithm.
    fn ln(self) -> Self;
    /// Real power.
    fn powf(self, n: f64) -> Self;
    /// Reciprocal.
    fn recip(self) -> Self {
        Self::cst(1.0) / self
    }
    /// `atan2(self, x)`: the angle of the vector `(x, self)` (rad).
    fn atan2(self, x: Self) -> Self;
    /// The larger of `self` and a constant (the derivative follows the chosen branch).
    fn max_c(self, c: f64) -> Self {
        if self.re() >= c { self } else { Self::cst(c) }
    }
}

impl Real for f64 {
    fn cst(v: f64) -> Self {
        v
    }
    fn re(self) -> f64 {
        self
    }
    fn sqrt(self) -> Self {
        f64::sqrt(self)
    }
    fn ln(self) -> Self {
        f64::ln(self)
    }
    fn powf(self, n: f64) -> Self {
        f64::powf(self, n)
    }
    fn atan2(self, x: Self) -> Self {
        f64::atan2(self, x)
    }
}

/// A first-order dual number `re + eps·ε` with `ε² = 0`.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Dual {
    /// Value.
    pub re: f64,
    /// Derivative along the seeded direction.
    pub eps: f64,
}

impl Dual {
    /// The active variable: value `v`, derivative 1.
    pub fn var(v: f64) -> Self {
        Dual { re: v, eps: 1.0 }
    }
    /// A value with a given derivative.
    pub fn new(re: f64, eps: f64) -> Self {
        Dual { re, eps }
    }
}

impl PartialOrd for Dual {
    fn partial_cmp(&self, other: &Self) -> Option<std::cmp::Ordering> {
        self.re.partial_cmp(&other.re)
    }
}

impl Add for Dual {
    type Output = Dual;
    fn add(self, o: Dual) -> Dual {
        Dual::new(self.re + o.re, self.eps + o.eps)
    }
}
impl Sub for Dual {
    type Output = Dual;
    fn sub(self, o: Dual) -> Dual {
        Dual::new(self.re - o.re, self.eps - o.eps)
    }
}
impl Mul for Dual {
    type Output = Dual;
    fn mul(self, o: Dual) -> Dual {
        Dual::new(self.re * o.re, self.re * o.eps + self.eps * o.re)
    }
}
impl Div for Dual {
    type Output = Dual;
    fn div(self, o: Dual) -> Dual {
        let inv = 1.0 / o.re;
        Dual::new(self.re * inv, (self.eps * o.re - self.re * o.eps) * inv * inv)
    }
}
impl Neg for Dual {
    type Output = Dual;
    fn neg(self) -> Dual {
        Dual::new(-self.re, -self.eps)
    }
}
impl AddAssign for Dual {
    fn add_assign(&mut self, o: Dual) {
        self.re += o.re;
        self.eps += o.eps;
    }
}
impl Add<f64> for Dual {
    type Output = Dual;
    fn add(self, o: f64) -> Dual {
        Dual::new(self.re + o, self.eps)
    }
}
impl Sub<f64> for Dual {
    type Output = Dual;
    fn sub(self, o: f64) -> Dual {
        Dual::new(self.re - o, self.eps)
    }
}
impl Mul<f64> for Dual {
    type Output = Dual;
    fn mul(self, o: f64) -> Dual {
        Dual::new(self.re * o, self.eps * o)
    }
}
impl Div<f64> for Dual {
    type Output = Dual;
    fn div(self, o: f64) -> Dual {
        Dual::new(self.re / o, self.eps / o)
    }
}

impl Real for Dual {
    fn cst(v: f64) -> Self {
        Dual::new(v, 0.0)
    }
    fn re(self) -> f64 {
        self.re
    }
    fn sqrt(self) -> Self {
        let s = self.re.sqrt();
        // At 0 the derivative is infinite; with a zero tangent the product is taken as 0.
        let d = if self.eps == 0.0 { 0.0 } else { self.eps * 0.5 / s };
        Dual::new(s, d)
    }
    fn ln(self) -> Self {
        Dual::new(self.re.ln(), self.eps / self.re)
    }
    fn powf(self, n: f64) -> Self {
        let p = self.re.powf(n - 1.0);
        Dual::new(p * self.re, n * p * self.eps)
    }
    fn atan2(self, x: Self) -> Self {
        let r2 = x.re * x.re + self.re * self.re;
        Dual::new(self.re.atan2(x.re), (x.re * self.eps - self.re * x.eps) / r2)
    }
}

/// `f(x)` and `f'(x)` of a scalar function written over [`Real`].
pub fn derivative(f: impl Fn(Dual) -> Dual, x: f64) -> (f64, f64) {
    let d = f(Dual::var(x));
    (d.re, d.eps)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dual_rules_match_calculus() {
        // d/dx [x^2.5 / ln(x) + sqrt(x)] at x = 3, by hand.
        let x = 3.0_f64;
        let (v, d) = derivative(|x| x.powf(2.5) / x.ln() + x.sqrt(), x);
        let expected_v = x.powf(2.5) / x.ln() + x.sqrt();
        let expected_d = (2.5 * x.powf(1.5) * x.ln() - x.powf(2.5) / x) / (x.ln() * x.ln()) + 0.5 / x.sqrt();
        assert!((v - expected_v).abs() < 1e-12);
        assert!((d - expected_d).abs() < 1e-12, "{d} vs {expected_d}");
    }

    #[test]
    fn max_c_follows_branch() {
        assert_eq!(Dual::var(2.0).max_c(1.0).eps, 1.0);
        assert_eq!(Dual::var(0.5).max_c(1.0).eps, 0.0);
    }
}

/// A forward-mode dual number with `N` tangent lanes: one evaluation gives `N` directional
/// derivatives at once (the whole Jacobian, plus `∂/∂t`, in one pass through the model).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DualN<const N: usize> {
    /// Value.
    pub re: f64,
    /// Derivatives along the `N` seeded directions.
    pub eps: [f64; N],
}

impl<const N: usize> DualN<N> {
    /// A value with zero derivatives.
    pub fn constant(re: f64) -> Self {
        DualN { re, eps: [0.0; N] }
    }
    /// The active variable of lane `lane`.
    pub fn seed(re: f64, lane: usize) -> Self {
        let mut eps = [0.0; N];
        eps[lane] = 1.0;
        DualN { re, eps }
    }
    #[inline]
    fn chain(self, re: f64, d: f64) -> Self {
        let mut eps = self.eps;
        for e in eps.iter_mut() {
            *e *= d;
        }
        DualN { re, eps }
    }
}

impl<const N: usize> PartialOrd for DualN<N> {
    fn partial_cmp(&self, other: &Self) -> Option<std::cmp::Ordering> {
        self.re.partial_cmp(&other.re)
    }
}

impl<const N: usize> Add for DualN<N> {
    type Output = Self;
    #[inline]
    fn add(mut self, o: Self) -> Self {
        self.re += o.re;
        for (a, b) in self.eps.iter_mut().zip(o.eps) {
            *a += b;
        }
        self
    }
}
impl<const N: usize> Sub for DualN<N> {
    type Output = Self;
    #[inline]
    fn sub(mut self, o: Self) -> Self {
        self.re -= o.re;
        for (a, b) in self.eps.iter_mut().zip(o.eps) {
            *a -= b;
        }
        self
    }
}
impl<const N: usize> Mul for DualN<N> {
    type Output = Self;
    #[inline]
    fn mul(self, o: Self) -> Self {
        let mut eps = [0.0; N];
        for i in 0..N {
            eps[i] = self.re * o.eps[i] + self.eps[i] * o.re;
        }
        DualN {
            re: self.re * o.re,
            eps,
        }
    }
}
impl<const N: usize> Div for DualN<N> {
    type Output = Self;
    #[inline]
    fn div(self, o: Self) -> Self {
        let inv = 1.0 / o.re;
        let q = self.re * inv;
        let mut eps = [0.0; N];
        for i in 0..N {
            eps[i] = (self.eps[i] - q * o.eps[i]) * inv;
        }
        DualN { re: q, eps }
    }
}
impl<const N: usize> Neg for DualN<N> {
    type Output = Self;
    #[inline]
    fn neg(self) -> Self {
        self.chain(-self.re, -1.0)
    }
}
impl<const N: usize> AddAssign for DualN<N> {
    #[inline]
    fn add_assign(&mut self, o: Self) {
        *self = *self + o;
    }
}
impl<const N: usize> Add<f64> for DualN<N> {
    type Output = Self;
    #[inline]
    fn add(mut self, o: f64) -> Self {
        self.re += o;
        self
    }
}
impl<const N: usize> Sub<f64> for DualN<N> {
    type Output = Self;
    #[inline]
    fn sub(mut self, o: f64) -> Self {
        self.re -= o;
        self
    }
}
impl<const N: usize> Mul<f64> for DualN<N> {
    type Output = Self;
    #[inline]
    fn mul(self, o: f64) -> Self {
        self.chain(self.re * o, o)
    }
}
impl<const N: usize> Div<f64> for DualN<N> {
    type Output = Self;
    #[inline]
    fn div(self, o: f64) -> Self {
        self.chain(self.re / o, 1.0 / o)
    }
}

impl<const N: usize> Real for DualN<N> {
    fn cst(v: f64) -> Self {
        DualN::constant(v)
    }
    fn re(self) -> f64 {
        self.re
    }
    fn sqrt(self) -> Self {
        let s = self.re.sqrt();
        if s == 0.0 {
            // Infinite slope at 0: with zero tangents the product is taken as 0.
            let mut eps = [0.0; N];
            for (e, &d) in eps.iter_mut().zip(self.eps.iter()) {
                *e = if d == 0.0 { 0.0 } else { d * f64::INFINITY };
            }
            return DualN { re: s, eps };
        }
        self.chain(s, 0.5 / s)
    }
    fn ln(self) -> Self {
        self.chain(self.re.ln(), 1.0 / self.re)
    }
    fn powf(self, n: f64) -> Self {
        let p = self.re.powf(n - 1.0);
        self.chain(p * self.re, n * p)
    }
    fn atan2(self, x: Self) -> Self {
        let r2 = x.re * x.re + self.re * self.re;
        let mut eps = [0.0; N];
        for i in 0..N {
            eps[i] = (x.re * self.eps[i] - self.re * x.eps[i]) / r2;
        }
        DualN {
            re: self.re.atan2(x.re),
            eps,
        }
    }
}

#[cfg(test)]
mod dualn_tests {
    use super::*;

    #[test]
    fn lanes_match_scalar_duals() {
        // f(x, y) = atan2(y, x)·sqrt(x² + y²)/ln(x) + (x/y)^1.5: both partials at once.
        let f = |x: DualN<2>, y: DualN<2>| y.atan2(x) * (x * x + y * y).sqrt() / x.ln() + (x / y).powf(1.5);
        let v = f(DualN::seed(3.0, 0), DualN::seed(2.0, 1));
        let g = |x: Dual, y: Dual| y.atan2(x) * (x * x + y * y).sqrt() / x.ln() + (x / y).powf(1.5);
        let dx = g(Dual::var(3.0), Dual::new(2.0, 0.0));
        let dy = g(Dual::new(3.0, 0.0), Dual::var(2.0));
        assert!((v.re - dx.re).abs() < 1e-15);
        assert!((v.eps[0] - dx.eps).abs() < 1e-14 && (v.eps[1] - dy.eps).abs() < 1e-14);
    }
}

/// Every operation of [`Real`], on `f64`, [`Dual`] and [`DualN`], against `std` for the values and
/// central finite differences for the derivatives (an independent reference, not the rules
/// themselves). Found by `make mutants`: the `f64` impl's `ln` and `powf`, `recip`, the orderings
/// and most of the `DualN` operators had no test of their own.
#[cfg(test)]
mod every_operation {
    use super::*;

    /// Uses every operator and function of the trait once, and the `f64`-operand forms.
    fn f<T: Real>(x: T, y: T) -> T {
        let mut a = (x * y - y / x) + (-x) * 0.75 - x / 3.0 + (y + 2.0) - (x - 0.5);
        a += x.sqrt() * y.ln() + (x * y).powf(1.7) + y.recip() + y.atan2(x) + (x - 2.5).max_c(0.1);
        a
    }

    fn reference(x: f64, y: f64) -> f64 {
        (x * y - y / x) + (-x) * 0.75 - x / 3.0 + (y + 2.0) - (x - 0.5)
            + x.sqrt() * y.ln()
            + (x * y).powf(1.7)
            + 1.0 / y
            + y.atan2(x)
            + f64::max(x - 2.5, 0.1)
    }

    #[test]
    fn values_and_derivatives_match_std_and_finite_differences() {
        for (x, y) in [(3.1, 1.7), (0.8, 2.9), (2.0, 0.6)] {
            let v = reference(x, y);
            assert!((f(x, y) - v).abs() < 1e-12 * v.abs(), "f64 at ({x}, {y})");
            let h = 1e-6;
            let dx = (reference(x + h, y) - reference(x - h, y)) / (2.0 * h);
            let dy = (reference(x, y + h) - reference(x, y - h)) / (2.0 * h);
            let gx = f(Dual::var(x), Dual::new(y, 0.0));
            let gy = f(Dual::new(x, 0.0), Dual::var(y));
            assert!((gx.re - v).abs() < 1e-12 * v.abs() && (gy.re - v).abs() < 1e-12 * v.abs());
            assert!(
                (gx.eps - dx).abs() < 1e-6 * dx.abs().max(1.0),
                "∂x at ({x}, {y}): {} vs {dx}",
                gx.eps
            );
            assert!(
                (gy.eps - dy).abs() < 1e-6 * dy.abs().max(1.0),
                "∂y at ({x}, {y}): {} vs {dy}",
                gy.eps
            );
            // Three lanes: x, y, and the direction (1, 1).
            let lanes = |l: usize| -> [f64; 3] {
                let mut e = [0.0; 3];
                e[l] = 1.0;
                e[2] = 1.0;
                e
            };
            let n = f(DualN::<3> { re: x, eps: lanes(0) }, DualN::<3> { re: y, eps: lanes(1) });
            assert!((n.re - v).abs() < 1e-12 * v.abs());
            assert!((n.eps[0] - gx.eps).abs() < 1e-12 * gx.eps.abs().max(1.0), "lane x");
            assert!((n.eps[1] - gy.eps).abs() < 1e-12 * gy.eps.abs().max(1.0), "lane y");
            assert!((n.eps[2] - (gx.eps + gy.eps)).abs() < 1e-12 * (gx.eps + gy.eps).abs().max(1.0));
        }
    }

    #[test]
    fn constants_values_and_order() {
        assert_eq!(<f64 as Real>::cst(2.5), 2.5);
        assert_eq!(Dual::cst(2.5), Dual::new(2.5, 0.0));
        assert_eq!(DualN::<2>::cst(2.5), DualN::constant(2.5));
        assert_eq!((Dual::new(4.0, 1.0).re(), DualN::<2>::seed(4.0, 1).re()), (4.0, 4.0));
        assert_eq!(DualN::<2>::seed(4.0, 1).eps, [0.0, 1.0]);
        assert_eq!(<f64 as Real>::recip(4.0), 0.25);
        assert_eq!(Dual::var(4.0).recip(), Dual::new(0.25, -1.0 / 16.0));
        // Ordering is by value alone, whatever the derivatives.
        assert!(Dual::new(1.0, 5.0) < Dual::new(2.0, -5.0));
        assert!(DualN::<2>::seed(1.0, 0) < DualN::<2>::seed(2.0, 1));
        assert!(DualN::<2>::seed(3.0, 0) > DualN::<2>::constant(2.0));
        assert_eq!(
            Dual::new(1.0, 5.0).partial_cmp(&Dual::new(1.0, -5.0)),
            Some(std::cmp::Ordering::Equal)
        );
        // A square root at 0 with no tangent has no (infinite) derivative.
        assert_eq!(Dual::new(0.0, 0.0).sqrt(), Dual::new(0.0, 0.0));
        assert_eq!(DualN::<2>::constant(0.0).sqrt().eps, [0.0, 0.0]);
        assert_eq!(DualN::<2>::seed(0.0, 0).sqrt().eps, [f64::INFINITY, 0.0]);
        let down = DualN::<2> {
            re: 0.0,
            eps: [-2.0, 0.0],
        };
        assert_eq!(down.sqrt().eps, [f64::NEG_INFINITY, 0.0]);
        assert_eq!(Dual::var(0.0).sqrt().eps, f64::INFINITY);
    }
}
