//! What an integrator integrates: `M y' = f(t, y)` with a diagonal mass matrix, and the
//! switching functions whose zeros are events.

/// Largest state dimension the integrators handle; their workspaces are fixed-size arrays of
/// this length, so a step allocates nothing.
pub const MAX_DIM: usize = 12;

/// A semi-explicit DAE `M y' = f(t, y)`, `M` diagonal with entries 1 (differential row) or 0
/// (algebraic row, index 1).
pub trait Problem {
    /// Dimension (≤ [`MAX_DIM`]).
    fn len(&self) -> usize;
    /// Whether the problem has no state (clippy's `len_without_is_empty`; the integrators do not
    /// call it).
    fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// Diagonal of `M`.
    fn mass(&self, i: usize) -> f64;
    /// `f(t, y)` into `out[..len]`.
    fn rhs(&self, t: f64, y: &[f64], out: &mut [f64]);
    /// `∂f/∂y` into `jac`, column-major `len × len`.
    fn jacobian(&self, t: f64, y: &[f64], jac: &mut [f64]);
    /// `∂f/∂t` into `out` (zero for autonomous problems).
    fn time_derivative(&self, _t: f64, _y: &[f64], out: &mut [f64]) {
        out[..self.len()].fill(0.0);
    }
    /// `f`, `∂f/∂t` and `J` together (a problem that can compute them in one pass overrides it).
    fn derivatives(&self, t: f64, y: &[f64], f: &mut [f64], ft: &mut [f64], jac: &mut [f64]) {
        self.rhs(t, y, f);
        self.time_derivative(t, y, ft);
        self.jacobian(t, y, jac);
    }
    /// Typical magnitude of component `i`: the absolute tolerance is `atol · scale(i)`.
    fn scale(&self, _i: usize) -> f64 {
        1.0
    }
}

/// Switching functions `g_k(t, y)`: an event is a sign change from positive to negative.
pub trait Events {
    /// Number of switching functions.
    fn count(&self) -> usize;
    /// Values into `out[..count]`; `f64::NAN` marks one that does not apply now.
    fn eval(&self, t: f64, y: &[f64], out: &mut [f64]);
    /// The same at the end of an accepted step, where the driver has already evaluated `f`,
    /// `∂f/∂t` and the Jacobian (column-major) for the next step: switching functions that need
    /// derivatives can reuse them.
    fn eval_at_step(&self, t: f64, y: &[f64], _f: &[f64], _ft: &[f64], _jac: &[f64], out: &mut [f64]) {
        self.eval(t, y, out);
    }
}

/// No events.
pub struct NoEvents;

impl Events for NoEvents {
    fn count(&self) -> usize {
        0
    }
    fn eval(&self, _t: f64, _y: &[f64], _out: &mut [f64]) {}
}

/// Step-size control and tolerances.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Options {
    /// Relative tolerance.
    pub rtol: f64,
    /// Absolute tolerance, multiplied by each component's [`Problem::scale`].
    pub atol: f64,
    /// Smallest step (s) before the integrator gives up.
    pub h_min: f64,
    /// Largest step (s); 0 = no limit.
    pub h_max: f64,
    /// Most steps in one call.
    pub max_steps: u64,
    /// Event location tolerance in time (s).
    pub event_tol: f64,
}

impl Options {
    /// Tolerances `rtol` and `atol = rtol` (of each component's scale), no step limit.
    pub fn with_rtol(rtol: f64) -> Options {
        Options {
            rtol,
            atol: rtol,
            h_min: 1e-20,
            h_max: 0.0,
            max_steps: 1_000_000,
            event_tol: 1e-15,
        }
    }
}

impl Default for Options {
    fn default() -> Self {
        Options::with_rtol(1e-6)
    }
}

