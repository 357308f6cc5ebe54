//! The four one-step methods, written for `M y' = f(t, y)` with diagonal `M`:
//!
//! - **Rodas4** (Hairer & Wanner, *Solving ODEs II*, Sec VI.4; the coefficients of their code
//!   RODAS): a 6-stage linearly implicit Rosenbrock method of order 4 with an embedded order-3
//!   solution, L-stable and stiffly accurate, index-1 DAEs included, with a 3rd-order dense
//!   output. One Jacobian and one LU per step, no Newton iteration.
//! - **Rodas5P** (G. Steinebach, "Construction of Rosenbrock–Wanner method Rodas5P and
//!   numerical benchmarks within the Julia Differential Equations package", *BIT Numerical
//!   Mathematics* 63, 27 (2023)): the same kind of method with 8 stages, order 5 with an
//!   embedded order-4 solution, L-stable and stiffly accurate, with a 4th-order dense output.
//!   Two more right-hand sides and solves per step than Rodas4, for one order more.
//! - **TR-BDF2** (Bank et al. 1985; as an ESDIRK by Hosea & Shampine, *Appl. Numer. Math.* 20,
//!   1996): trapezoidal stage to `γh`, BDF2 stage to `h`, `γ = 2 − √2`; order 2, L-stable,
//!   stiffly accurate, embedded order-3 estimate filtered by `(M − hdJ)⁻¹`, quadratic dense
//!   output through its stages. Simplified Newton on each implicit stage.
//! - **Implicit Euler**: order 1, L-stable; the baseline. Its error estimate is
//!   `(M − hJ)⁻¹ (h/2)(f(t₁, y₁) − f(t₀, y₀))` (the filtered `h²y''/2`), dense output linear.

// Numerical kernels index several arrays with one loop variable: index loops are clearer.
#![allow(clippy::needless_range_loop)]

use super::linalg::Lu;
use super::problem::{MAX_DIM, Problem};
use super::rosenbrock::{RODAS4, RODAS5P, Rosenbrock};

/// An integration method.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Method {
    /// Rosenbrock, order 4(3).
    Rodas4,
    /// Rosenbrock, order 5(4).
    Rodas5P,
    /// ESDIRK TR-BDF2, order 2(3).
    TrBdf2,
    /// Implicit Euler, order 1.
    ImplicitEuler,
}

impl Method {
    /// All methods.
    pub const ALL: [Method; 4] = [Method::Rodas4, Method::Rodas5P, Method::TrBdf2, Method::ImplicitEuler];

    /// Command-line name.
    pub fn name(self) -> &'static str {
        match self {
            Method::Rodas4 => "rodas4",
            Method::Rodas5P => "rodas5p",
            Method::TrBdf2 => "trbdf2",
            Method::ImplicitEuler => "implicit-euler",
        }
    }

    /// Parses a command-line name.
    pub fn parse(s: &str) -> Option<Method> {
        Method::ALL.into_iter().find(|m| m.name() == s)
    }

    /// Classical order of the method.
    pub fn order(self) -> u32 {
        match self {
            Method::Rodas4 => 4,
            Method::Rodas5P => 5,
            Method::TrBdf2 => 2,
            Method::ImplicitEuler => 1,
        }
    }

    /// The Rosenbrock method for a tolerance `rtol`, where the tolerance sets the steps: Rodas5P
    /// at `rtol` ≤ 1e-3, Rodas4 above. Measured with `nanopush accuracy` on Van der Pol and
    /// Robertson (docs/validation.md): from 1e-3 down Rodas5P reaches every error level sooner
    /// than Rodas4; at 1e-2 Rodas4's cheaper step is faster. Where something else caps the step
    /// (the push's 1 ms ticks and 0.1 ms samples) that measurement does not apply, and the push
    /// keeps Rodas4: on the minimal scene a tick is one step, cheaper with Rodas4.
    pub fn for_tolerance(rtol: f64) -> Method {
        if rtol <= 1e-3 { Method::Rodas5P } else { Method::Rodas4 }
    }

    /// Order of the error estimate plus one: the exponent of the step controller.
    pub(crate) fn controller_order(self) -> f64 {
        match self {
            Method::Rodas4 => 4.0,
            Method::Rodas5P => 5.0,
            Method::TrBdf2 => 3.0,
            Method::ImplicitEuler => 2.0,
        }
    }
}

