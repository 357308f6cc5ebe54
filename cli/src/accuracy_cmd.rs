//! `nanopush accuracy`: error against run time.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use clap::Args;
use nanopush_instrument::numerics::integrate::Method;
use nanopush_instrument::physics::pushing::{Dof, PushModel};
use nanopush_instrument::scene::Scene;
use nanopush_proto::accuracy::{AccuracyPoint, AccuracyReport, EqualError, PushOutcome, QuasiStaticCost, ReductionRow};
use nanopush_study::accuracy::reduction::{CompareOptions, Comparison, compare};
use nanopush_study::accuracy::{classical_points, classical_reference, estimate_errors, push_points, push_reference};
use plotters::prelude::*;

/// Most integrator steps a run of the report may take; beyond it the run is reported as failed.
const MAX_STEPS: u64 = 2_000_000;

/// Arguments of `nanopush accuracy`.
#[derive(Args, Debug)]
pub struct AccuracyArgs {
    /// Scene file (TOML); the embedded paper scene when absent.
    #[arg(long)]
    scene: Option<PathBuf>,
    /// Simulated push (s), in (0, 1].
    #[arg(long, default_value_t = 0.02)]
    duration: f64,
    /// Repetitions per point (median wall time), in [1, 50].
    #[arg(long, default_value_t = 3)]
    reps: usize,
    /// Where to write accuracy.csv and the SVG plots.
    #[arg(long, default_value = "out/accuracy")]
    out: PathBuf,
    /// Print one JSON object instead of a table.
    #[arg(long)]
    json: bool,
    /// Skip the full-dynamics comparison (it resolves nanosecond modes and takes a while).
    #[arg(long)]
    no_full_model: bool,
    /// Finest tolerance of the sweep (1e-2 down to this), in [1e-10, 1e-2].
    #[arg(long, default_value_t = 1e-10)]
    min_rtol: f64,
    /// Run the stability grid over extreme parameters instead (see `extremes` in nanopush-study),
    /// then the whole pushes (`whole_pushes` in nanopush-study).
    #[arg(long)]
    extremes: bool,
    /// With --extremes: the reduced grid (sweep end points and two corners).
    #[arg(long)]
    reduced: bool,
}

/// The reduction table: one line per model and rotation setting, then the errors.
fn write_reduction(out: &mut String, rows: &[ReductionRow]) -> anyhow::Result<()> {
    let nm = |v: f64| format!("{:.3}", v * 1e9);
    let ms = |v: Option<f64>| v.map_or("never".to_string(), |t| format!("{:.4}", t * 1e3));
    writeln!(
        out,
        "Quasi-static reduction against the full model (rodas4, rtol 1e-6; settled = mean of the last half, ± its spread):"
    )?;
    writeln!(
        out,
        "  {:<9} {:<15} {:<11} {:>6} {:>9} {:>17} {:>17} {:>9} {:>10}",
        "rotation", "model", "regime", "jumps", "t*/ms", "settled y/nm", "settled ζz/nm", "steps", "time/s"
    )?;
    for r in rows {
        let rot = if r.rotation { "on" } else { "off" };
        let mut line = |name: &str, o: &PushOutcome| {
            writeln!(
                out,
                "  {:<9} {:<15} {:<11} {:>6} {:>9} {:>17} {:>17} {:>9} {:>10.3e}",
                rot,
                name,
                o.regime,
                o.jumps,
                ms(o.shearing_time),
                format!("{} ± {}", nm(o.settled_y), nm(o.y_spread / 2.0)),
                format!("{} ± {}", nm(o.zeta_z), nm(o.zeta_z_spread / 2.0)),
                o.steps,
                o.wall_time
            )
        };
        line("reduced", &r.reduced)?;
        if let Some(f) = &r.full {
            line("full", f)?;
        }
        if let Some(f) = &r.full_fine {
            line("full, rtol/100", f)?;
        }
        if let Some(e) = &r.failure {
            writeln!(out, "  {rot:<9} FAILED: {e}")?;
        }
    }
    writeln!(out, "  Error of the reduction against the full model:")?;
    for r in rows {
        let t = match (r.reduced.shearing_time, r.full.as_ref().and_then(|f| f.shearing_time)) {
            (Some(_), Some(_)) => format!("{:.3e} s", r.shearing_time_error.unwrap_or(f64::NAN)),
            (None, None) => "neither shears".into(),
            (Some(_), None) => "only the reduction shears".into(),
            (None, Some(_)) => "only the full model shears".into(),
        };
        writeln!(
            out,
            "  rotation {:<3}: regime {}; t* {}; settled y {} nm; ζz {} nm",
            if r.rotation { "on" } else { "off" },
            match r.regime_agrees {
                Some(true) => "agrees",
                Some(false) => "DIFFERS",
                None => "-",
            },
            t,
            r.settled_y_error.map_or("-".into(), |v| format!("{:+.3}", v * 1e9)),
            r.zeta_z_error.map_or("-".into(), |v| format!("{:+.3}", v * 1e9)),
        )?;
    }
    writeln!(
        out,
        "  (After the first shear the full model's jump overshoots the kinetic balance and the contact sticks again, stick-slip; the reduction, which has no inertia, lands on the balance and slides or rolls steadily: docs/validation.md, \"Which is right, and why they differ\".)"
    )?;
    Ok(())
}

