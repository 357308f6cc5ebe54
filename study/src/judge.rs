//! One whole move planned, pushed and judged as `nanopush push` judges it, then checked against
//! the truth the simulation knows: the judge of the whole pushes ([`crate::whole_pushes`]) and of
//! the random scenes ([`crate::random_scenes`]).

use std::time::Instant;

use nanopush_instrument::afm::Afm;
use nanopush_instrument::control::derive;
use nanopush_instrument::control::moves::locate::MoveTarget;
use nanopush_instrument::control::{
    DEFAULT_ATTEMPTS, MoveOptions, MoveRun, MoveRunError, RunError, RunRow, Verdict, move_particle,
};
use nanopush_instrument::scene::Scene;

const UM: f64 = 1e-6;

/// A whole move planned, pushed and judged.
#[derive(Debug, Clone, PartialEq)]
pub struct Judged {
    /// `ok`, `missed`, `not_found`, a failure code, `refused` or `error`.
    pub outcome: String,
    /// Why it was refused (the plan's code, or `scene`, `locate`, `model`), when it was.
    pub refusal: Option<String>,
    /// The reason (empty for `ok`).
    pub reason: String,
    /// Distance asked for (m).
    pub distance: f64,
    /// The particle's true displacement along the push (m).
    pub moved: f64,
    /// The true distance from the target at the end (m), when pushed.
    pub true_error: Option<f64>,
    /// The distance from the target the scan after measured (m).
    pub measured_error: Option<f64>,
    /// Pushes made.
    pub attempts: u32,
    /// Largest |reading| (V).
    pub max_volts: f64,
    /// Checks that failed (empty when sound): no panic, rows finite, readings inside the
    /// readout, the particle on the stage, and an `ok` truly within the tolerance, retracted.
    pub violations: Vec<String>,
    /// The tip ended retracted.
    pub retracted: bool,
    /// Ticks run.
    pub ticks: usize,
    /// Memory of the traces (bytes).
    pub trace_bytes: usize,
    /// Simulated time (s).
    pub simulated: f64,
    /// Wall time (s).
    pub wall_time: f64,
    /// The values a refusal names as a way out, each checked or not by the plan.
    pub advice: Vec<derive::Advice>,
}

impl Judged {
    fn refused(code: &str, reason: String, distance: f64) -> Judged {
        Judged {
            outcome: "refused".into(),
            refusal: Some(code.into()),
            reason,
            distance,
            moved: 0.0,
            true_error: None,
            measured_error: None,
            attempts: 0,
            max_volts: 0.0,
            violations: Vec::new(),
            retracted: true,
            ticks: 0,
            trace_bytes: 0,
            simulated: 0.0,
            wall_time: 0.0,
            advice: Vec::new(),
        }
    }
}

/// Plans `scene`'s pushed particle (the plan derives what the scene does not set), moves it
/// `distance` (m) along the unit `direction` from where a local scan finds it, and judges the
/// move against `tolerance` (m) as `nanopush push` does; then checks it against the truth the
/// simulation knows. Never panics on a valid scene: a panic is caught and reported as a
/// violation.
pub fn push_judged(scene: &Scene, distance: f64, direction: (f64, f64), tolerance: f64) -> Judged {
    let start = Instant::now();
    let caught = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
        judge_inner(scene, distance, direction, tolerance)
    }));
    let mut j = caught.unwrap_or_else(|p| {
        let mut j = Judged::refused("error", String::new(), distance);
        j.outcome = "error".into();
        j.refusal = None;
        j.violations
            .push(format!("panic: {}", nanopush_instrument::panic_message(&*p)));
        j
    });
    j.wall_time = start.elapsed().as_secs_f64();
    j
}

