//! The adaptive driver shared by the methods: step-size control from the embedded error
//! estimate, event location on the dense output, statistics. No heap allocation: everything
//! lives in fixed-size arrays inside [`Integrator`].

// Numerical kernels index several arrays with one loop variable: index loops are clearer.
#![allow(clippy::needless_range_loop)]

use std::time::Instant;

use super::linalg::Lu;
use super::methods::{Method, StepFailure, Work};
use super::problem::{Events, IntegrateError, MAX_DIM, Options, Outcome, Problem, Stats};

/// Most switching functions one problem may have.
pub const MAX_EVENTS: usize = 8;

/// An adaptive integrator for `M y' = f(t, y)`; it keeps its step size between calls, so a
/// control loop calling it once per tick does not restart from a tiny step.
#[derive(Debug, Clone)]
pub struct Integrator {
    method: Method,
    /// Tolerances and limits.
    pub opts: Options,
    h: f64,
    h_old: f64,
    err_old: f64,
    last_rejected: bool,
    work: Work,
    /// `(t, y)` where `work.*_next` and `g_next` are valid: the end of the last call, when it
    /// ended at its end time. A call that starts there skips re-evaluating them.
    cached_at: Option<(f64, [f64; MAX_DIM])>,
    g_next: [f64; MAX_EVENTS],
    /// The algebraic rows' block `∂f_a/∂y_a` of the Jacobian at the ends of the last two
    /// accepted steps of one problem: what locates a fold of those rows ([`fold_time`]).
    balance: Balance,
}

/// Below this fraction of Hadamard's bound an equilibrated block is singular
/// ([`Balance::singular_at`]): some 1e4 ulps, far below the 1e-3..1 of a balance that a step
/// can follow.
const SINGULAR: f64 = 1e-12;

/// The algebraic rows' Jacobian block at the ends of the last two accepted steps.
#[derive(Debug, Clone)]
struct Balance {
    /// Column-major `m × m` blocks.
    blocks: [[f64; MAX_DIM * MAX_DIM]; 2],
    /// Their times (`NaN` where there is none yet).
    times: [f64; 2],
    /// Which of the two is the newer.
    newest: usize,
    /// Rows in a block.
    m: usize,
}

impl Balance {
    fn new() -> Balance {
        Balance {
            blocks: [[0.0; MAX_DIM * MAX_DIM]; 2],
            times: [f64::NAN; 2],
            newest: 0,
            m: 0,
        }
    }

    fn forget(&mut self) {
        self.times = [f64::NAN; 2];
    }

    /// Whether the newer block, from `t`, is singular to working precision: with its rows and
    /// then its columns scaled to a largest entry of 1 (the rows and unknowns are in different
    /// units), `|det|` is under [`SINGULAR`] of the product of its rows' norms (Hadamard's
    /// bound, 1 for orthogonal rows). What tells a fold when an event has just restarted the
    /// balance's history, so that one block is all there is.
    fn singular_at(&self, t: f64) -> bool {
        let m = self.m;
        if m == 0 || self.times[self.newest] != t {
            return false;
        }
        let mut a = [0.0; MAX_DIM * MAX_DIM];
        a[..m * m].copy_from_slice(&self.blocks[self.newest][..m * m]);
        // Column-major: entry (r, c) at c * m + r.
        for r in 0..m {
            let big = (0..m).map(|c| a[c * m + r].abs()).fold(0.0, f64::max);
            if big == 0.0 || !big.is_finite() {
                return big == 0.0;
            }
            (0..m).for_each(|c| a[c * m + r] /= big);
        }
        for c in 0..m {
            let big = a[c * m..c * m + m].iter().fold(0.0f64, |x, v| x.max(v.abs()));
            if big == 0.0 {
                return true;
            }
            a[c * m..c * m + m].iter_mut().for_each(|v| *v /= big);
        }
        let norms: f64 = (0..m)
            .map(|r| (0..m).map(|c| a[c * m + r].powi(2)).sum::<f64>().sqrt())
            .product();
        let mut lu = Lu::default();
        lu.factor(m, &a[..m * m]);
        lu.determinant().abs() <= SINGULAR * norms
    }

    /// `(t, det ∂f_a/∂y_a)` of the older and the newer block.
    fn determinants(&self) -> [(f64, f64); 2] {
        let det = |k: usize| {
            let mut lu = Lu::default();
            lu.factor(self.m, &self.blocks[k][..self.m * self.m]);
            (self.times[k], lu.determinant())
        };
        [det(1 - self.newest), det(self.newest)]
    }
}