fn plot(path: &Path, title: &str, unit: &str, points: &[&AccuracyPoint]) -> anyhow::Result<()> {
    let ok: Vec<(&str, f64, f64)> = points
        .iter()
        .filter_map(|p| {
            p.final_error
                .filter(|e| *e > 0.0 && p.wall_time > 0.0)
                .map(|e| (p.method.as_str(), p.wall_time, e))
        })
        .collect();
    if ok.is_empty() {
        return Ok(());
    }
    let (tmin, tmax) = ok
        .iter()
        .fold((f64::INFINITY, 0.0f64), |(a, b), p| (a.min(p.1), b.max(p.1)));
    let (emin, emax) = ok
        .iter()
        .fold((f64::INFINITY, 0.0f64), |(a, b), p| (a.min(p.2), b.max(p.2)));
    let root = SVGBackend::new(path, (860, 580)).into_drawing_area();
    root.fill(&WHITE)?;
    let mut chart = ChartBuilder::on(&root)
        .caption(title, ("sans-serif", 22))
        .margin(12)
        .x_label_area_size(48)
        .y_label_area_size(80)
        .build_cartesian_2d(
            (tmin * 0.7..tmax * 1.4).log_scale(),
            (emin * 0.3..emax * 3.0).log_scale(),
        )?;
    chart
        .configure_mesh()
        .x_desc("wall time (s), median")
        .y_desc(format!("final error ({unit})"))
        .x_label_formatter(&|v| format!("{v:.0e}"))
        .y_label_formatter(&|v| format!("{v:.0e}"))
        .draw()?;
    let mut names: Vec<&str> = Vec::new();
    for p in &ok {
        if !names.contains(&p.0) {
            names.push(p.0);
        }
    }
    for (i, name) in names.into_iter().enumerate() {
        let color = Palette99::pick(i).to_rgba();
        let series: Vec<(f64, f64)> = ok.iter().filter(|p| p.0 == name).map(|p| (p.1, p.2)).collect();
        chart
            .draw_series(LineSeries::new(series.clone(), color.stroke_width(2)))?
            .label(name.to_string())
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(2)));
        chart.draw_series(series.iter().map(|&(x, y)| Circle::new((x, y), 4, color.filled())))?;
    }
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .draw()?;
    root.present()?;
    Ok(())
}

/// The peer solvers built into this `nanopush` (none without its feature `peers`).
#[cfg(feature = "peers")]
const PEERS: &[&str] = &nanopush_study::peers::SOLVERS;
#[cfg(not(feature = "peers"))]
const PEERS: &[&str] = &[];