type Vector = [f64; MAX_DIM];

/// Per-step data shared by the methods, and the dense output of the last accepted step.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Work {
    pub n: usize,
    pub mass: Vector,
    pub y0: Vector,
    pub f0: Vector,
    pub ft: Vector,
    pub jac: [f64; MAX_DIM * MAX_DIM],
    /// `f`, `∂f/∂t` and `J` at the end of the last accepted step: the next step's start data.
    pub f_next: Vector,
    pub ft_next: Vector,
    pub jac_next: [f64; MAX_DIM * MAX_DIM],
    pub y1: Vector,
    pub err: Vector,
    lu: Lu,
    /// The stages (Rodas4 uses six, Rodas5P eight).
    k: [Vector; 8],
    tmp: Vector,
    tmp2: Vector,
    /// Error-norm scale `atol·scaleᵢ + rtol·|y₀ᵢ|`, set by the driver; the Newton test uses it.
    pub scale: Vector,
    /// The absolute part alone, `atol·scaleᵢ`.
    pub abs_tol: Vector,
    /// The relative tolerance (for the Newton rounding floor).
    pub rtol: f64,
    /// Dense output: Rodas4 uses the first two, Rodas5P all three (the coefficients `h_r` of
    /// [`Rosenbrock`]); TR-BDF2 the stage at `γh` in the first; implicit Euler none.
    cont: [Vector; 3],
    method: Method,
    pub rhs_evals: u64,
    pub factorizations: u64,
}

/// Why a step attempt failed (the driver shrinks the step and tries again).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum StepFailure {
    /// The iteration matrix was singular.
    Singular,
    /// Newton did not converge.
    Newton,
}

// TR-BDF2 (Hosea & Shampine 1996).
const T_GAMMA: f64 = 2.0 - std::f64::consts::SQRT_2;
const T_D: f64 = T_GAMMA / 2.0;
const T_W: f64 = std::f64::consts::SQRT_2 / 4.0;

impl Work {
    pub fn new(method: Method) -> Work {
        Work {
            n: 0,
            mass: [0.0; MAX_DIM],
            y0: [0.0; MAX_DIM],
            f0: [0.0; MAX_DIM],
            ft: [0.0; MAX_DIM],
            jac: [0.0; MAX_DIM * MAX_DIM],
            f_next: [0.0; MAX_DIM],
            ft_next: [0.0; MAX_DIM],
            jac_next: [0.0; MAX_DIM * MAX_DIM],
            y1: [0.0; MAX_DIM],
            err: [0.0; MAX_DIM],
            lu: Lu::default(),
            k: [[0.0; MAX_DIM]; 8],
            tmp: [0.0; MAX_DIM],
            tmp2: [0.0; MAX_DIM],
            scale: [1.0; MAX_DIM],
            abs_tol: [1.0; MAX_DIM],
            rtol: 1e-6,
            cont: [[0.0; MAX_DIM]; 3],
            method,
            rhs_evals: 0,
            factorizations: 0,
        }
    }

    /// Factorizes `M/(hg) − J` (Rodas form) or `M − hgJ` (implicit form).
    fn factor(&mut self, diag: impl Fn(f64) -> f64, jac_factor: f64) -> bool {
        let n = self.n;
        let mut a = [0.0; MAX_DIM * MAX_DIM];
        for j in 0..n {
            for i in 0..n {
                a[j * n + i] = jac_factor * self.jac[j * n + i];
            }
            a[j * n + j] += diag(self.mass[j]);
        }
        self.factorizations += 1;
        self.lu.factor(n, &a)
    }

    /// One attempt of a step of size `h` from `(t, y0)` (with `f0`, `ft`, `jac` already set).
    /// On success `y1` and `err` hold the new state and the local error estimate.
    pub fn step<P: Problem>(&mut self, p: &P, t: f64, h: f64) -> Result<(), StepFailure> {
        match self.method {
            Method::Rodas4 => self.rosenbrock(p, t, h, &RODAS4),
            Method::Rodas5P => self.rosenbrock(p, t, h, &RODAS5P),
            Method::TrBdf2 => self.trbdf2(p, t, h),
            Method::ImplicitEuler => self.implicit_euler(p, t, h),
        }
    }