/// Where the algebraic rows' balance, followed up to `t` (the last accepted time), ends at a
/// fold, from `(t, det ∂f_a/∂y_a)` at the last two accepted steps (older first): `None` unless
/// they ended at `t` and before it with the determinant of one sign and shrinking.
///
/// At a saddle-node fold of `f_a(y_a, t) = 0` one eigenvalue of `∂f_a/∂y_a` goes to zero as
/// `√(t_f − t)` and the others stay finite: `det²` is linear in `t` near `t_f`, and its line
/// through the last two points crosses zero at `t_f`. The solution cannot be followed to `t_f`
/// itself (its rate grows as `1/√(t_f − t)`), only ever closer: the fold is located when the step
/// collapses there ([`Integrator::at_fold`]).
fn fold_time([(t0, d0), (t1, d1)]: [(f64, f64); 2], t: f64) -> Option<f64> {
    let shrinking = t1 == t && t0 < t1 && d0 * d1 > 0.0 && d1.abs() < d0.abs();
    shrinking.then(|| t1 + d1 * d1 * (t1 - t0) / (d0 * d0 - d1 * d1))
}

impl Integrator {
    /// A new integrator; the first step size is chosen from the problem on the first call.
    pub fn new(method: Method, opts: Options) -> Integrator {
        Integrator {
            method,
            opts,
            h: 0.0,
            h_old: 0.0,
            err_old: 1.0,
            last_rejected: false,
            work: Work::new(method),
            cached_at: None,
            g_next: [f64::NAN; MAX_EVENTS],
            balance: Balance::new(),
        }
    }

    /// Forgets the step-size history and the derivatives kept from the last call: call it
    /// whenever the problem changes (an event switched the mode, a parameter changed). A call
    /// that starts where the previous one ended otherwise reuses `f`, `∂f/∂t`, `J` and the
    /// switching functions evaluated there, assuming the same problem.
    pub fn reset_step(&mut self) {
        self.h_old = 0.0;
        self.err_old = 1.0;
        self.cached_at = None;
        self.balance.forget();
    }

    /// Forgets the derivatives kept from the last call but keeps the step size: for a problem
    /// whose forcing changed at the current time while the state stayed continuous (a new
    /// control segment), where the step-size history is still a good guess.
    pub fn forget_derivatives(&mut self) {
        self.cached_at = None;
        self.balance.forget();
    }

    /// The method (fixed at construction: its workspace is built for it).
    pub fn method(&self) -> Method {
        self.method
    }

    /// The step size the next step will try (s).
    pub fn step_size(&self) -> f64 {
        self.h
    }

    fn error_norm(&self, n: usize) -> f64 {
        let w = &self.work;
        let mut sum = 0.0;
        for i in 0..n {
            let sc = w.abs_tol[i] + self.opts.rtol * w.y0[i].abs().max(w.y1[i].abs());
            sum += (w.err[i] / sc).powi(2);
        }
        (sum / n as f64).sqrt()
    }

    /// Records the algebraic rows' block of the Jacobian just evaluated at the end of an
    /// accepted step (`work.jac_next`) at `t`, when the problem has algebraic rows: a copy, its
    /// determinant taken only when a step collapses ([`Self::at_fold`]).
    fn note_balance(&mut self, t: f64) {
        let w = &self.work;
        let n = w.n;
        let mut alg = [0usize; MAX_DIM];
        let mut m = 0;
        for i in 0..n {
            if w.mass[i] == 0.0 {
                alg[m] = i;
                m += 1;
            }
        }
        if m == 0 {
            return;
        }
        let b = &mut self.balance;
        let slot = 1 - b.newest;
        for (c, &j) in alg[..m].iter().enumerate() {
            for (r, &i) in alg[..m].iter().enumerate() {
                b.blocks[slot][c * m + r] = w.jac_next[j * n + i];
            }
        }
        b.m = m;
        b.times[slot] = t;
        b.newest = slot;
    }

    /// Whether the algebraic rows' balance, followed up to `t` (the last accepted time), has
    /// reached a fold there: `det ∂f_a/∂y_a` changed sign over the last accepted step (a real
    /// eigenvalue crossed zero: the balance lost its stability, and the step landed past the
    /// fold), or [`fold_time`] is nearer than the last accepted step (or within `event_tol`): the
    /// next step at the size the solution allowed so far would cross it. What the driver asks
    /// when no step from `t` is accepted, to tell the end of the solution from a failure to
    /// follow it.
    fn at_fold(&self, t: f64) -> bool {
        let dets = self.balance.determinants();
        let [(t0, d0), (t1, d1)] = dets;
        let crossed = t1 == t && t0 < t1 && d0 * d1 < 0.0;
        let reach = self.opts.event_tol.max(t1 - t0);
        crossed || fold_time(dets, t).is_some_and(|tf| tf - t <= reach) || self.balance.singular_at(t)
    }

