//! `nanopush push`: one full manipulation — scan, locate, plan, then for each leg the Sec 2.1
//! strategy (park, contact detection, force-controlled push, retract) — and the traces of
//! Figs 9 and 15.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use clap::Args;
use nanopush_instrument::afm::Afm;
use nanopush_instrument::control::derive::{self, DerivedStrategy};
use nanopush_instrument::control::{
    DEFAULT_ATTEMPTS, Failure, MoveOptions, MoveTarget, RunRow, StrategyRun, move_particle,
};
use nanopush_instrument::scan::{HeightImage, Located};
use nanopush_instrument::scene::Scene;
use nanopush_instrument::scene::file::ControlFile;
use nanopush_proto::push::{LegReport, LocatedParticle, PushReport};

use crate::plot::{Mark, Panel, Series, stacked};

/// Arguments of `nanopush push`.
#[derive(Args, Debug)]
pub struct PushArgs {
    /// Scene file (TOML); the embedded paper scene when absent.
    #[arg(long)]
    scene: Option<PathBuf>,
    /// Particle to push (its id); the scene's `push.particle_id` when absent.
    #[arg(long, allow_hyphen_values = true)]
    particle: Option<u32>,
    /// Distance to push (µm), in (0, 100]; with `--direction-deg`.
    #[arg(long, value_name = "D", allow_hyphen_values = true)]
    distance_um: Option<f64>,
    /// Direction of the push in the plane (degrees from +x), in [-360, 360].
    #[arg(long, default_value_t = 0.0, allow_hyphen_values = true)]
    direction_deg: f64,
    /// The move is `ok` when the scan after it finds the particle within this of the target
    /// (nm), in [1, 100000]; otherwise a correction is pushed, and after the last `missed`.
    #[arg(long, value_name = "NM", default_value_t = nanopush_proto::push::TOLERANCE_NM, allow_hyphen_values = true)]
    tolerance_nm: f64,
    /// Pushes at most, the first and the corrections, in [1, 10].
    // Read as a signed integer so that `-1` is told the allowed range, not u32's.
    #[arg(long, default_value_t = DEFAULT_ATTEMPTS as i64, allow_hyphen_values = true, value_parser = crate::units::attempts_arg)]
    attempts: i64,
    /// Derive every strategy setting from the model, ignoring the scene's hand-set
    /// `[strategy]`, contact angle and speed (to compare the two).
    #[arg(long)]
    derive_all: bool,
    /// Target position instead of a distance (µm), e.g. `--to-um 60,45`: planned as several
    /// pushes when one cannot reach it.
    #[arg(long, value_name = "X_UM,Y_UM", allow_hyphen_values = true)]
    to_um: Option<String>,
    /// Loop closure: xy, z or xyz; the scene's `strategy.control` when absent.
    #[arg(long)]
    control: Option<String>,
    /// A brief stop during the (first) push at this travel (µm), as in Fig 15.
    #[arg(long, value_name = "UM", allow_hyphen_values = true)]
    pause_at_um: Option<f64>,
    /// Length of that stop (ms), in (0, 10000].
    #[arg(long, default_value_t = 500.0, allow_hyphen_values = true)]
    pause_ms: f64,
    /// Write the traces and figures here: contact.csv/svg (Fig 9), push.csv/svg (Fig 15),
    /// scan-before/after.gsf/png and summary.json.
    #[arg(long)]
    out: Option<PathBuf>,
    /// Print one JSON object (SI units) instead of a summary.
    #[arg(long)]
    pub json: bool,
    #[command(flatten)]
    instrument: crate::instrument_cmd::InstrumentArgs,
    #[command(flatten)]
    held: crate::instrument_cmd::HeldPushArgs,
}

const UM: f64 = 1e-6;
const TICK: f64 = 1e-3;

/// The target asked for: a distance (m) along a direction, or a point (µm, as given: checked in
/// the units it was given in).
enum Asked {
    Distance(f64, (f64, f64)),
    Point(f64, f64),
}