    /// One step of the Rosenbrock method `tab` (the equations are [`Rosenbrock`]'s).
    #[inline(always)]
    fn rosenbrock<P: Problem, const S: usize, const D: usize>(
        &mut self,
        p: &P,
        t: f64,
        h: f64,
        tab: &Rosenbrock<S, D>,
    ) -> Result<(), StepFailure> {
        let n = self.n;
        if !self.factor(|m| m / (h * tab.gamma), -1.0) {
            return Err(StepFailure::Singular);
        }
        // Stage 1.
        for i in 0..n {
            self.k[0][i] = self.f0[i] + h * tab.d[0] * self.ft[i];
        }
        self.lu.solve(&mut self.k[0][..n]);
        // Stages 2..S.
        for s in 1..S {
            for i in 0..n {
                let mut v = self.y0[i];
                for j in 0..s {
                    v += tab.a[s][j] * self.k[j][i];
                }
                self.tmp[i] = v;
            }
            p.rhs(t + tab.alpha[s] * h, &self.tmp[..n], &mut self.tmp2[..n]);
            self.rhs_evals += 1;
            for i in 0..n {
                let mut c = 0.0;
                for j in 0..s {
                    c += tab.c[s][j] * self.k[j][i];
                }
                self.k[s][i] = self.tmp2[i] + tab.d[s] * h * self.ft[i] + self.mass[i] * c / h;
            }
            self.lu.solve(&mut self.k[s][..n]);
        }
        // tmp holds the last stage's argument y0 + Σ a_Sj kj; the solution adds k_S, the error is k_S.
        let last = S - 1;
        for i in 0..n {
            self.y1[i] = self.tmp[i] + self.k[last][i];
            self.err[i] = self.k[last][i];
            for r in 0..D {
                let mut c = 0.0;
                for j in 0..tab.dense_stages {
                    c += tab.h[r][j] * self.k[j][i];
                }
                self.cont[r][i] = c;
            }
        }
        Ok(())
    }

    /// Simplified Newton for the implicit stage `M(Y − y₀) − h·d·(f(ts, Y) + E) = 0` (`E` the
    /// explicit part of the stage), started at `y`; the iteration matrix `M − h d J` is
    /// factorized already. Leaves the stage value in `y` and `f(ts, Y)` in `fy`. Converged when
    /// the weighted update is below 1e-3 of the tolerance (or contracting below 1e-2).
    fn newton<P: Problem>(
        &mut self,
        p: &P,
        ts: f64,
        hd: f64,
        explicit: &Vector,
        y: &mut Vector,
        fy: &mut Vector,
    ) -> Result<(), StepFailure> {
        let n = self.n;
        let mut prev = f64::INFINITY;
        for iter in 0..10 {
            p.rhs(ts, &y[..n], &mut fy[..n]);
            self.rhs_evals += 1;
            let mut dy = [0.0; MAX_DIM];
            for i in 0..n {
                dy[i] = hd * (fy[i] + explicit[i]) - self.mass[i] * (y[i] - self.y0[i]);
            }
            self.lu.solve(&mut dy[..n]);
            let mut norm = 0.0;
            for i in 0..n {
                y[i] += dy[i];
                norm += (dy[i] / self.scale[i]).powi(2);
            }
            let norm = (norm / n as f64).sqrt();
            if !norm.is_finite() {
                return Err(StepFailure::Newton);
            }
            // Converged when the update is far below the tolerance (or, contracting at rate θ,
            // the remaining error θ/(1−θ)·norm is), or when it is down at the rounding floor of the
            // state that the tolerance cannot see below (Hairer & Wanner IV.8).
            let theta = if iter > 0 { norm / prev } else { 0.5 };
            let floor = 1e2 * f64::EPSILON / self.rtol.max(1e-300);
            if norm < 1e-3 || norm < floor || (iter > 0 && theta < 1.0 && theta / (1.0 - theta) * norm < 0.03) {
                p.rhs(ts, &y[..n], &mut fy[..n]);
                self.rhs_evals += 1;
                return Ok(());
            }
            if iter > 1 && norm > 0.9 * prev {
                return Err(StepFailure::Newton);
            }
            prev = norm;
        }
        Err(StepFailure::Newton)
    }