    /// Initial step from the size of `y'` (Hairer & Wanner's heuristic, first part).
    fn initial_step<P: Problem>(&self, p: &P, n: usize, span: f64) -> f64 {
        let w = &self.work;
        let mut d = 0.0f64;
        for i in 0..n {
            if w.mass[i] != 0.0 {
                d += (w.f0[i] / w.scale[i]).powi(2);
            }
        }
        let d = (d / n as f64).sqrt();
        let _ = p;
        let h = if d > 1e-300 { 0.01 / d } else { span * 1e-3 };
        h.min(span).max(self.opts.h_min)
    }

    /// Advances `(t, y)` towards `t_end`, stopping early at the first event (a switching
    /// function crossing from positive to non-positive), where `(t, y)` is left within
    /// `event_tol` after the crossing.
    pub fn advance<P: Problem, E: Events>(
        &mut self,
        p: &P,
        events: &E,
        t: &mut f64,
        y: &mut [f64],
        t_end: f64,
    ) -> Result<(Outcome, Stats), IntegrateError> {
        let start = Instant::now();
        let mut st = Stats::default();
        let n = p.len();
        if n > MAX_DIM {
            return Err(IntegrateError::TooLarge { n, max: MAX_DIM });
        }
        let ne = events.count().min(MAX_EVENTS);
        let q = self.method.controller_order();
        self.work.n = n;
        for i in 0..n {
            self.work.mass[i] = p.mass(i);
        }
        // Whether f, ∂f/∂t and J at (t, y) are already in the work arrays (computed at the end of
        // the previous accepted step, possibly in the previous call).
        let mut have_start = matches!(&self.cached_at, Some((tc, yc)) if *tc == *t && yc[..n] == y[..n]);
        let mut g0 = [f64::NAN; MAX_EVENTS];
        if have_start {
            g0 = self.g_next;
        } else if ne > 0 {
            events.eval(*t, y, &mut g0);
        }
        self.cached_at = None;
        let result = loop {
            let remaining = t_end - *t;
            if remaining <= 1e-14 * t_end.abs().max(1e-300) || remaining <= 0.0 {
                break Ok(Outcome::Reached);
            }
            if st.steps + st.rejected >= self.opts.max_steps {
                break Err(IntegrateError::TooManySteps {
                    t: *t,
                    max: self.opts.max_steps,
                });
            }
            if let Err(e) = self.start_data(p, *t, y, n, have_start, remaining, &mut st) {
                break Err(e);
            }
            let mut h = self.h;
            if self.opts.h_max > 0.0 {
                h = h.min(self.opts.h_max);
            }
            // Do not leave a sliver: stretch the last step to the end.
            if h >= remaining || remaining - h < 0.01 * h {
                h = remaining;
            }
            let accepted = self.attempt(p, *t, h, q, &mut st);
            let (h, err, h_new) = match accepted {
                Ok(v) => v,
                // No step gets on from here because the solution ends here: the algebraic
                // rows' balance reached a fold.
                Err(IntegrateError::StepTooSmall { .. }) if self.at_fold(*t) => {
                    break Err(IntegrateError::Fold { t: *t });
                }
                Err(e) => break Err(e),
            };
            st.steps += 1;
            st.max_local_error = st.max_local_error.max(err);
            st.error_sum += err;
            self.h = h_new;
            let t1 = *t + h;
            // The next step's start data, evaluated once here so the events can use it too.
            {
                let w = &mut self.work;
                p.derivatives(
                    t1,
                    &w.y1[..n],
                    &mut w.f_next[..n],
                    &mut w.ft_next[..n],
                    &mut w.jac_next[..n * n],
                );
                st.rhs_evals += 1;
                st.jac_evals += 1;
            }
            self.note_balance(t1);
            // Events: the earliest switching function that went from > 0 to ≤ 0.
            if ne > 0 {
                let (first, g1) = self.first_event(p, events, ne, *t, h, &g0, &mut st);
                if let Some((k, theta)) = first {
                    let mut ye = [0.0; MAX_DIM];
                    self.work.dense(theta, &mut ye[..n]);
                    *t += theta * h;
                    y[..n].copy_from_slice(&ye[..n]);
                    st.events += 1;
                    break Ok(Outcome::Event { index: k });
                }
                g0 = g1;
            }
            *t = if t_end - t1 < 1e-14 * t_end.abs() { t_end } else { t1 };
            y[..n].copy_from_slice(&self.work.y1[..n]);
            have_start = true;
        };
        if result == Ok(Outcome::Reached) && have_start {
            let mut yc = [0.0; MAX_DIM];
            yc[..n].copy_from_slice(&y[..n]);
            self.cached_at = Some((*t, yc));
            self.g_next = g0;
        }
        st.wall_time = start.elapsed().as_secs_f64();
        result.map(|o| (o, st))
    }