/// `--distance-um` with `--direction-deg`, or `--to-um`, checked: a distance in (0, `max_um`]
/// (`max_words` says what the bound is).
fn asked_target(a: &PushArgs, max_um: f64, max_words: &str) -> anyhow::Result<Asked> {
    match (a.distance_um, &a.to_um) {
        (Some(_), Some(_)) => bail!("give either --distance-um or --to-um, not both"),
        (None, None) => bail!("give --distance-um D (with --direction-deg) or --to-um X_UM,Y_UM"),
        (Some(d), None) => {
            if !(d.is_finite() && d > 0.0 && d <= max_um) {
                bail!(
                    "--distance-um {} is out of range; allowed: (0, {max_um}] µm{max_words}",
                    crate::units::num(d)
                );
            }
            if !(a.direction_deg.is_finite() && (-360.0..=360.0).contains(&a.direction_deg)) {
                bail!(
                    "--direction-deg {} is out of range; allowed: [-360, 360] degrees",
                    crate::units::num(a.direction_deg)
                );
            }
            let th = a.direction_deg.to_radians();
            Ok(Asked::Distance(d * UM, (th.cos(), th.sin())))
        }
        (None, Some(s)) => {
            let (x, y) = crate::units::parse_point_um("--to-um", s, "60,45")?;
            Ok(Asked::Point(x, y))
        }
    }
}

/// Where a particle located at a point is to go (m).
type Destination = dyn Fn((f64, f64)) -> (f64, f64);

/// A push on a real controller: the target from `--to-um` or `--distance-um`/`--direction-deg`.
fn run_held(a: &PushArgs, spec: &str) -> anyhow::Result<(String, bool)> {
    if a.scene.is_some()
        || a.particle.is_some()
        || a.control.is_some()
        || a.derive_all
        || a.pause_at_um.is_some()
        || a.json
    {
        bail!(
            "--scene, --particle, --control, --derive-all, --pause-at-um and --json are for the simulated AFM; with --instrument give --at-um and the target"
        );
    }
    let target: Box<Destination> = match asked_target(a, 100.0, "")? {
        Asked::Distance(d, (c, sn)) => Box::new(move |(x, y)| (x + d * c, y + d * sn)),
        Asked::Point(x, y) => Box::new(move |_| (x * UM, y * UM)),
    };
    crate::units::check_tolerance_nm(a.tolerance_nm)?;
    crate::instrument_cmd::push(
        &a.instrument,
        &a.held,
        spec,
        target,
        a.tolerance_nm * 1e-9,
        a.out.as_deref(),
    )
}

/// What the operator asked for, checked.
struct Request {
    id: u32,
    tolerance: f64,
    attempts: u32,
    target: MoveTarget,
    control: ControlFile,
    pause: Option<(f64, f64)>,
}

fn check(a: &PushArgs, scene: &Scene) -> anyhow::Result<Request> {
    let f = &scene.file;
    let id = a.particle.unwrap_or(f.push.particle_id);
    if !f.particles.iter().any(|p| p.id == id) {
        let ids: Vec<String> = f.particles.iter().map(|p| p.id.to_string()).collect();
        bail!(
            "--particle {id}: no such particle; ids in the scene: {}",
            ids.join(", ")
        );
    }
    let range = f.stage.range_um;
    let target = match asked_target(a, range, " (the stage range)")? {
        Asked::Distance(distance, direction) => MoveTarget::Distance { distance, direction },
        Asked::Point(x, y) => {
            if !((0.0..=range).contains(&x) && (0.0..=range).contains(&y)) {
                bail!(
                    "--to-um {},{} is outside the stage; allowed: [0, {range}] µm in x and y",
                    crate::units::num(x),
                    crate::units::num(y)
                );
            }
            MoveTarget::Point((x * UM, y * UM))
        }
    };
    let control = match a.control.as_deref() {
        None => f.strategy.control,
        Some("xy") => ControlFile::Xy,
        Some("z") => ControlFile::Z,
        Some("xyz") => ControlFile::Xyz,
        Some(other) => bail!("--control {}: unknown; allowed: xy, z, xyz", crate::units::echo(other)),
    };
    let pause = match a.pause_at_um {
        None => None,
        Some(at) => {
            if !(at.is_finite() && at > 0.0 && at <= range) {
                bail!(
                    "--pause-at-um {} is out of range; allowed: (0, {range}] µm",
                    crate::units::num(at)
                );
            }
            if !(a.pause_ms.is_finite() && a.pause_ms > 0.0 && a.pause_ms <= 10_000.0) {
                bail!(
                    "--pause-ms {} is out of range; allowed: (0, 10000] ms",
                    crate::units::num(a.pause_ms)
                );
            }
            Some((at * UM, a.pause_ms * 1e-3))
        }
    };
    crate::units::check_tolerance_nm(a.tolerance_nm)?;
    let attempts = match u32::try_from(a.attempts) {
        Ok(n) if (1..=10).contains(&n) => n,
        _ => bail!("--attempts {} is out of range; allowed: [1, 10]", a.attempts),
    };
    Ok(Request {
        id,
        tolerance: a.tolerance_nm * 1e-9,
        attempts,
        target,
        control,
        pause,
    })
}