    fn trbdf2<P: Problem>(&mut self, p: &P, t: f64, h: f64) -> Result<(), StepFailure> {
        let n = self.n;
        let hd = h * T_D;
        if !self.factor(|m| m, -hd) {
            return Err(StepFailure::Singular);
        }
        // Stage 2 at t + γh: M(Y₂ − y₀) = h d (f₀ + f(Y₂)).
        let explicit2 = self.f0;
        let mut y2 = self.y0;
        let mut f2 = [0.0; MAX_DIM];
        self.newton(p, t + T_GAMMA * h, hd, &explicit2, &mut y2, &mut f2)?;
        // Stage 3 at t + h: M(Y₃ − y₀) = h (w f₀ + w f₂ + d f(Y₃)).
        let mut explicit3 = [0.0; MAX_DIM];
        let mut y3 = [0.0; MAX_DIM];
        for i in 0..n {
            explicit3[i] = T_W * (self.f0[i] + f2[i]) / T_D;
            y3[i] = self.y0[i] + (y2[i] - self.y0[i]) / T_GAMMA;
        }
        let mut f3 = [0.0; MAX_DIM];
        self.newton(p, t + h, hd, &explicit3, &mut y3, &mut f3)?;
        // Error: (M − hdJ)⁻¹ h Σ (bᵢ − b̂ᵢ) Fᵢ with b = (w, w, d), b̂ = ((1−w)/3, (3w+1)/3, d/3).
        let e = [T_W - (1.0 - T_W) / 3.0, T_W - (3.0 * T_W + 1.0) / 3.0, T_D - T_D / 3.0];
        for i in 0..n {
            self.err[i] = h * (e[0] * self.f0[i] + e[1] * f2[i] + e[2] * f3[i]);
            self.y1[i] = y3[i];
            self.cont[0][i] = y2[i];
        }
        self.lu.solve(&mut self.err[..n]);
        Ok(())
    }

    fn implicit_euler<P: Problem>(&mut self, p: &P, t: f64, h: f64) -> Result<(), StepFailure> {
        let n = self.n;
        if !self.factor(|m| m, -h) {
            return Err(StepFailure::Singular);
        }
        let mut y = self.y0;
        let mut f1 = [0.0; MAX_DIM];
        self.newton(p, t + h, h, &[0.0; MAX_DIM], &mut y, &mut f1)?;
        for i in 0..n {
            self.y1[i] = y[i];
            self.err[i] = 0.5 * h * (f1[i] - self.f0[i]);
        }
        self.lu.solve(&mut self.err[..n]);
        Ok(())
    }

    /// Dense output at `θ ∈ [0, 1]` of the last accepted step (`y0` → `y1`).
    pub fn dense(&self, theta: f64, out: &mut [f64]) {
        let n = self.n;
        match self.method {
            Method::Rodas4 => {
                let s1 = 1.0 - theta;
                let [c1, c2, _] = &self.cont;
                for i in 0..n {
                    out[i] = s1 * self.y0[i] + theta * (self.y1[i] + s1 * (c1[i] + theta * c2[i]));
                }
            }
            Method::Rodas5P => {
                let s1 = 1.0 - theta;
                let [c1, c2, c3] = &self.cont;
                for i in 0..n {
                    out[i] = s1 * self.y0[i] + theta * (self.y1[i] + s1 * (c1[i] + theta * (c2[i] + theta * c3[i])));
                }
            }
            Method::TrBdf2 => {
                // Quadratic through (0, y0), (γ, Y2), (1, y1).
                let g = T_GAMMA;
                let l0 = (theta - g) * (theta - 1.0) / g;
                let l1 = theta * (theta - 1.0) / (g * (g - 1.0));
                let l2 = theta * (theta - g) / (1.0 - g);
                for i in 0..n {
                    out[i] = l0 * self.y0[i] + l1 * self.cont[0][i] + l2 * self.y1[i];
                }
            }
            Method::ImplicitEuler => {
                for i in 0..n {
                    out[i] = (1.0 - theta) * self.y0[i] + theta * self.y1[i];
                }
            }
        }
    }
}
