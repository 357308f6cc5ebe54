//! A push handed to the control loop ([`launch`]), with what it needs: the particle's strategy
//! plan, derived once per tolerance ([`strategy_scene`]); and a move that ends before the loop
//! runs it ([`run_done_failed`]).

use std::sync::atomic::Ordering::Relaxed;

use nanopush_proto::ws::{ChosenStrategy, PushPath, ServerMessage};

use crate::app_state::{AppState, Move, Pending};
use crate::control_loop::{LoopCommand, PushJob};
use nanopush_instrument::control::derive::{self, derive};
use nanopush_instrument::control::{MoveRoute, Prepared};

/// A push that ended before the loop ran it (refused by the plan, stopped, the queue full): its
/// `run_done` to everyone, and to the audit log under the person who asked.
pub(crate) fn run_done_failed(st: &AppState, mv: &Move, particle: u32, outcome: &str, failure: String) {
    audit_early_end(st, mv, particle, outcome, Some(&failure));
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
pub(crate) fn audit_early_end(st: &AppState, mv: &Move, particle: u32, outcome: &str, failure: Option<&str>) {
    let mut args = serde_json::Map::new();
    args.insert("particle".into(), particle.into());
    st.audit.event(crate::audit::Happened {
        person: &mv.person,
        address: None,
        client: Some(mv.by),
        command: "run_done",
        args,
        outcome,
        message: failure,
    });
}

/// Strategy plans kept at most (particle and tolerance pairs).
pub(crate) const PLANS_KEPT: usize = 64;

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
    // Who ran it, for its record and the audit log's `run_done` (as the move was asked: the
    // session may be gone by now).
    if let Ok(mut people) = st.audit.runs.lock() {
        people.insert(run, mv.person.to_string());
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
    // The plan's choice and warnings, said to everyone with the move's first push.
    let (warnings, strategy) = (attempt == 1)
        .then(|| {
            let plans = st.activity.plans.lock().ok()?;
            let plan = plans.get(&(particle, mv.tolerance.to_bits()))?.as_ref().ok()?;
            let chosen = ChosenStrategy {
                summary: plan.summary(),
                tried: plan.tried.iter().take(16).cloned().collect(),
            };
            Some((plan.warnings.clone(), Some(Box::new(chosen))))
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
        strategy,
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
                lost: None,
            },
        );
    }
    let job = PushJob {
        run,
        particle,
        legs: plan.legs,
        slope: located.slope,
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
