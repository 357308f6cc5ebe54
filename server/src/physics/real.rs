//! A scalar that is either `f64` or a forward-mode dual number.
//!
//! The pushing model's right-hand side is written once, generic over [`Real`]; evaluating it on
//! [`Dual`] numbers seeded with a unit tangent gives one exact column of the Jacobian (no finite
//! differences, no truncation error). Only the operations the model needs are provided.

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