    /// The data at the start of a step from `(t, y)`: f, ∂f/∂t and J (reused by every attempt;
    /// taken from the previous accepted step when `have_start`), the error weights, and a first
    /// step size when there is none yet.
    #[allow(clippy::too_many_arguments)]
    fn start_data<P: Problem>(
        &mut self,
        p: &P,
        t: f64,
        y: &[f64],
        n: usize,
        have_start: bool,
        remaining: f64,
        st: &mut Stats,
    ) -> Result<(), IntegrateError> {
        // Data at the start of the step: f, ∂f/∂t, J (reused by every attempt).
        let w = &mut self.work;
        w.y0[..n].copy_from_slice(&y[..n]);
        if have_start {
            w.f0[..n].copy_from_slice(&w.f_next[..n]);
            w.ft[..n].copy_from_slice(&w.ft_next[..n]);
            w.jac[..n * n].copy_from_slice(&w.jac_next[..n * n]);
        } else {
            p.derivatives(t, &w.y0[..n], &mut w.f0[..n], &mut w.ft[..n], &mut w.jac[..n * n]);
            st.rhs_evals += 1;
            st.jac_evals += 1;
        }
        w.rtol = self.opts.rtol;
        for i in 0..n {
            w.abs_tol[i] = self.opts.atol * p.scale(i);
            w.scale[i] = w.abs_tol[i] + self.opts.rtol * w.y0[i].abs();
        }
        if !w.f0[..n].iter().all(|v| v.is_finite()) {
            return Err(IntegrateError::NonFinite { t });
        }
        if self.h <= 0.0 {
            self.h = self.initial_step(p, n, remaining);
        }
        Ok(())
    }

    /// Attempts steps from `t` with `h`, shrinking it after each rejection (a failed Newton
    /// iteration, a singular matrix, a non-finite result, or an error norm above 1), until one
    /// is accepted. Step control: Hairer & Wanner IV.8, with Gustafsson's predictive
    /// controller. Returns the accepted step, its error norm and the next step's size.
    fn attempt<P: Problem>(
        &mut self,
        p: &P,
        t: f64,
        mut h: f64,
        q: f64,
        st: &mut Stats,
    ) -> Result<(f64, f64, f64), IntegrateError> {
        let n = self.work.n;
        loop {
            if h < self.opts.h_min {
                break Err(IntegrateError::StepTooSmall { t, h });
            }
            let r0 = self.work.rhs_evals;
            let f0 = self.work.factorizations;
            let outcome = self.work.step(p, t, h);
            st.rhs_evals += self.work.rhs_evals - r0;
            st.factorizations += self.work.factorizations - f0;
            match outcome {
                Err(StepFailure::Newton) | Err(StepFailure::Singular) => {
                    st.rejected += 1;
                    h *= 0.25;
                    self.last_rejected = true;
                    continue;
                }
                Ok(()) => {}
            }
            let err = self.error_norm(n);
            if !err.is_finite() || !self.work.y1[..n].iter().all(|v| v.is_finite()) {
                st.rejected += 1;
                h *= 0.25;
                self.last_rejected = true;
                continue;
            }
            // Step control (Hairer & Wanner IV.8, with Gustafsson's predictive controller).
            let safe = 0.9;
            let mut fac = (err.powf(1.0 / q) / safe).clamp(1.0 / 6.0, 5.0);
            if err <= 1.0 {
                if self.h_old > 0.0 {
                    let pred =
                        ((self.h_old / h) * (err * err / self.err_old).powf(1.0 / q) / safe).clamp(1.0 / 6.0, 5.0);
                    fac = fac.max(pred);
                }
                let mut h_new = h / fac;
                if self.last_rejected {
                    h_new = h_new.min(h);
                }
                self.h_old = h;
                self.err_old = err.max(1e-2);
                self.last_rejected = false;
                break Ok((h, err, h_new));
            }
            st.rejected += 1;
            self.last_rejected = true;
            h /= fac;
        }
    }