/// The peer solvers' work-precision points on the classical problems.
#[cfg(feature = "peers")]
fn peer_rows(reps: usize, min_rtol: f64) -> Vec<AccuracyPoint> {
    nanopush_study::peers::peer_points(reps, min_rtol)
        .iter()
        .map(AccuracyPoint::from)
        .collect()
}

/// No peer solver is built in: no points.
#[cfg(not(feature = "peers"))]
fn peer_rows(_reps: usize, _min_rtol: f64) -> Vec<AccuracyPoint> {
    Vec::new()
}

/// The point of `problem` that reached `error` in the least wall time, among those `chosen`.
fn fastest_to<'a>(
    rows: &'a [AccuracyPoint],
    problem: &str,
    error: f64,
    chosen: impl Fn(&AccuracyPoint) -> bool,
) -> Option<&'a AccuracyPoint> {
    rows.iter()
        .filter(|p| p.problem == problem && chosen(p) && p.final_error.is_some_and(|e| e <= error))
        .min_by(|a, b| a.wall_time.total_cmp(&b.wall_time))
}

/// Least wall time at which `method` reached `error` on `problem`.
fn time_to(rows: &[AccuracyPoint], problem: &str, method: &str, error: f64) -> Option<f64> {
    fastest_to(rows, problem, error, |p| p.method == method).map(|p| p.wall_time)
}

/// Whether `p` is our default's point: the method [`Method::for_tolerance`] chooses at its
/// tolerance.
fn is_our_default(p: &AccuracyPoint) -> bool {
    p.method == Method::for_tolerance(p.rtol).name()
}

/// The time our default (the method chosen by the tolerance) and the fastest peer take to
/// reach each error on the classical problems (none without a peer built in: nothing to compare
/// with).
fn equal_error(rows: &[AccuracyPoint]) -> Vec<EqualError> {
    let mut out = Vec::new();
    if PEERS.is_empty() {
        return out;
    }
    for problem in ["van-der-pol", "robertson"] {
        for error in [1e-4, 1e-6, 1e-8] {
            let ours = fastest_to(rows, problem, error, is_our_default);
            let ours_time = ours.map(|p| p.wall_time);
            let best = PEERS
                .iter()
                .filter_map(|s| time_to(rows, problem, s, error).map(|t| (s.to_string(), t)))
                .min_by(|a, b| a.1.total_cmp(&b.1));
            let ratio = match (&best, ours_time) {
                (Some((_, bt)), Some(ot)) => Some(bt / ot),
                _ => None,
            };
            out.push(EqualError {
                problem: problem.into(),
                error,
                ours: ours.map_or_else(|| Method::for_tolerance(error).name().into(), |p| p.method.clone()),
                ours_time,
                best_peer: best.as_ref().map(|b| b.0.clone()),
                best_peer_time: best.map(|b| b.1),
                ratio,
            });
        }
    }
    out
}

/// What the work-precision report computes, before it writes anything.
struct Computed {
    crosscheck: f64,
    rows: Vec<AccuracyPoint>,
    equal: Vec<EqualError>,
    reduction: Vec<ReductionRow>,
    quasi_static_cost: Option<QuasiStaticCost>,
}

/// Runs `nanopush accuracy`.
pub fn run(a: &AccuracyArgs) -> anyhow::Result<String> {
    if a.extremes {
        return crate::extremes_cmd::run(a.scene.as_ref(), a.reduced, &a.out, a.json);
    }
    check(a)?;
    let scene = crate::load_scene(a.scene.as_ref())?;
    let c = compute(a, &scene)?;
    write_files(a, &scene.file.name, &c.rows)?;
    let report = AccuracyReport {
        schema: "nanopush.accuracy".into(),
        version: nanopush_proto::VERSION,
        scene: scene.file.name.clone(),
        duration: a.duration,
        reference_crosscheck: c.crosscheck,
        repetitions: a.reps,
        points: c.rows,
        quasi_static_cost: c.quasi_static_cost,
        reduction: c.reduction,
        equal_error: c.equal,
    };
    let mut out = String::new();
    if a.json {
        writeln!(out, "{}", serde_json::to_string(&report)?)?;
        return Ok(out);
    }
    write_text(&mut out, a, &report)?;
    Ok(out)
}

