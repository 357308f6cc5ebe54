//! A push prepared off the loop and off the async workers: a quick local scan locates the
//! particle, the move is planned and the model predicts it; then the job goes to the loop, and
//! the scan after it judges the move (`judge.rs`).

use std::sync::atomic::Ordering::Relaxed;

use nanopush_proto::ws::{ErrorCode, PushPath, ServerMessage};

use crate::app_state::AppState;
use crate::command_checks::Refusal;
use crate::control_loop::{LoopCommand, PushJob};
use crate::judge;
use nanopush_instrument::control::derive::{self, derive};
use nanopush_instrument::control::{MoveRoute, MoveTarget, Prepared, route_move};

/// Whether a particle of radius `r` (m) can be pushed to `p` (m): its centre at least a radius
/// inside the stage's `[0, range]` square, so the particle stays on the stage and the tip, which
/// stays inside it, can reach behind it. Checked as the planner checks it
/// ([`nanopush_instrument::control::route::on_stage`]: in µm, the bounds rounded inward to the nanometre, as
/// the refusal prints them).
pub(crate) fn on_stage(p: (f64, f64), r: f64, range: f64) -> Result<(), Refusal> {
    if nanopush_instrument::control::route::on_stage(p, r, range) {
        return Ok(());
    }
    let (lo, hi) = nanopush_instrument::control::route::centre_bounds_um(r, range);
    Err(Refusal::new(
        ErrorCode::OutOfRange,
        format!(
            "target ({:.3}, {:.3}) µm is out of range for a particle {:.3} µm in radius; allowed: [{lo:.3}, {hi:.3}] µm in x and y",
            p.0 * 1e6,
            p.1 * 1e6,
            r * 1e6,
        ),
    ))
}

/// A move as the operator asked for it: the particle, the tolerance it must end within, the
/// `stop` generation it began in, and who asked.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Move {
    /// Particle id.
    pub particle: u32,
    /// `ok` within this of the target, as the scan after the push measures it (m).
    pub tolerance: f64,
    /// [`crate::app_state::Activity::generation`] when it was asked: a `stop` changes it.
    pub generation: u64,
    /// The client that asked.
    pub by: u32,
}

/// A push the loop runs, whose move the scan after it judges (`judge.rs`).
#[derive(Debug, Clone, PartialEq)]
pub struct Pending {
    pub(crate) mv: Move,
    /// The target (m).
    pub(crate) target: (f64, f64),
    /// The particle's radius in the scene (m): what the command's target was checked against,
    /// and the local scans' hint.
    pub(crate) radius: f64,
    /// Which push of the move this is (1, then the corrections).
    pub(crate) attempt: u32,
    /// Its model prediction and geometry.
    pub(crate) prepared: Prepared,
}

/// A push that ended before the loop ran it (refused by the plan, stopped, the queue full): its
/// `run_done` to everyone, and to the audit log under the person who asked.
pub(crate) fn run_done_failed(st: &AppState, by: u32, particle: u32, outcome: &str, failure: String) {
    audit_early_end(st, by, particle, outcome, Some(&failure));
    st.push_ended(false);
    st.shared.busy.store(false, Relaxed);
    st.broadcast_event(&ServerMessage::RunDone {
        particle,
        outcome: outcome.into(),
        failure: Some(failure),
        estimate: None,
        record: None,
        record_error: None,
        judged: None,
    });
}

/// A move that ended before the loop ran it, in the audit log under the person who asked.
pub(crate) fn audit_early_end(st: &AppState, by: u32, particle: u32, outcome: &str, failure: Option<&str>) {
    let person = st.auth.name_of(by).unwrap_or_else(|| format!("client {by}"));
    let mut args = serde_json::Map::new();
    args.insert("particle".into(), particle.into());
    st.audit.event(crate::audit::Happened {
        person: &person,
        address: None,
        client: Some(by),
        command: "run_done",
        args,
        outcome,
        message: failure,
    });
}

/// Strategy plans kept at most (particle and tolerance pairs).
const PLANS_KEPT: usize = 64;