    /// The earliest event in the accepted step `[t, t + h]`: the switching functions at its end
    /// (from the next step's start data), and the first crossing located in it. Returns it (index,
    /// fraction θ of the step) and the functions' values at the end.
    #[allow(clippy::too_many_arguments)]
    fn first_event<P: Problem, E: Events>(
        &self,
        p: &P,
        events: &E,
        ne: usize,
        t: f64,
        h: f64,
        g0: &[f64; MAX_EVENTS],
        st: &mut Stats,
    ) -> (Option<(usize, f64)>, [f64; MAX_EVENTS]) {
        let n = self.work.n;
        let mut g1 = [f64::NAN; MAX_EVENTS];
        let w = &self.work;
        events.eval_at_step(
            t + h,
            &w.y1[..n],
            &w.f_next[..n],
            &w.ft_next[..n],
            &w.jac_next[..n * n],
            &mut g1,
        );
        let mut first: Option<(usize, f64)> = None;
        for k in 0..ne {
            // A crossing from positive to non-positive, or from exactly zero (a mode that
            // starts on its boundary, e.g. a static limit of zero) to negative.
            let crossed = (g0[k] > 0.0 && g1[k] <= 0.0) || (g0[k] == 0.0 && g1[k] < 0.0);
            if crossed
                && let Some(theta) = self.locate(p, events, k, t, h, g0[k], g1[k], &mut st.event_evals)
                && first.is_none_or(|(_, th)| theta < th)
            {
                first = Some((k, theta));
            }
        }
        (first, g1)
    }

    /// Illinois (modified regula falsi) on `θ ↦ g_k(t + θh, y(θ))` with the dense output, to
    /// `event_tol` in time. Returns the right end of the final bracket (`g ≤ 0` there), or
    /// `None` when the function stops applying (NaN) inside the step: then it did not cross.
    /// Counts its evaluations of the switching functions in `evals`.
    #[allow(clippy::too_many_arguments)]
    fn locate<P: Problem, E: Events>(
        &self,
        p: &P,
        events: &E,
        k: usize,
        t: f64,
        h: f64,
        ga: f64,
        gb: f64,
        evals: &mut u64,
    ) -> Option<f64> {
        let n = p.len();
        if ga == 0.0 {
            return Some(0.0);
        }
        let (mut a, mut b) = (0.0f64, 1.0f64);
        let (mut fa, mut fb) = (ga, gb);
        let mut side = 0i32;
        let mut ys = [0.0; MAX_DIM];
        let mut g = [f64::NAN; MAX_EVENTS];
        for _ in 0..200 {
            if (b - a) * h <= self.opts.event_tol {
                break;
            }
            let mut c = (a * fb - b * fa) / (fb - fa);
            if !(c > a && c < b) {
                c = 0.5 * (a + b);
            }
            self.work.dense(c, &mut ys[..n]);
            events.eval(t + c * h, &ys[..n], &mut g);
            *evals += 1;
            let fc = g[k];
            if fc.is_nan() {
                return None;
            }
            if fc > 0.0 {
                a = c;
                fa = fc;
                if side == -1 {
                    fb *= 0.5;
                }
                side = -1;
            } else {
                b = c;
                fb = fc;
                if side == 1 {
                    fa *= 0.5;
                }
                side = 1;
            }
        }
        Some(b)
    }
}

#[cfg(test)]
mod balance_tests {
    use super::*;

    fn with_block(m: usize, col_major: &[f64]) -> Balance {
        let mut b = Balance::new();
        b.blocks[0][..m * m].copy_from_slice(col_major);
        b.times[0] = 1.0;
        b.newest = 0;
        b.m = m;
        b
    }

    /// A block singular to working precision is told whatever the units of its rows and
    /// unknowns; a regular one with entries twenty orders apart is not.
    #[test]
    fn a_singular_balance_is_told_apart_from_a_badly_scaled_one() {
        // Rows in N and m, unknowns in m and N: regular (det ≈ 1 − 1e-10 after scaling).
        assert!(!with_block(2, &[1.0, 1e-20, 1e10, 1.0]).singular_at(1.0));
        // The second row is the first times 1e-20 (plus a rounding's worth): singular.
        let rows = [[3.0, 7.0], [3.0e-20, 7.0e-20 * (1.0 + 1e-15)]];
        let b = with_block(2, &[rows[0][0], rows[1][0], rows[0][1], rows[1][1]]);
        assert!(b.singular_at(1.0));
        // Only the block of the time asked about counts.
        assert!(!b.singular_at(2.0));
        // A diagonal block with entries 1e-30 and 1e30 is as regular as the identity.
        assert!(!with_block(2, &[1e-30, 0.0, 0.0, 1e30]).singular_at(1.0));
    }
}