/// Checks `--duration`, `--reps` and `--min-rtol` against their ranges.
fn check(a: &AccuracyArgs) -> anyhow::Result<()> {
    if !(a.duration.is_finite() && a.duration > 0.0 && a.duration <= 1.0) {
        bail!("--duration {} s is out of range; allowed: (0, 1] s", a.duration);
    }
    if !(1..=50).contains(&a.reps) {
        bail!("--reps {} is out of range; allowed: [1, 50]", a.reps);
    }
    if !(a.min_rtol.is_finite() && (1e-10..=1e-2).contains(&a.min_rtol)) {
        bail!("--min-rtol {} is out of range; allowed: [1e-10, 1e-2]", a.min_rtol);
    }
    Ok(())
}

/// The work-precision points (ours, then the peers'), the equal-error times, and the
/// quasi-static reduction against the full model with its cost.
fn compute(a: &AccuracyArgs, scene: &Scene) -> anyhow::Result<Computed> {
    let model = PushModel::new(scene.push_params());
    let (reference, crosscheck) = push_reference(&model, a.duration).map_err(anyhow::Error::msg)?;
    let mut points = push_points("push", &model, a.duration, &reference, a.reps, MAX_STEPS, a.min_rtol);
    points.extend(classical_points(a.reps, MAX_STEPS, a.min_rtol));
    estimate_errors(&mut points, classical_reference);
    let mut rows: Vec<AccuracyPoint> = points.iter().map(AccuracyPoint::from).collect();
    rows.extend(peer_rows(a.reps, a.min_rtol));
    let equal = equal_error(&rows);

    // The quasi-static reduction against the full model (every DOF dynamic), rotation off and
    // on: regime, t*, settled y and ζ_z (see `accuracy::reduction`).
    let reduction = if a.no_full_model {
        Vec::new()
    } else {
        compare(&model.p, &CompareOptions::report(a.duration)).map_err(anyhow::Error::msg)?
    };
    // Its cost, on the scene's own rotation setting.
    let scene_rotation = model.p.dofs.particle_rotation != Dof::Off;
    Ok(Computed {
        crosscheck,
        rows,
        equal,
        reduction: reduction.iter().map(ReductionRow::from).collect(),
        quasi_static_cost: quasi_static_cost(&reduction, scene_rotation, a.duration),
    })
}

/// The cost of the reduction against the full model, on the scene's rotation setting.
fn quasi_static_cost(reduction: &[Comparison], rotation: bool, duration: f64) -> Option<QuasiStaticCost> {
    reduction
        .iter()
        .find(|c| c.rotation == rotation)
        .map(|c| match &c.full {
            Ok(f) => QuasiStaticCost {
                duration,
                final_difference: Some(
                    c.settled_y_error()
                        .unwrap_or(f64::NAN)
                        .abs()
                        .max(c.zeta_z_error().unwrap_or(f64::NAN).abs()),
                ),
                reduced_wall_time: c.reduced.wall_time,
                full_wall_time: f.wall_time,
                full_steps: f.steps,
                failure: None,
            },
            Err(e) => QuasiStaticCost {
                duration,
                final_difference: None,
                reduced_wall_time: c.reduced.wall_time,
                full_wall_time: 0.0,
                full_steps: 0,
                failure: Some(e.clone()),
            },
        })
}

