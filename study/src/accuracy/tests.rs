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
fn runs_a_few_ulps_apart_agree_to_rounding() {
    let ulps = |k: f64| [1.0 + k * f64::EPSILON];
    assert!(!differ_beyond_rounding(&[1.0], &ulps(16.0)));
    assert!(differ_beyond_rounding(&[1.0], &ulps(17.0)));
    assert!(!differ_beyond_rounding(&[-1.0], &[-1.0 - 16.0 * f64::EPSILON]));
}

/// On the paper scene's push Rodas4 takes one step per 0.1 ms sample at rtol 1e-2…1e-4 and its
/// runs agree to the last bit, while the error against the reference is ~4e-15 m: the estimate
/// must not read 0 there. Every estimate where the error is not 0 is within a factor of 10 of
/// it (the reference: Rodas4 at rtol 1e-12).
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

/// The Rodas4, Rodas5P and TR-BDF2 work-precision points of a classical problem at every
/// tolerance (the report's [`Classical::point`]), with their estimates.
fn classical_rows<P: Problem>(c: &Classical<'_, P>) -> Vec<Point> {
    let mut pts = Vec::new();
    for method in [Method::Rodas4, Method::Rodas5P, Method::TrBdf2] {
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
/// 1.9e-13 m in 3989 steps at 1e-6; Rodas5P 8.5e-19 / 8.5e-19 / 4.5e-19 m (estimates 3.9e-19 at
/// 1e-2 and 1e-6) in 205 / 205 / 406 steps (the same 205 steps from 1e-2 to 1e-8); the reference
/// and its TR-BDF2 cross-check 1.2e-14 m apart.
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
    let rodas5p = push_rows(&model, &reference, Method::Rodas5P, &TOLERANCES);
    let row = |pts: &[Point], rtol: f64| pts.iter().find(|p| p.rtol == rtol).cloned().unwrap();
    // (rows, rtol, steps, final error, estimate; NaN: none).
    let readme: [(&[Point], f64, u64, f64, f64); 10] = [
        (&rodas, 1e-2, 205, 4.0e-15, 4.0e-15),
        (&rodas, 1e-6, 218, 3.9e-15, 3.9e-15),
        (&rodas, 1e-10, 1228, 9.2e-18, f64::NAN),
        (&trbdf2, 1e-2, 205, 9.0e-12, 9.0e-12),
        (&trbdf2, 1e-6, 459, 3.3e-12, 3.3e-12),
        (&trbdf2, 1e-10, 7353, 1.2e-14, f64::NAN),
        (&euler, 1e-6, 3989, 1.9e-13, f64::NAN),
        (&rodas5p, 1e-2, 205, 8.5e-19, 3.9e-19),
        (&rodas5p, 1e-6, 205, 8.5e-19, 3.9e-19),
        (&rodas5p, 1e-10, 406, 4.5e-19, f64::NAN),
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
    for rtol in [1e-3, 1e-4, 1e-5, 1e-7, 1e-8] {
        assert_eq!(row(&rodas5p, rtol).steps, 205);
    }
    for pts in [&rodas, &trbdf2, &euler, &rodas5p] {
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
/// two digits (Van der Pol 2.3e-7, 5.7e-7 and 1.5e-4 at 1e-6, Robertson 6.2e-9, 2.0e-8 and
/// 1.1e-5 at 1e-8, for Rodas4, Rodas5P and TR-BDF2); the
/// error falls with the tolerance (TR-BDF2 on Van der Pol from 1e-3: its error at 1e-2 is
/// below the one at 1e-3).
#[test]
fn the_estimate_tracks_the_error_on_the_classical_problems() {
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
    assert!(two_digits(estimate(&vdp, Method::Rodas5P, 1e-6), 5.7e-7));
    assert!(two_digits(estimate(&rob, Method::Rodas5P, 1e-8), 2.0e-8));
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
fn only_implicit_euler_at_the_finest_tolerance_passes_the_step_limit() {
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
fn the_reference_tolerance_is_the_finest_rodas4_reaches_on_the_push() {
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

/// A point's row of the report: the errors that are not numbers (a failed run, no estimate) are
/// absent, the others as measured.
#[test]
fn a_points_row_leaves_out_the_errors_that_are_not_numbers() {
    let failed = Point::failed("robertson", Method::Rodas4, 1e-6, 0.5, "step limit".into());
    let row = AccuracyPoint::from(&failed);
    let errors = (
        row.final_error,
        row.trajectory_error,
        row.estimated_error,
        row.estimate_rtol,
    );
    assert_eq!(errors, (None, None, None, None));
    assert_eq!(
        (row.method.as_str(), row.rtol, row.wall_time, row.failure.as_deref()),
        ("rodas4", 1e-6, 0.5, Some("step limit"))
    );
    let measured = Point {
        final_error: 2e-7,
        estimated_error: 3e-7,
        estimate_rtol: 1e-7,
        failure: None,
        ..failed
    };
    let row = AccuracyPoint::from(&measured);
    assert_eq!(
        (row.final_error, row.estimated_error, row.estimate_rtol),
        (Some(2e-7), Some(3e-7), Some(1e-7))
    );
    assert_eq!((row.trajectory_error, row.failure), (None, None));
}