fn judge_inner(scene: &Scene, distance: f64, direction: (f64, f64), tolerance: f64) -> Judged {
    let p = scene.pushed_particle();
    let plan = match derive::derive(scene, p.id, tolerance) {
        Ok(plan) => plan,
        Err(e) => {
            let mut j = Judged::refused(e.code, e.to_string(), distance);
            j.advice = e.advice;
            return j;
        }
    };
    let mut scene = scene.clone();
    plan.apply(&mut scene);
    // With the plan's start height and angle (a dynamic particle or lever is refused here).
    if let Err(e) = scene.pushable(p.id) {
        return Judged::refused("scene", e.to_string(), distance);
    }
    let (x, y, r) = (p.x_um * UM, p.y_um * UM, p.radius_nm * 1e-9);
    let range = scene.file.stage.range_um * UM;
    let back = scene.file.strategy.approach_distance_um * UM + r + 2.0 * UM;
    let clamp = |v: f64| v.clamp(0.0, range);
    let mut afm = Afm::from_scene(
        &scene,
        clamp(x - direction.0 * back),
        clamp(y - direction.1 * back),
        1e-3,
    );
    let options = MoveOptions {
        tolerance,
        attempts: DEFAULT_ATTEMPTS,
        pause: None,
    };
    let target = MoveTarget::Distance { distance, direction };
    let moved = match move_particle(&scene, &mut afm, p.id, (x, y), r, target, options) {
        Ok(m) => m,
        Err(MoveRunError::Locate(e)) => return Judged::refused("locate", e.to_string(), distance),
        Err(MoveRunError::Run(RunError::Predict(e))) => {
            return Judged::refused("model", format!("the estimator's prediction failed: {e}"), distance);
        }
        Err(MoveRunError::Run(RunError::NotPushable(e))) => return Judged::refused("scene", e, distance),
        Err(MoveRunError::Run(e)) => {
            let mut j = Judged::refused("error", e.to_string(), distance);
            j.outcome = "error".into();
            j.refusal = None;
            j.violations.push(format!("the run failed: {e}"));
            return j;
        }
    };
    let truth = afm
        .particles()
        .iter()
        .find(|q| q.id == p.id)
        .copied()
        .expect("the particle exists");
    let true_error = (truth.x - moved.target.0).hypot(truth.y - moved.target.1);
    let mut j = Judged {
        outcome: moved.verdict.code().into(),
        refusal: None,
        reason: String::new(),
        distance,
        moved: (truth.x - x) * direction.0 + (truth.y - y) * direction.1,
        true_error: Some(true_error),
        measured_error: moved
            .after
            .1
            .map(|l| (l.x - moved.target.0).hypot(l.y - moved.target.1)),
        attempts: moved.attempts,
        max_volts: 0.0,
        violations: Vec::new(),
        retracted: moved.legs.last().is_none_or(|l| l.run.retracted),
        ticks: moved.legs.iter().map(|l| l.run.trace.len()).sum(),
        trace_bytes: moved
            .legs
            .iter()
            .map(|l| l.run.trace.capacity() * std::mem::size_of::<RunRow>())
            .sum(),
        simulated: afm.time(),
        wall_time: 0.0,
        advice: Vec::new(),
    };
    j.reason = match &moved.verdict {
        Verdict::Ok { .. } => String::new(),
        Verdict::Missed { error } => format!(
            "the scan after the last of {} push(es) finds it {:.1} nm from the target, beyond the {} nm tolerance",
            moved.attempts,
            error * 1e9,
            nanopush_instrument::nm_text(tolerance)
        ),
        Verdict::NotFound => "the scan after the push does not find the particle".into(),
        Verdict::Failed { .. } => moved.legs.last().and_then(|l| l.run.failure_text()).unwrap_or_default(),
    };
    check_traces(&scene, &moved, r, &mut j);
    if j.outcome == "ok" && true_error > tolerance {
        j.violations.push(format!(
            "ok, but the particle is truly {:.2} nm from the target (tolerance {} nm)",
            true_error * 1e9,
            nanopush_instrument::nm_text(tolerance)
        ));
    }
    // A failed push may leave a soft lever stuck to the surface by adhesion it cannot pull
    // free within the retraction (a failure, said in the reason); an `ok` never.
    if !j.retracted {
        if j.outcome == "ok" {
            j.violations.push("ok, but the tip did not end retracted".into());
        } else {
            j.reason.push_str("; the tip did not come free of the surface");
        }
    }
    j
}

/// The soundness of every tick: finite, inside the readout, the particle on the stage.
fn check_traces(scene: &Scene, moved: &MoveRun, r: f64, j: &mut Judged) {
    let range = scene.file.stage.range_um * UM;
    let full_scale = scene.file.sensor.full_scale_v;
    for row in moved.legs.iter().flat_map(|l| l.run.trace.iter()) {
        j.max_volts = j.max_volts.max(row.volts.abs());
        let finite = row.volts.is_finite()
            && row.stage.iter().all(|v| v.is_finite())
            && row.particle.0.is_finite()
            && row.particle.1.is_finite();
        if !finite {
            j.violations.push(format!("non-finite row at t = {} s: {row:?}", row.t));
            return;
        }
        if row.volts.abs() > full_scale {
            j.violations
                .push(format!("reading {} V beyond the ±{full_scale} V readout", row.volts));
            return;
        }
        let inside = |v: f64| (-r..=range + r).contains(&v);
        if !(inside(row.particle.0) && inside(row.particle.1)) {
            j.violations.push(format!(
                "particle outside the stage at t = {} s: {:?}",
                row.t, row.particle
            ));
            return;
        }
    }
}
