//! The work-precision report: error against run time for each method and tolerance, on the
//! scene's push and on two classical stiff problems with published references.
//!
//! Error norms (all against a reference solution):
//! - **final**: the largest absolute difference of the position states (m) at the end time;
//! - **trajectory L2**: the RMS over the samples (every 0.1 ms) of the particle's y and the
//!   measured deflection ζ_z, in m.
//!
//! The reference is the same model with Rodas4 at `rtol = 1e-12` (the finest tolerance at which
//! the quasi-static scenes still integrate cleanly in double precision), cross-checked against
//! TR-BDF2 at `rtol = 1e-10`; the report prints their difference.
//!
//! [`reduction`] compares the quasi-static reduction with the full model on what a push does
//! (regime, `t*`, settled `y` and `ζ_z`), rotation on and off.

use std::time::Instant;

use nanopush_instrument::numerics::integrate::test_problems::{Robertson, VanDerPol};
use nanopush_instrument::numerics::integrate::{Integrator, Method, NoEvents, Options, Problem};
use nanopush_instrument::physics::pushing::PushModel;
use nanopush_instrument::physics::pushing::trace::{PushRun, run_push};
use nanopush_proto::accuracy::AccuracyPoint;

pub mod reduction;

/// One method at one tolerance.
#[derive(Debug, Clone, PartialEq)]
pub struct Point {
    /// Problem name.
    pub problem: String,
    /// Method.
    pub method: Method,
    /// Relative tolerance.
    pub rtol: f64,
    /// Final-time error (problem units; m for the push).
    pub final_error: f64,
    /// Trajectory L2 error (m; NaN for the reference problems).
    pub trajectory_error: f64,
    /// The error estimated without the reference: the largest difference from the same
    /// method's runs at finer tolerances, in the units of `final_error` (see
    /// [`estimate_errors`]); NaN at the finest tolerance and where no finer run differs beyond
    /// rounding.
    pub estimated_error: f64,
    /// The finer tolerance whose run gave `estimated_error` (NaN with it).
    pub estimate_rtol: f64,
    /// The values the final error is measured on (positions for the push, the state for the
    /// classical problems), for the estimate.
    pub final_values: Vec<f64>,
    /// Median wall time of the repetitions (s).
    pub wall_time: f64,
    /// Accepted steps.
    pub steps: u64,
    /// Rejected steps.
    pub rejected: u64,
    /// Why the run failed, if it did.
    pub failure: Option<String>,
}

impl Point {
    /// A run that failed: no errors, the failure's message.
    fn failed(problem: &str, method: Method, rtol: f64, wall_time: f64, failure: String) -> Point {
        Point {
            problem: problem.into(),
            method,
            rtol,
            final_error: f64::NAN,
            trajectory_error: f64::NAN,
            estimated_error: f64::NAN,
            estimate_rtol: f64::NAN,
            final_values: Vec::new(),
            wall_time,
            steps: 0,
            rejected: 0,
            failure: Some(failure),
        }
    }
}

impl From<&Point> for AccuracyPoint {
    /// The report's row: an error that is not a number (a failed run, no estimate) is absent.
    fn from(p: &Point) -> AccuracyPoint {
        let opt = |v: f64| v.is_finite().then_some(v);
        AccuracyPoint {
            problem: p.problem.clone(),
            method: p.method.name().into(),
            rtol: p.rtol,
            final_error: opt(p.final_error),
            trajectory_error: opt(p.trajectory_error),
            estimated_error: opt(p.estimated_error),
            estimate_rtol: opt(p.estimate_rtol),
            wall_time: p.wall_time,
            steps: p.steps,
            rejected: p.rejected,
            failure: p.failure.clone(),
        }
    }
}

/// Tolerances of the report.
pub const TOLERANCES: [f64; 9] = [1e-2, 1e-3, 1e-4, 1e-5, 1e-6, 1e-7, 1e-8, 1e-9, 1e-10];

/// Runs `f` `reps` times (at least once): its last result and the median wall time (s).
pub fn timed<R>(reps: usize, mut f: impl FnMut() -> R) -> (R, f64) {
    let mut times = Vec::with_capacity(reps.max(1));
    let mut last = None;
    for _ in 0..reps.max(1) {
        let start = Instant::now();
        last = Some(f());
        times.push(start.elapsed().as_secs_f64());
    }
    times.sort_by(|a, b| a.total_cmp(b));
    (last.expect("at least one repetition"), times[times.len() / 2])
}

pub use nanopush_instrument::numerics::integrate::test_problems::max_relative_error;

fn position_rows(model: &PushModel) -> Vec<usize> {
    let m = model.mass_diagonal();
    let l = &model.layout;
    let mut rows = vec![l.zeta_y.pos, l.zeta_z.pos, l.particle_y.pos];
    rows.extend(l.particle_z.map(|s| s.pos));
    rows.extend(l.stage.map(|s| s.pos));
    let _ = m;
    rows
}