/// accuracy.csv and the three work-precision plots, into `--out`.
fn write_files(a: &AccuracyArgs, scene_name: &str, rows: &[AccuracyPoint]) -> anyhow::Result<()> {
    std::fs::create_dir_all(&a.out).with_context(|| format!("creating {}", a.out.display()))?;
    let mut csv = String::from(
        "problem,method,rtol,final_error,trajectory_error,estimated_error,wall_time_s,steps,rejected,failure\n",
    );
    let num = |v: Option<f64>| v.map_or("NaN".to_string(), |v| format!("{v:e}"));
    for p in rows {
        writeln!(
            csv,
            "{},{},{:e},{},{},{},{:e},{},{},{}",
            p.problem,
            p.method,
            p.rtol,
            num(p.final_error),
            num(p.trajectory_error),
            num(p.estimated_error),
            p.wall_time,
            p.steps,
            p.rejected,
            p.failure.clone().unwrap_or_default().replace(',', ";")
        )?;
    }
    crate::units::write_file(&a.out.join("accuracy.csv"), &csv)?;
    for (problem, unit) in [("push", "m"), ("van-der-pol", "relative"), ("robertson", "relative")] {
        let pts: Vec<&AccuracyPoint> = rows.iter().filter(|p| p.problem == problem).collect();
        let title = if problem == "push" {
            format!("{scene_name}: error vs run time")
        } else {
            format!("{problem}: error vs run time")
        };
        plot(&a.out.join(format!("{problem}.svg")), &title, unit, &pts)
            .with_context(|| format!("plotting {problem}"))?;
    }
    Ok(())
}

/// The text report: the points, the equal-error times, the reduction's cost and table.
fn write_text(out: &mut String, a: &AccuracyArgs, report: &AccuracyReport) -> anyhow::Result<()> {
    write_points(out, a, report)?;
    if PEERS.is_empty() {
        writeln!(
            out,
            "Peer solvers: not built in (this nanopush was built without its feature `peers`): no peer points, no time to reach an error against them."
        )?;
    } else {
        write_equal_error(out, &report.equal_error)?;
    }
    if let Some(q) = &report.quasi_static_cost {
        write_quasi_static_cost(out, q)?;
    }
    if !report.reduction.is_empty() {
        write_reduction(out, &report.reduction)?;
    }
    writeln!(
        out,
        "Wrote {}/accuracy.csv and push.svg, van-der-pol.svg, robertson.svg.",
        a.out.display()
    )?;
    Ok(())
}

/// The header, then a line per work-precision point.
fn write_points(out: &mut String, a: &AccuracyArgs, report: &AccuracyReport) -> anyhow::Result<()> {
    writeln!(
        out,
        "Work-precision of scene \"{}\" ({} s push) and two classical stiff problems",
        report.scene, a.duration
    )?;
    writeln!(
        out,
        "Reference: rodas4 at rtol 1e-12; cross-check trbdf2 at rtol 1e-10 differs by {:.3e} m at the end.",
        report.reference_crosscheck
    )?;
    writeln!(
        out,
        "Errors: push in m (final: largest position error; traj: RMS of particle y and ζ_z over samples), classical problems relative."
    )?;
    writeln!(
        out,
        "{:<12} {:<17} {:>7} {:>11} {:>11} {:>11} {:>11} {:>8} {:>6}",
        "problem", "method", "rtol", "final", "traj", "estimate", "time/s", "steps", "rej"
    )?;
    for p in &report.points {
        writeln!(
            out,
            "{:<12} {:<17} {:>7.0e} {:>11} {:>11} {:>11} {:>11.3e} {:>8} {:>6}{}",
            p.problem,
            p.method,
            p.rtol,
            sci3(p.final_error),
            sci3(p.trajectory_error),
            sci3(p.estimated_error),
            p.wall_time,
            p.steps,
            p.rejected,
            p.failure.as_ref().map(|f| format!("  FAILED: {f}")).unwrap_or_default()
        )?;
    }
    Ok(())
}