/// Work done by one call.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Stats {
    /// Accepted steps.
    pub steps: u64,
    /// Rejected steps (error too large or Newton failure).
    pub rejected: u64,
    /// Right-hand side evaluations.
    pub rhs_evals: u64,
    /// Jacobian evaluations.
    pub jac_evals: u64,
    /// LU factorizations.
    pub factorizations: u64,
    /// Largest weighted local error estimate of an accepted step (1 = at tolerance).
    pub max_local_error: f64,
    /// Sum of the accepted steps' weighted local error norms (dimensionless, 1 = at
    /// tolerance): a crude upper bound on the global error in units of the tolerance.
    pub error_sum: f64,
    /// Events located.
    pub events: u64,
    /// Switching-function evaluations made to locate events (on the dense output).
    pub event_evals: u64,
    /// Wall time of the call (s).
    pub wall_time: f64,
}

impl Stats {
    /// Adds another call's work.
    pub fn add(&mut self, o: &Stats) {
        self.steps += o.steps;
        self.rejected += o.rejected;
        self.rhs_evals += o.rhs_evals;
        self.jac_evals += o.jac_evals;
        self.factorizations += o.factorizations;
        self.max_local_error = self.max_local_error.max(o.max_local_error);
        self.error_sum += o.error_sum;
        self.events += o.events;
        self.event_evals += o.event_evals;
        self.wall_time += o.wall_time;
    }
}

/// Why integration stopped early.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum IntegrateError {
    /// The step fell below `h_min`.
    #[error("step size {h:.3e} s fell below the minimum at t = {t:.3e} s")]
    StepTooSmall {
        /// Time reached.
        t: f64,
        /// Step tried.
        h: f64,
    },
    /// The algebraic rows' balance ends at a fold: their Jacobian `∂f_a/∂y_a` turns singular at a
    /// saddle-node, where the solution `y_a(t)` runs into `t_f` with a square-root law and has no
    /// continuation past it (the step size collapses approaching it). Located as an event: `t`
    /// is the last accepted time, nearer to `t_f` than the last accepted step.
    #[error(
        "the algebraic rows' balance ends at a fold at t = {t:.6e} s: their Jacobian turns singular and no solution continues"
    )]
    Fold {
        /// Time reached.
        t: f64,
    },
    /// More than `max_steps` steps.
    #[error("more than {max} steps before t = {t:e} s")]
    TooManySteps {
        /// Time reached.
        t: f64,
        /// The limit.
        max: u64,
    },
    /// The right-hand side produced a non-finite value.
    #[error("non-finite state at t = {t:.3e} s")]
    NonFinite {
        /// Time reached.
        t: f64,
    },
    /// The problem is larger than the integrator's workspace.
    #[error("dimension {n} exceeds the integrator's maximum {max}")]
    TooLarge {
        /// Dimension.
        n: usize,
        /// Maximum.
        max: usize,
    },
}

/// How a call ended.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Outcome {
    /// The end time was reached.
    Reached,
    /// Switching function `index` crossed zero at the returned time (state at the event).
    Event {
        /// Which switching function.
        index: usize,
    },
}

#[cfg(test)]
mod tests {
    use super::Stats;

    /// Every counter adds up and the largest local error is kept (the run reports, the
    /// accuracy table and docs/validation.md's step counts read these).
    #[test]
    fn stats_add_every_field() {
        let mut a = Stats {
            steps: 2,
            rejected: 3,
            rhs_evals: 5,
            jac_evals: 7,
            factorizations: 11,
            max_local_error: 0.5,
            error_sum: 1.5,
            events: 13,
            event_evals: 41,
            wall_time: 0.25,
        };
        let b = Stats {
            steps: 17,
            rejected: 19,
            rhs_evals: 23,
            jac_evals: 29,
            factorizations: 31,
            max_local_error: 0.75,
            error_sum: 2.5,
            events: 37,
            event_evals: 43,
            wall_time: 0.5,
        };
        a.add(&b);
        let sum = Stats {
            steps: 19,
            rejected: 22,
            rhs_evals: 28,
            jac_evals: 36,
            factorizations: 42,
            max_local_error: 0.75,
            error_sum: 4.0,
            events: 50,
            event_evals: 84,
            wall_time: 0.75,
        };
        assert_eq!(a, sum);
        a.add(&Stats::default());
        assert_eq!(a, sum, "adding nothing changes nothing (the larger error stays)");
    }
}