/// Differences of two runs of the same model: (final, trajectory L2).
pub fn push_errors(model: &PushModel, run: &PushRun, reference: &PushRun) -> (f64, f64) {
    let fin = position_rows(model)
        .into_iter()
        .map(|i| (run.final_state[i] - reference.final_state[i]).abs())
        .fold(0.0, f64::max);
    let n = run.trace.len().min(reference.trace.len());
    let sum: f64 = run.trace[..n]
        .iter()
        .zip(&reference.trace[..n])
        .map(|(a, b)| (a.particle_y - b.particle_y).powi(2) + (a.zeta_z - b.zeta_z).powi(2))
        .sum();
    (fin, (sum / (2 * n.max(1)) as f64).sqrt())
}

/// The push reference and its cross-check difference (final-time, m).
pub fn push_reference(model: &PushModel, duration: f64) -> Result<(PushRun, f64), String> {
    let r = run_push(model.clone(), Method::Rodas4, Options::with_rtol(1e-12), duration, 1e-4)
        .map_err(|e| format!("reference (rodas4, rtol 1e-12): {e}"))?;
    let c = run_push(model.clone(), Method::TrBdf2, Options::with_rtol(1e-10), duration, 1e-4)
        .map_err(|e| format!("cross-check (trbdf2, rtol 1e-10): {e}"))?;
    let (fin, _) = push_errors(model, &c, &r);
    Ok((r, fin))
}

/// The report's tolerances down to `min_rtol`.
pub fn tolerances(min_rtol: f64) -> impl Iterator<Item = f64> {
    TOLERANCES.into_iter().filter(move |&t| t >= min_rtol * (1.0 - 1e-9))
}

/// Work-precision points of the push for every method × tolerance, `reps` repetitions each.
pub fn push_points(
    name: &str,
    model: &PushModel,
    duration: f64,
    reference: &PushRun,
    reps: usize,
    max_steps: u64,
    min_rtol: f64,
) -> Vec<Point> {
    each_method_and_tolerance(min_rtol, max_steps, |method, opts| {
        push_point(name, model, duration, reference, reps, method, opts)
    })
}

/// One work-precision point of the push: `method` with `opts` (its tolerance is the point's),
/// the best wall time of `reps` repetitions; a failed run is a failed point.
pub fn push_point(
    name: &str,
    model: &PushModel,
    duration: f64,
    reference: &PushRun,
    reps: usize,
    method: Method,
    opts: Options,
) -> Point {
    let rtol = opts.rtol;
    let (last, wall) = timed(reps, || run_push(model.clone(), method, opts, duration, 1e-4));
    match last {
        Ok(run) => {
            let (fin, traj) = push_errors(model, &run, reference);
            Point {
                problem: name.into(),
                method,
                rtol,
                final_error: fin,
                trajectory_error: traj,
                estimated_error: f64::NAN,
                estimate_rtol: f64::NAN,
                final_values: position_rows(model).into_iter().map(|i| run.final_state[i]).collect(),
                wall_time: wall,
                steps: run.stats.steps,
                rejected: run.stats.rejected,
                failure: None,
            }
        }
        Err(e) => Point::failed(name, method, rtol, wall, e.to_string()),
    }
}

/// One point per method and tolerance (down to `min_rtol`), with at most `max_steps` steps.
fn each_method_and_tolerance(
    min_rtol: f64,
    max_steps: u64,
    mut point: impl FnMut(Method, Options) -> Point,
) -> Vec<Point> {
    let mut out = Vec::new();
    for method in Method::ALL {
        for rtol in tolerances(min_rtol) {
            let opts = Options {
                max_steps,
                ..Options::with_rtol(rtol)
            };
            out.push(point(method, opts));
        }
    }
    out
}

/// A classical test problem with its published reference values at `t_end`.
struct Classical<'a, P> {
    name: &'a str,
    problem: &'a P,
    y0: &'a [f64],
    t_end: f64,
    reference: &'a [f64],
}