/// Time to reach an error: our default against the fastest peer.
fn write_equal_error(out: &mut String, rows: &[EqualError]) -> anyhow::Result<()> {
    writeln!(
        out,
        "Time to reach an error, our default (rodas5p at rtol ≤ 1e-3, rodas4 above) against the fastest peer:"
    )?;
    for e in rows {
        writeln!(
            out,
            "  {:<12} error ≤ {:.0e}: {} {} s, {} {} s, ratio {}",
            e.problem,
            e.error,
            e.ours,
            sci3(e.ours_time),
            e.best_peer.as_deref().unwrap_or("no peer"),
            sci3(e.best_peer_time),
            e.ratio.map_or("-".into(), |r| format!("{r:.2}"))
        )?;
    }
    Ok(())
}

/// The reduction's cost against the full model, or the full model's failure.
fn write_quasi_static_cost(out: &mut String, q: &QuasiStaticCost) -> anyhow::Result<()> {
    match (&q.final_difference, &q.failure) {
        (Some(_), _) => writeln!(
            out,
            "Quasi-static reduction over {} s: {:.3e} s against {:.3e} s ({} steps) for the full 12-state model.",
            q.duration, q.reduced_wall_time, q.full_wall_time, q.full_steps
        )?,
        (None, Some(f)) => writeln!(
            out,
            "Quasi-static reduction: the full model failed over {} s: {f}",
            q.duration
        )?,
        _ => {}
    }
    Ok(())
}

/// An optional number as `1.234e-5`, or `-`.
fn sci3(v: Option<f64>) -> String {
    v.map_or("-".to_string(), |v| format!("{v:.3e}"))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Command;

    /// docs/validation.md, "`nanopush accuracy`": tolerances 1e-2 … 1e-10, a 20 ms push, 3
    /// repetitions, and the 2·10⁶-step limit beyond which a run is reported as failed.
    #[test]
    fn accuracy_defaults_are_the_documented_ones() {
        let Command::Accuracy(a) = crate::parse(&["accuracy"]) else {
            unreachable!()
        };
        assert_eq!(a.duration, 0.02);
        assert_eq!(a.reps, 3);
        assert_eq!(a.min_rtol, 1e-10);
        let tols: Vec<f64> = nanopush_study::accuracy::tolerances(a.min_rtol).collect();
        assert_eq!(tols, nanopush_study::accuracy::TOLERANCES);
        assert_eq!((tols[0], tols[tols.len() - 1]), (1e-2, 1e-10));
        assert_eq!(MAX_STEPS, 2_000_000);
    }

    /// With the peer solvers built in (feature `peers`) the report has their points (4 solvers,
    /// 3 tolerances, 2 problems) and the time to reach an error against the fastest; without
    /// them, no peer point, and the report says they are not built in.
    #[test]
    fn the_report_has_the_peers_only_when_they_are_built_in() {
        let dir = std::env::temp_dir().join(format!("nanopush-accuracy-peers-{}", std::process::id()));
        let scene = concat!(env!("CARGO_MANIFEST_DIR"), "/../scenes/minimal.toml");
        let Command::Accuracy(a) = crate::parse(&[
            "accuracy",
            "--scene",
            scene,
            "--duration",
            "0.002",
            "--reps",
            "1",
            "--min-rtol",
            "1e-4",
            "--no-full-model",
            "--out",
            dir.to_str().unwrap(),
        ]) else {
            unreachable!()
        };
        let text = run(&a).unwrap();
        let csv = std::fs::read_to_string(dir.join("accuracy.csv")).unwrap();
        std::fs::remove_dir_all(&dir).ok();
        let peer_rows = csv
            .lines()
            .filter(|l| {
                l.split(',')
                    .nth(1)
                    .is_some_and(|m| m.starts_with("diffsol") || m.starts_with("russell"))
            })
            .count();
        let compared = text.contains(
            "Time to reach an error, our default (rodas5p at rtol ≤ 1e-3, rodas4 above) against the fastest peer:",
        );
        let not_built_in = text.contains("Peer solvers: not built in");
        if cfg!(feature = "peers") {
            assert_eq!((peer_rows, compared, not_built_in), (24, true, false), "{text}");
        } else {
            assert_eq!((peer_rows, compared, not_built_in), (0, false, true), "{text}");
        }
    }
}