fn located(l: &Located) -> LocatedParticle {
    LocatedParticle {
        x: l.x,
        y: l.y,
        radius: l.radius,
    }
}

fn leg_report(run: &StrategyRun, from: (f64, f64), to: (f64, f64), attempt: u32) -> LegReport {
    let s = &run.summary;
    LegReport {
        from: [from.0, from.1],
        to: [to.0, to.1],
        outcome: s.failure.as_ref().map_or("ok", Failure::code).into(),
        failure: run.failure_text(),
        contact_step: s.contact_step,
        t_star: s.t_star,
        estimated_distance: s.estimated_distance,
        true_distance: run.true_distance(),
        search_distance: run.search_distance(),
        push_travel: s.push_travel,
        settle_offset: run.prediction.settle_offset,
        retract_shift: run.prediction.retract_shift,
        retracted: run.retracted,
        attempt,
    }
}

/// Exit status of a push that ran but whose outcome is not `ok` (a failure code, `missed`,
/// `not_found`: the tip is retracted and the report written). Errors (bad input, a failed
/// simulation, a scene no strategy can push) exit 2.
pub const EXIT_FAILED_PUSH: u8 = 1;

/// Runs the command: the report, and whether the move ended `ok` (within the tolerance, as the
/// scan after it measured).
pub fn run(a: &PushArgs) -> anyhow::Result<(String, bool)> {
    if let Some(spec) = &a.instrument.instrument {
        return run_held(a, spec);
    }
    if a.held.at_um.is_some() {
        bail!("--at-um is for a real controller (with --instrument); on the simulated AFM give --particle");
    }
    let scene = crate::load_scene(a.scene.as_ref())?;
    let req = check(a, &scene)?;
    let wall = std::time::Instant::now();
    let mut scene = scene;
    if a.derive_all {
        scene.hand_set = nanopush_instrument::scene::hand_set::HandSet::none();
    }
    // The plan is derived and dry-run with the loop closure the push will use.
    scene.file.strategy.control = req.control;
    let plan = derive::derive(&scene, req.id, req.tolerance)?;
    plan.apply(&mut scene);
    let f = &scene.file;
    let part = f.particles.iter().find(|p| p.id == req.id).expect("checked");
    let click = (part.x_um * UM, part.y_um * UM);

    // The operator's view: a local scan at the click, and the scene's overview for the plan.
    let start = (click.0 - 8.0 * UM, click.1);
    let mut afm = Afm::from_scene(&scene, start.0.max(0.0), start.1, TICK);
    let options = MoveOptions {
        tolerance: req.tolerance,
        attempts: req.attempts,
        pause: req.pause,
    };
    let moved = move_particle(
        &scene,
        &mut afm,
        req.id,
        click,
        part.radius_nm * 1e-9,
        req.target,
        options,
    )?;
    let reports: Vec<LegReport> = moved
        .legs
        .iter()
        .map(|l| leg_report(&l.run, l.from, l.to, l.attempt))
        .collect();
    let truth = afm
        .particles()
        .iter()
        .find(|p| p.id == req.id)
        .expect("the particle exists");
    let target = moved.target;
    let after = moved.after.1.as_ref();
    let report = PushReport {
        schema: "push".into(),
        version: nanopush_proto::VERSION,
        scene: f.name.clone(),
        particle: req.id,
        control: req.control.name().into(),
        located_before: located(&moved.before.1),
        located_after: after.map(located),
        target: [target.0, target.1],
        legs: reports,
        outcome: moved.verdict.code().into(),
        tolerance: req.tolerance,
        measured_error: after.map(|l| (l.x - target.0).hypot(l.y - target.1)),
        attempts: moved.attempts,
        cut_short: moved.cut_short,
        warnings: plan.warnings.clone(),
        final_position: [truth.x, truth.y],
        final_error: (truth.x - target.0).hypot(truth.y - target.1),
        simulated_time: afm.time(),
        wall_time: wall.elapsed().as_secs_f64(),
    };
    let runs: Vec<StrategyRun> = moved.legs.into_iter().map(|l| l.run).collect();
    if let Some(dir) = &a.out {
        write_outputs(dir, &scene, &runs, &report, &moved.before.0, &moved.after.0)?;
    }
    let ok = report.outcome == "ok";
    if a.json {
        return Ok((serde_json::to_string_pretty(&report)? + "\n", ok));
    }
    Ok((text(&report, &runs, &plan), ok))
}

