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
/// Only the next, 10× finer run was used before, and at loose tolerances on the push both runs
/// take the same steps (one per 0.1 ms sample): their difference is exactly 0 while the error
/// is 4e-15 m, and where it is not 0 it underestimates an error that has stopped falling with
/// the tolerance. A finer run that agrees to rounding (the same discretisation) tells nothing
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
mod tests {
    use super::*;
    use nanopush_instrument::scene::Scene;

    fn point(rtol: f64, values: Vec<f64>) -> Point {
        Point {
            problem: "push".into(),
            method: Method::Rodas4,
            rtol,
            final_error: 1.0,
            trajectory_error: f64::NAN,
            estimated_error: f64::NAN,
            estimate_rtol: f64::NAN,
            final_values: values,
            wall_time: 0.0,
            steps: 1,
            rejected: 0,
            failure: None,
        }
    }

    /// Runs that agree to rounding are the same discretisation: the estimate skips them and
    /// takes the largest difference from a finer run that differs; with none, it is unknown
    /// (NaN), never 0.
    #[test]
    fn estimate_skips_identical_runs_and_is_never_zero() {
        let v = 50e-9;
        let mut pts = vec![
            point(1e-2, vec![v]),
            point(1e-3, vec![v]),
            point(1e-4, vec![v * (1.0 + f64::EPSILON)]),
            point(1e-5, vec![v + 3e-15]),
            point(1e-6, vec![v + 4e-15]),
        ];
        estimate_errors(&mut pts, |_| None);
        for p in &pts[..4] {
            assert!(p.estimated_error > 0.0, "{p:?}");
        }
        assert!(
            (pts[0].estimated_error - 4e-15).abs() < 1e-20,
            "{:e}",
            pts[0].estimated_error
        );
        assert_eq!(pts[0].estimate_rtol, 1e-6);
        assert!((pts[3].estimated_error - 1e-15).abs() < 1e-20);
        assert!(pts[4].estimated_error.is_nan());
        // Nothing finer differs: unknown, not 0.
        let mut same = vec![point(1e-2, vec![v]), point(1e-3, vec![v])];
        estimate_errors(&mut same, |_| None);
        assert!(same[0].estimated_error.is_nan());
    }

    /// docs/validation.md, "`nanopush accuracy`": the estimate skips finer runs "that agree with it
    /// to rounding (16 ulps)": 16 ulps of the larger magnitude is rounding, 17 is not.
    #[test]
    fn runs_within_16_ulps_agree_to_rounding() {
        let ulps = |k: f64| [1.0 + k * f64::EPSILON];
        assert!(!differ_beyond_rounding(&[1.0], &ulps(16.0)));
        assert!(differ_beyond_rounding(&[1.0], &ulps(17.0)));
        assert!(!differ_beyond_rounding(&[-1.0], &[-1.0 - 16.0 * f64::EPSILON]));
    }

    /// Issue 13, item 5: on the paper scene's push Rodas4 takes one step per 0.1 ms sample at
    /// rtol 1e-2…1e-4 and its runs agree to the last bit; the estimate column read 0 there
    /// while the error against the reference is ~4e-15 m. Now every estimate where the error is
    /// not 0 is within a factor of 10 of it (the reference: Rodas4 at rtol 1e-12).
    #[test]
    fn push_estimate_is_not_zero_where_the_error_is_not() {
        let model = PushModel::new(Scene::default_scene().push_params());
        let duration = 0.008;
        let reference = run_push(model.clone(), Method::Rodas4, Options::with_rtol(1e-12), duration, 1e-4).unwrap();
        let mut pts: Vec<Point> = [1e-2, 1e-3, 1e-4, 1e-5, 1e-6, 1e-7, 1e-8]
            .into_iter()
            .map(|rtol| {
                let run = run_push(model.clone(), Method::Rodas4, Options::with_rtol(rtol), duration, 1e-4).unwrap();
                let (fin, _) = push_errors(&model, &run, &reference);
                Point {
                    final_error: fin,
                    final_values: position_rows(&model).into_iter().map(|i| run.final_state[i]).collect(),
                    ..point(rtol, Vec::new())
                }
            })
            .collect();
        estimate_errors(&mut pts, |_| None);
        for p in &pts[..pts.len() - 1] {
            eprintln!(
                "rtol {:e}: error {:e}, estimate {:e} (against {:e})",
                p.rtol, p.final_error, p.estimated_error, p.estimate_rtol
            );
            if p.final_error > 0.0 {
                let ratio = p.estimated_error / p.final_error;
                assert!(
                    ratio > 0.1 && ratio < 10.0,
                    "rtol {:e}: estimate {:e} against error {:e}",
                    p.rtol,
                    p.estimated_error,
                    p.final_error
                );
            }
        }
    }