/// The scene with particle `particle`'s strategy plan for `tolerance` applied (hand-set values
/// win), the plan derived on the first push that asks for it and kept; or why no strategy can
/// push it.
pub(crate) fn strategy_scene(
    st: &AppState,
    particle: u32,
    tolerance: f64,
) -> Result<nanopush_instrument::scene::Scene, derive::Refusal> {
    let key = (particle, tolerance.to_bits());
    let cached = st.activity.plans.lock().ok().and_then(|p| p.get(&key).cloned());
    let outcome = cached.unwrap_or_else(|| {
        let outcome = derive(&st.scene, particle, tolerance);
        match &outcome {
            Ok(plan) => {
                for w in &plan.warnings {
                    tracing::warn!("strategy plan for particle {particle}: {w}");
                }
            }
            Err(e) => tracing::warn!("{e}"),
        }
        if let Ok(mut p) = st.activity.plans.lock() {
            // One plan per particle and tolerance asked for: bounded, however many tolerances
            // a client tries (the plans are derived again when needed).
            if p.len() >= PLANS_KEPT {
                p.clear();
            }
            p.insert(key, outcome.clone());
        }
        outcome
    });
    let plan = outcome?;
    let mut scene = st.scene.clone();
    plan.apply(&mut scene);
    Ok(scene)
}

/// Off the loop: locate the particle in a quick local scan, plan, predict; then hand the first
/// push to the loop ([`launch`]). A particle already within the planner's 10 nm of the target is
/// judged where the scan found it.
pub(crate) fn prepare_push(st: &AppState, mv: Move, target: MoveTarget) {
    let f = &st.scene.file;
    let particle = mv.particle;
    let Some(part) = f.particles.iter().find(|p| p.id == particle) else {
        return;
    };
    let nominal = st
        .activity
        .estimates
        .lock()
        .ok()
        .and_then(|e| e.get(&particle).copied())
        .unwrap_or((part.x_um * 1e-6, part.y_um * 1e-6));
    // The strategy for this particle: the plan's, where the scene sets none (derived once).
    let scene = match strategy_scene(st, particle, mv.tolerance) {
        Ok(s) => s,
        Err(refusal) => return run_done_failed(st, mv.by, particle, "refused", refusal.to_string()),
    };
    let plan = match route_move(&scene, &st.surface_now(), nominal, part.radius_nm * 1e-9, target) {
        Ok(p) => p,
        Err(e) => return run_done_failed(st, mv.by, particle, "plan", format!("particle {particle}: {e}")),
    };
    // A target the particle cannot reach whole, with the tip behind it, fails now, not after a
    // push that runs into the stage's edge until its time-out.
    // Against the scene's radius, as the command's check stated the range (the located one
    // differs by a fraction of a nanometre: a target on the stated edge was accepted, then
    // refused here with other bounds).
    if let Err(r) = on_stage(plan.target, part.radius_nm * 1e-9, f.stage.range_um * 1e-6) {
        return run_done_failed(
            st,
            mv.by,
            particle,
            "plan",
            format!("particle {particle}: {}", r.message),
        );
    }
    if plan.legs.is_empty() {
        // Already there (within the planner's 10 nm): judged where the scan found it, no push.
        return judge::already_there(st, mv, &plan);
    }
    if let Err((outcome, failure)) = launch(st, mv, &scene, plan, 1) {
        run_done_failed(st, mv.by, particle, outcome, failure);
    }
}