impl<P: Problem> Classical<'_, P> {
    /// Every method × tolerance down to `min_rtol`, with at most `max_steps` steps.
    fn points(&self, reps: usize, max_steps: u64, min_rtol: f64) -> Vec<Point> {
        each_method_and_tolerance(min_rtol, max_steps, |method, opts| self.point(reps, method, opts))
    }

    /// One point: `method` with `opts`, the best wall time of `reps` repetitions; the final
    /// error is the largest relative error of a component.
    fn point(&self, reps: usize, method: Method, opts: Options) -> Point {
        let ((r, y), wall) = timed(reps, || {
            let mut it = Integrator::new(method, opts);
            let mut y = self.y0.to_vec();
            let mut t = 0.0;
            (it.advance(self.problem, &NoEvents, &mut t, &mut y, self.t_end), y)
        });
        match r {
            Ok((_, st)) => Point {
                problem: self.name.into(),
                method,
                rtol: opts.rtol,
                final_error: max_relative_error(&y, self.reference),
                trajectory_error: f64::NAN,
                estimated_error: f64::NAN,
                estimate_rtol: f64::NAN,
                final_values: y.clone(),
                wall_time: wall,
                steps: st.steps,
                rejected: st.rejected,
                failure: None,
            },
            Err(e) => Point::failed(self.name, method, opts.rtol, wall, e.to_string()),
        }
    }
}

const VAN_DER_POL: Classical<'static, VanDerPol> = Classical {
    name: "van-der-pol",
    problem: &VanDerPol { eps: 1e-6 },
    y0: &VanDerPol::Y0,
    t_end: VanDerPol::T_END,
    reference: &VanDerPol::REFERENCE,
};

const ROBERTSON: Classical<'static, Robertson> = Classical {
    name: "robertson",
    problem: &Robertson,
    y0: &Robertson::Y0,
    t_end: Robertson::T_END,
    reference: &Robertson::REFERENCE,
};

/// Van der Pol (ε = 1e-6, t = 2) and Robertson (t = 1e11) against their published references;
/// the final error is the largest relative error of a component.
pub fn classical_points(reps: usize, max_steps: u64, min_rtol: f64) -> Vec<Point> {
    let mut out = VAN_DER_POL.points(reps, max_steps, min_rtol);
    out.extend(ROBERTSON.points(reps, max_steps, min_rtol));
    out
}

/// Whether two runs' values differ by more than rounding: in some component by more than
/// 16 ulps of the larger magnitude. Runs at two tolerances that the step-size control (or the
/// trace's sample points) drove through the same steps agree to the last bits, and their
/// difference says nothing about the error.
fn differ_beyond_rounding(a: &[f64], b: &[f64]) -> bool {
    a.iter()
        .zip(b)
        .any(|(x, y)| (x - y).abs() > 16.0 * f64::EPSILON * x.abs().max(y.abs()))
}

/// Fills `estimated_error` (and `estimate_rtol`) of every point from the same problem and
/// method's runs at finer tolerances: the largest `|values(rtol) − values(finer)|` over them
/// (largest component; relative to the reference magnitude for the classical problems, like
/// their `final_error`), which is the difference from the finest run when the error falls with
/// the tolerance: what a user without the reference gets by tightening the tolerance until the
/// answer stops changing.
///
/// Not only the next, 10× finer run: at loose tolerances on the push both runs take the same
/// steps (one per 0.1 ms sample), so their difference is exactly 0 while the error is 4e-15 m,
/// and where it is not 0 it underestimates an error that has stopped falling with the
/// tolerance. A finer run that agrees to rounding (the same discretisation) tells nothing
/// and is skipped; with no finer run that differs the estimate stays NaN (unknown), never 0.
pub fn estimate_errors(points: &mut [Point], relative_to: impl Fn(&str) -> Option<Vec<f64>>) {
    let n = points.len();
    for i in 0..n {
        let (problem, method, rtol) = (points[i].problem.clone(), points[i].method, points[i].rtol);
        let a = &points[i].final_values;
        if a.is_empty() {
            continue;
        }
        let scale = relative_to(&problem);
        let mut best: Option<(f64, f64)> = None;
        for p in points.iter() {
            let b = &p.final_values;
            if p.problem != problem
                || p.method != method
                || p.rtol >= rtol * (1.0 - 1e-9)
                || b.len() != a.len()
                || !differ_beyond_rounding(a, b)
            {
                continue;
            }
            let d = a
                .iter()
                .zip(b)
                .enumerate()
                .map(|(k, (x, y))| {
                    let d = (x - y).abs();
                    match &scale {
                        Some(s) => d / s[k].abs().max(1e-300),
                        None => d,
                    }
                })
                .fold(0.0, f64::max);
            if best.is_none_or(|(e, _)| d > e) {
                best = Some((d, p.rtol));
            }
        }
        if let Some((e, r)) = best {
            points[i].estimated_error = e;
            points[i].estimate_rtol = r;
        }
    }
}

/// The reference values the classical problems' errors are relative to.
pub fn classical_reference(problem: &str) -> Option<Vec<f64>> {
    match problem {
        "van-der-pol" => Some(VanDerPol::REFERENCE.to_vec()),
        "robertson" => Some(Robertson::REFERENCE.to_vec()),
        _ => None,
    }
}

#[cfg(test)]
mod tests;