    /// `x` printed to two significant digits is `readme`: within half a unit of its second digit.
    fn two_digits(x: f64, readme: f64) -> bool {
        let unit = 10f64.powf(readme.abs().log10().floor() - 1.0);
        (x - readme).abs() <= 0.5 * unit
    }

    /// `x` printed to two decimals is `readme`.
    fn two_decimals(x: f64, readme: f64) -> bool {
        (x - readme).abs() <= 0.005
    }

    /// The push's work-precision points for `method` at `rtols` (the report's [`push_point`]),
    /// with their estimates (from the same runs, as the report computes them).
    fn push_rows(model: &PushModel, reference: &PushRun, method: Method, rtols: &[f64]) -> Vec<Point> {
        let mut pts: Vec<Point> = rtols
            .iter()
            .map(|&rtol| push_point("push", model, 0.02, reference, 1, method, Options::with_rtol(rtol)))
            .collect();
        estimate_errors(&mut pts, classical_reference);
        pts
    }

    /// The Rodas4 and TR-BDF2 work-precision points of a classical problem at every tolerance
    /// (the report's [`Classical::point`]), with their estimates.
    fn classical_rows<P: Problem>(c: &Classical<'_, P>) -> Vec<Point> {
        let mut pts = Vec::new();
        for method in [Method::Rodas4, Method::TrBdf2] {
            for rtol in TOLERANCES {
                pts.push(c.point(1, method, Options::with_rtol(rtol)));
            }
        }
        estimate_errors(&mut pts, classical_reference);
        pts
    }