/// Hands push `attempt` of move `mv` (the legs of `plan`, from where its local scan found the
/// particle) to the loop, and says so (`push_started`); its end is judged by `judge.rs`. When it
/// cannot start, the move's outcome and why, for the caller to end the move with (nothing is
/// said to anyone yet).
pub(crate) fn launch(
    st: &AppState,
    mv: Move,
    scene: &nanopush_instrument::scene::Scene,
    plan: MoveRoute,
    attempt: u32,
) -> Result<(), (&'static str, String)> {
    let particle = mv.particle;
    let params = scene.strategy_params(st.params.tick);
    let prepared =
        Prepared::new(scene, particle, plan.located.radius, &params).map_err(|e| ("error", e.to_string()))?;
    if let Err(e) = prepared.check_reach(&plan.legs) {
        let push = if attempt == 1 {
            String::new()
        } else {
            format!(" (correction {})", attempt - 1)
        };
        return Err(("plan", format!("particle {particle}{push}: {e}")));
    }
    if st.activity.generation.load(Relaxed) != mv.generation || st.activity.stopping.load(Relaxed) {
        let when = if attempt == 1 {
            "stopped before the push began".to_string()
        } else {
            format!("stopped before correction {} began", attempt - 1)
        };
        return Err(("stopped", when));
    }
    let run = st.shared.runs.fetch_add(1, Relaxed) + 1;
    // Who ran it, for its record and the audit log's `run_done` (the session may be gone by
    // now: then its client number).
    if let Ok(mut people) = st.audit.runs.lock() {
        people.insert(
            run,
            st.auth.name_of(mv.by).unwrap_or_else(|| format!("client {}", mv.by)),
        );
    }
    let located = plan.located;
    let scene_radius = st
        .scene
        .file
        .particles
        .iter()
        .find(|p| p.id == particle)
        .map_or(located.radius, |p| p.radius_nm * 1e-9);
    let mut path = vec![[located.x, located.y]];
    path.extend(plan.legs.iter().map(|l| [l.to.0, l.to.1]));
    // The plan's warnings, said to everyone with the move's first push.
    let warnings = (attempt == 1)
        .then(|| {
            let plans = st.activity.plans.lock().ok()?;
            let plan = plans.get(&(particle, mv.tolerance.to_bits()))?.as_ref().ok()?;
            Some(plan.warnings.clone())
        })
        .flatten()
        .unwrap_or_default();
    let started = PushPath {
        particle,
        path,
        by: mv.by,
        run,
        attempt,
        warnings,
    };
    if let Ok(mut j) = st.activity.judging.lock() {
        j.insert(
            run,
            Pending {
                mv,
                target: plan.target,
                radius: scene_radius,
                attempt,
                prepared: prepared.clone(),
            },
        );
    }
    let job = PushJob {
        run,
        particle,
        legs: plan.legs,
        prepared,
        params,
    };
    // Said after the job is queued: a `stop` sent on hearing `push_started` reaches the loop
    // after the push, and stops it.
    if let Ok(mut p) = st.activity.push_now.lock() {
        *p = Some(started.clone());
    }
    if st.shared.commands.push(LoopCommand::Push(Box::new(job))).is_err() {
        st.shared.metrics.dropped_commands.fetch_add(1, Relaxed);
        if let Ok(mut j) = st.activity.judging.lock() {
            j.remove(&run);
        }
        return Err(("error", "the control loop's command queue is full".into()));
    }
    st.broadcast_event(&ServerMessage::PushStarted(started));
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::on_stage;

    /// Issue 27.9: the edges the refusal states are accepted, in µm as sent; a nanometre past
    /// them is not.
    #[test]
    fn a_target_on_the_stated_edge_is_on_the_stage() {
        let (r, range) = (500.0 * 1e-9, 100.0 * 1e-6);
        for edge in [0.5, 99.5] {
            assert_eq!(on_stage((edge * 1e-6, 30.0 * 1e-6), r, range), Ok(()), "{edge}");
        }
        for past in [0.499, 99.501] {
            let e = on_stage((past * 1e-6, 30.0 * 1e-6), r, range).unwrap_err();
            assert!(e.message.contains("allowed: [0.500, 99.500] µm"), "{}", e.message);
        }
        // A radius between nanometres: the bounds are rounded inward, and the stated one holds.
        let e = on_stage((0.0, 0.0), 251.37e-9, range).unwrap_err();
        assert!(e.message.contains("allowed: [0.252, 99.748] µm"), "{}", e.message);
        assert_eq!(on_stage((0.252e-6, 99.748e-6), 251.37e-9, range), Ok(()));
    }
}