fn text(r: &PushReport, runs: &[StrategyRun], plan: &DerivedStrategy) -> String {
    let mut s = String::new();
    for w in &plan.warnings {
        let _ = writeln!(s, "warning: {w}");
    }
    let um = |v: f64| v / UM;
    let _ = writeln!(
        s,
        "Push of particle {} in scene {:?} ({} control)",
        r.particle, r.scene, r.control
    );
    let b = &r.located_before;
    let _ = writeln!(
        s,
        "  located at ({:.3}, {:.3}) µm, radius {:.1} nm (scan)",
        um(b.x),
        um(b.y),
        b.radius * 1e9
    );
    let _ = writeln!(
        s,
        "  target ({:.3}, {:.3}) µm in {} leg(s)",
        um(r.target[0]),
        um(r.target[1]),
        r.legs.len()
    );
    for (k, (l, run)) in r.legs.iter().zip(runs).enumerate() {
        let _ = writeln!(
            s,
            "  leg {}{}: {} | contact at step {} | t* {} | estimated {:.3} µm, true {:.3} µm (error {:+.1} nm) | retracted {}",
            k + 1,
            if l.attempt > 1 {
                format!(" (correction {})", l.attempt - 1)
            } else {
                String::new()
            },
            // A leg that ran to its end is `pushed`: only the scan after the move says `ok`.
            l.failure.as_deref().unwrap_or("pushed"),
            l.contact_step.map_or("-".into(), |v| v.to_string()),
            l.t_star.map_or("-".into(), |t| format!("{t:.3} s")),
            um(l.estimated_distance),
            um(l.true_distance),
            (l.true_distance - (run.task.distance)) * 1e9,
            l.retracted,
        );
    }
    let _ = writeln!(
        s,
        "  final position ({:.3}, {:.3}) µm: {:.1} nm from the target",
        um(r.final_position[0]),
        um(r.final_position[1]),
        r.final_error * 1e9
    );
    if let Some(a) = &r.located_after {
        let _ = writeln!(s, "  scan after: ({:.3}, {:.3}) µm", um(a.x), um(a.y));
    }
    let verdict = match (r.outcome.as_str(), r.measured_error) {
        ("ok", Some(e)) => format!(
            "ok: the scan after finds it {:.1} nm from the target (tolerance {} nm)",
            e * 1e9,
            nanopush_instrument::nm_text(r.tolerance)
        ),
        ("missed", Some(e)) => format!(
            "missed: the scan after finds it {:.1} nm from the target, beyond the {} nm tolerance, after {} push(es){}",
            e * 1e9,
            nanopush_instrument::nm_text(r.tolerance),
            r.attempts,
            r.cut_short.map_or(String::new(), |c| format!(
                ": the stage's edge cut the push {:.0} nm short of the retraction's drag, and would cut a correction the same way",
                c * 1e9
            ))
        ),
        ("not_found", _) => "not_found: the scan after the push does not find the particle".into(),
        (code, _) => format!("{code}: a push failed (its leg says why)"),
    };
    let _ = writeln!(s, "  outcome {verdict}");
    let _ = writeln!(
        s,
        "  simulated {:.2} s in {:.2} s of wall time",
        r.simulated_time, r.wall_time
    );
    s
}

fn trace_csv(runs: &[StrategyRun]) -> String {
    let mut s = String::from(
        "leg,t_s,phase,stage_x_um,stage_y_um,stage_z_um,volts,estimate_um,particle_x_um,particle_y_um,contact\n",
    );
    for (k, run) in runs.iter().enumerate() {
        for r in &run.trace {
            let RunRow {
                t,
                phase,
                stage,
                volts,
                estimate,
                particle,
                contact,
            } = *r;
            let _ = writeln!(
                s,
                "{},{t:.4},{phase},{:.6},{:.6},{:.6},{volts:.5},{:.6},{:.6},{:.6},{contact}",
                k + 1,
                stage[0] / UM,
                stage[1] / UM,
                stage[2] / UM,
                estimate / UM,
                particle.0 / UM,
                particle.1 / UM,
            );
        }
    }
    s
}