    /// Smallest and largest estimate / error over `pts` (rows with an estimate).
    fn ratio_range<'a>(pts: impl Iterator<Item = &'a Point>) -> (f64, f64) {
        pts.filter(|p| p.estimated_error.is_finite())
            .map(|p| p.estimated_error / p.final_error)
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), r| (lo.min(r), hi.max(r)))
    }

    /// docs/validation.md, "`nanopush accuracy`": the push rows of the work-precision table
    /// (default scene, 20 ms, 0.1 ms samples, against Rodas4 at rtol 1e-12), as the report computes
    /// them — steps exactly, final error and estimate to their two digits: Rodas4 4.0e-15 / 3.9e-15
    /// / 9.2e-18 m in 205 / 218 / 1228 steps at 1e-2 / 1e-6 / 1e-10 (the same 205 steps at 1e-2 …
    /// 1e-4); TR-BDF2 9.0e-12 / 3.3e-12 / 1.2e-14 m in 205 / 459 / 7353 steps; implicit Euler
    /// 1.9e-13 m in 3989 steps at 1e-6; the reference and its TR-BDF2 cross-check 1.2e-14 m apart.
    /// Then the error falls with the tolerance for each method (implicit Euler down to 1e-7: its
    /// finer runs, 4·10⁴ steps and more, are too slow for a debug build), and the estimate / error
    /// ranges over the Rodas4 and TR-BDF2 rows: 0.88-1.00 and 0.77-1.00.
    #[test]
    fn the_readmes_push_work_precision_rows() {
        let model = PushModel::new(Scene::default_scene().push_params());
        let (reference, crosscheck) = push_reference(&model, 0.02).unwrap();
        assert!(two_digits(crosscheck, 1.2e-14), "cross-check {crosscheck:e}");
        let rodas = push_rows(&model, &reference, Method::Rodas4, &TOLERANCES);
        let trbdf2 = push_rows(&model, &reference, Method::TrBdf2, &TOLERANCES);
        let euler = push_rows(&model, &reference, Method::ImplicitEuler, &TOLERANCES[..6]);
        let row = |pts: &[Point], rtol: f64| pts.iter().find(|p| p.rtol == rtol).cloned().unwrap();
        // (rows, rtol, steps, final error, estimate; NaN: none).
        let readme: [(&[Point], f64, u64, f64, f64); 7] = [
            (&rodas, 1e-2, 205, 4.0e-15, 4.0e-15),
            (&rodas, 1e-6, 218, 3.9e-15, 3.9e-15),
            (&rodas, 1e-10, 1228, 9.2e-18, f64::NAN),
            (&trbdf2, 1e-2, 205, 9.0e-12, 9.0e-12),
            (&trbdf2, 1e-6, 459, 3.3e-12, 3.3e-12),
            (&trbdf2, 1e-10, 7353, 1.2e-14, f64::NAN),
            (&euler, 1e-6, 3989, 1.9e-13, f64::NAN),
        ];
        for (pts, rtol, steps, error, estimate) in readme {
            let p = row(pts, rtol);
            let what = format!("{:?} at {rtol:e}", p.method);
            eprintln!(
                "{what}: {} steps, error {:.4e}, estimate {:.4e}",
                p.steps, p.final_error, p.estimated_error
            );
            assert_eq!(p.steps, steps, "{what}: steps");
            assert!(two_digits(p.final_error, error), "{what}: error {:e}", p.final_error);
            if p.method != Method::ImplicitEuler {
                assert_eq!(estimate.is_nan(), p.estimated_error.is_nan(), "{what}: estimate");
                assert!(
                    estimate.is_nan() || two_digits(p.estimated_error, estimate),
                    "{what}: estimate"
                );
            }
        }
        for rtol in [1e-3, 1e-4] {
            assert_eq!((row(&rodas, rtol).steps, row(&trbdf2, rtol).steps), (205, 205));
        }
        for pts in [&rodas, &trbdf2, &euler] {
            assert!(pts.windows(2).all(|w| w[1].final_error <= w[0].final_error), "{pts:?}");
        }
        let (lo, hi) = ratio_range(rodas.iter());
        assert!(two_decimals(lo, 0.88) && two_decimals(hi, 1.00), "Rodas4 {lo}-{hi}");
        let (lo, hi) = ratio_range(trbdf2.iter());
        assert!(two_decimals(lo, 0.77) && two_decimals(hi, 1.00), "TR-BDF2 {lo}-{hi}");
    }

    /// docs/validation.md, "`nanopush accuracy`": estimate / true error on the classical problems,
    /// every tolerance 1e-2 … 1e-10: Rodas4 0.89-1.02 (Robertson) and 1.00-1.56 (Van der Pol),
    /// TR-BDF2 within the 0.77-1.00 of its push rows; the estimates of the table's rows to their
    /// two digits (Van der Pol 2.3e-7 and 1.5e-4 at 1e-6, Robertson 6.2e-9 and 1.1e-5 at 1e-8); the
    /// error falls with the tolerance (TR-BDF2 on Van der Pol from 1e-3: its error at 1e-2 is
    /// below the one at 1e-3).
    #[test]
    fn estimate_over_error_is_0_89_to_1_02_on_robertson_and_1_00_to_1_56_on_van_der_pol() {
        let (vdp, rob) = (classical_rows(&VAN_DER_POL), classical_rows(&ROBERTSON));
        let of = |pts: &[Point], m: Method| pts.iter().filter(|p| p.method == m).cloned().collect::<Vec<_>>();
        let (lo, hi) = ratio_range(of(&rob, Method::Rodas4).iter());
        assert!(
            two_decimals(lo, 0.89) && two_decimals(hi, 1.02),
            "Robertson Rodas4 {lo}-{hi}"
        );
        let (lo, hi) = ratio_range(of(&vdp, Method::Rodas4).iter());
        assert!(
            two_decimals(lo, 1.00) && two_decimals(hi, 1.56),
            "Van der Pol Rodas4 {lo}-{hi}"
        );
        for pts in [&vdp, &rob] {
            let (lo, hi) = ratio_range(of(pts, Method::TrBdf2).iter());
            assert!(lo >= 0.765 && hi < 1.005, "TR-BDF2 {lo}-{hi}");
        }
        let estimate = |pts: &[Point], m: Method, rtol: f64| {
            pts.iter()
                .find(|p| p.method == m && p.rtol == rtol)
                .unwrap()
                .estimated_error
        };
        assert!(two_digits(estimate(&vdp, Method::Rodas4, 1e-6), 2.3e-7));
        assert!(two_digits(estimate(&vdp, Method::TrBdf2, 1e-6), 1.5e-4));
        assert!(two_digits(estimate(&rob, Method::Rodas4, 1e-8), 6.2e-9));
        assert!(two_digits(estimate(&rob, Method::TrBdf2, 1e-8), 1.1e-5));
        for pts in [&vdp, &rob] {
            for m in [Method::Rodas4, Method::TrBdf2] {
                let rows = of(pts, m);
                let from = if pts[0].problem == "van-der-pol" && m == Method::TrBdf2 {
                    // docs/validation.md's exception ("`nanopush accuracy`"): TR-BDF2's error on
                    // Van der Pol at 1e-2 is below the one at 1e-3.
                    assert!(rows[0].final_error < rows[1].final_error, "{rows:?}");
                    1
                } else {
                    0
                };
                assert!(
                    rows[from..].windows(2).all(|w| w[1].final_error < w[0].final_error),
                    "{rows:?}"
                );
            }
        }
    }

    /// docs/validation.md, "`nanopush accuracy`": a run beyond the step limit is reported as a
    /// failed point (no error, the integrator's message), and the other points are not affected.
    /// Van der Pol with Rodas4 takes 1069 + 8 rejected = 1077 step attempts at 1e-6 (the
    /// integrator's pinned work): with a limit of 1076 that run fails, the looser ones do not.
    #[test]
    fn a_run_beyond_the_step_limit_is_reported_as_a_failed_point() {
        let pts = VAN_DER_POL.points(1, 1076, 1e-6);
        let rodas = |rtol: f64| {
            pts.iter()
                .find(|p| p.method == Method::Rodas4 && p.rtol == rtol)
                .unwrap()
        };
        let failed = rodas(1e-6);
        let msg = failed.failure.as_deref().unwrap_or_default();
        assert!(msg.contains("more than 1076 steps"), "{failed:?}");
        assert!(failed.final_error.is_nan() && failed.final_values.is_empty());
        for rtol in [1e-2, 1e-3, 1e-4, 1e-5] {
            assert_eq!(rodas(rtol).failure, None, "{:?}", rodas(rtol));
        }
    }

    /// docs/validation.md, "`nanopush accuracy`": with the report's 2·10⁶-step limit
    /// (`nanopush accuracy`'s `MAX_STEPS`), the only classical runs that fail are implicit Euler's
    /// at 1e-10, on both Van der Pol and Robertson. Ignored: implicit Euler takes 1.5·10⁶ steps at
    /// 1e-9 on Van der Pol, and 2·10⁶ before failing at 1e-10, too slow for the debug build of
    /// `make test` (~2 s in release):
    /// `cargo test --release -p nanopush-study --lib -- --ignored implicit_euler_at_1e_10`.
    #[test]
    #[ignore = "runs every method to 1e-10 on both classical problems, implicit Euler into 2e6 steps: ~2 s in release, a minute in debug"]
    fn implicit_euler_at_1e_10_is_the_only_classical_run_beyond_the_2e6_step_limit() {
        let pts = classical_points(1, 2_000_000, 1e-10);
        let failed: Vec<(&str, Method, f64)> = pts
            .iter()
            .filter(|p| p.failure.is_some())
            .map(|p| (p.problem.as_str(), p.method, p.rtol))
            .collect();
        assert_eq!(
            failed,
            [
                ("van-der-pol", Method::ImplicitEuler, 1e-10),
                ("robertson", Method::ImplicitEuler, 1e-10)
            ],
            "{pts:?}"
        );
        for p in pts.iter().filter(|p| p.failure.is_some()) {
            let msg = p.failure.as_deref().unwrap();
            assert!(msg.contains("more than 2000000 steps"), "{msg}");
        }
    }

    /// docs/validation.md, "`nanopush accuracy`": the push's reference is Rodas4 at rtol 1e-12
    /// because at 1e-13 double precision runs out on this problem: the step size falls below the
    /// minimum within the first microsecond, while the run at 1e-12 completes.
    #[test]
    fn rodas4_on_the_push_fails_at_rtol_1e_13_so_the_reference_is_1e_12() {
        let model = PushModel::new(Scene::default_scene().push_params());
        let run = |rtol: f64| run_push(model.clone(), Method::Rodas4, Options::with_rtol(rtol), 0.02, 1e-4);
        assert!(run(1e-12).is_ok());
        let e = run(1e-13).unwrap_err();
        let msg = e.to_string();
        assert!(msg.contains("fell below the minimum"), "{msg}");
        let at: f64 = msg
            .rsplit_once("at t = ")
            .and_then(|(_, t)| t.trim_end_matches(" s").parse().ok())
            .unwrap_or_else(|| panic!("no time in {msg}"));
        assert!(at < 1e-6, "{msg}");
    }
}