fn write_outputs(
    dir: &Path,
    scene: &Scene,
    runs: &[StrategyRun],
    report: &PushReport,
    before: &HeightImage,
    after: &HeightImage,
) -> anyhow::Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    // Fig 9: the reading after each contact-search step of the first leg.
    if let Some(first) = runs.first() {
        let mut csv = String::from("step,volts\n");
        for st in &first.summary.search {
            let _ = writeln!(csv, "{},{:.5}", st.step, st.volts);
        }
        crate::units::write_file(&dir.join("contact.csv"), csv.as_bytes())?;
        let pts: Vec<(f64, f64)> = first.summary.search.iter().map(|s| (s.step as f64, s.volts)).collect();
        let set = scene.file.strategy.set_point_v;
        let (x0, x1) = (pts.first().map_or(0.0, |p| p.0), pts.last().map_or(1.0, |p| p.0));
        stacked(
            &dir.join("contact.svg"),
            "Automatic contact detection (Fig 9)",
            "step of Δ",
            &[Panel {
                y_desc: "deflection reading (V)".into(),
                series: vec![
                    Series {
                        label: "reading after each step".into(),
                        points: pts,
                        mark: Mark::Circle,
                        color: 0,
                        bars: vec![],
                    },
                    Series {
                        label: format!("ζ_set = {set} V"),
                        points: vec![(x0, set), (x1, set)],
                        mark: Mark::Line,
                        color: 1,
                        bars: vec![],
                    },
                ],
            }],
        )?;
    }
    crate::units::write_file(&dir.join("push.csv"), trace_csv(runs).as_bytes())?;
    // Fig 15: the reading against the stage position along the push, while pushing.
    let mut reading = Vec::new();
    let mut particle = Vec::new();
    for run in runs {
        let d = run.task.direction;
        for r in run.trace.iter().filter(|r| r.phase == "push") {
            let along = (r.stage[0] * d.0 + r.stage[1] * d.1) / UM;
            reading.push((along, r.volts));
            particle.push((along, (r.particle.0 * d.0 + r.particle.1 * d.1) / UM));
        }
    }
    stacked(
        &dir.join("push.svg"),
        "Deflection during pushing (Fig 15)",
        "stage position along the push (µm)",
        &[
            Panel {
                y_desc: "deflection reading (V)".into(),
                series: vec![Series {
                    label: "reading".into(),
                    points: reading,
                    mark: Mark::Line,
                    color: 0,
                    bars: vec![],
                }],
            },
            Panel {
                y_desc: "particle position (µm, simulator)".into(),
                series: vec![Series {
                    label: "particle".into(),
                    points: particle,
                    mark: Mark::Line,
                    color: 2,
                    bars: vec![],
                }],
            },
        ],
    )?;
    for (name, img) in [("scan-before", before), ("scan-after", after)] {
        let mut gsf = Vec::new();
        nanopush_instrument::scan::write_gsf(&mut gsf, img, name)?;
        crate::units::write_file(&dir.join(format!("{name}.gsf")), &gsf)?;
        let mut png = Vec::new();
        nanopush_instrument::scan::write_png(&mut png, img)?;
        crate::units::write_file(&dir.join(format!("{name}.png")), &png)?;
    }
    crate::units::write_file(
        &dir.join("summary.json"),
        (serde_json::to_string_pretty(report)? + "\n").as_bytes(),
    )?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn args(a: &[&str]) -> PushArgs {
        match crate::parse(a) {
            crate::Command::Push(p) => p,
            other => panic!("{other:?}"),
        }
    }

    /// A negative number after a flag is the flag's value, not another flag: `--direction-deg -90`
    /// (the help gives [-360, 360]), a negative point (`--to-um -1,50`) and a negative number in
    /// exponent form (`-1e-320`).
    #[test]
    fn a_negative_direction_is_a_number() {
        let a = args(&["push", "--distance-um", "1", "--direction-deg", "-90"]);
        assert_eq!(a.direction_deg, -90.0);
        let r = check(&a, &Scene::default_scene()).unwrap();
        match r.target {
            MoveTarget::Distance { direction, .. } => assert!((direction.1 + 1.0).abs() < 1e-12),
            t => panic!("{t:?}"),
        }
        let e = check(&args(&["push", "--distance-um", "1e308"]), &Scene::default_scene())
            .err()
            .unwrap()
            .to_string();
        assert!(e.starts_with("--distance-um 1e308 is out of range"), "{e}");
        assert_eq!(args(&["push", "--distance-um", "1"]).tolerance_nm, 25.0);
        // A negative point and a negative number in exponent form are values too.
        let a = args(&["push", "--to-um", "-1,50", "--direction-deg", "-1e-320"]);
        assert_eq!((a.to_um.as_deref(), a.direction_deg), (Some("-1,50"), -1e-320));
        let e = check(&args(&["push", "--to-um", "-1,50"]), &Scene::default_scene())
            .err()
            .unwrap()
            .to_string();
        assert!(e.contains("-1"), "{e}");
    }
}
