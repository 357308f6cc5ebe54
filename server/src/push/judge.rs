//! A move judged by the instrument, as `nanopush push` judges it
//! ([`nanopush_instrument::control::moves::run`]): when the loop has run a push's legs (`pushed`), a local scan
//! around the controller's estimate finds the particle. Within the move's tolerance of the target
//! it is `ok`; outside it, a correction is pushed from where the scan found it, up to
//! [`DEFAULT_ATTEMPTS`] pushes in all; still outside, `missed`, with the distance. The estimate
//! never decides: a push can end with the estimate on the target and the particle off it (the
//! retraction's drag, a stick-slip push, a lagging stage).
//!
//! Off the loop and off the async workers (a blocking task), as the preparation is. The
//! instrument stays busy while the move is judged: no other push or scan starts in between. A
//! `stop` (or the lease holder leaving, or shutdown) while the scan runs ends the move
//! `stopped` instead of correcting it. Each push keeps its record; the verdict is written into
//! the summary of the push it judges (`records::amend`): `corrected` for a push a correction
//! followed, the move's verdict for the last.

use std::sync::Arc;
use std::sync::atomic::Ordering::Relaxed;

use nanopush_proto::ws::{Judged, ServerMessage};

use super::launch::{audit_early_end, launch, strategy_scene};
use crate::app_state::{AppState, Move, Pending};
use crate::records::{self, Recorded};
use nanopush_instrument::control::{DEFAULT_ATTEMPTS, MoveError, MoveRoute, MoveTarget, Verdict, route_move};
use nanopush_instrument::scene::Scene;

/// The loop ran run `run`'s legs (`pushed`) and left the particle believed at `estimate`:
/// judge the move on a blocking task. `record` is the push's record (or why none was written).
pub(crate) fn on_pushed(st: &Arc<AppState>, run: u64, particle: u32, estimate: [f64; 2], record: Recorded) {
    let pending = st.activity.judging.lock().ok().and_then(|mut j| j.remove(&run));
    let Some(pending) = pending else {
        // Every push the loop runs is launched with its move (`launch.rs`).
        tracing::error!("run {run}: no move to judge");
        let why = "internal error: the push's move was lost, so it was not judged".to_string();
        return end(st, run, particle, "error", Some(why), Some(estimate), record, None);
    };
    let st = st.clone();
    tokio::task::spawn_blocking(move || {
        let judged = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
            judge(&st, run, &pending, estimate, record.clone());
        }));
        if judged.is_err() {
            let why = "judging the push failed (internal error)".to_string();
            end(&st, run, particle, "error", Some(why), Some(estimate), record, None);
        }
    });
}

/// The scan after push `run`, and the verdict or the correction, with the particle's strategy.
fn judge(st: &AppState, run: u64, p: &Pending, estimate: [f64; 2], record: Recorded) {
    match strategy_scene(st, p.mv.particle, p.mv.tolerance) {
        Ok(scene) => judge_with(st, &scene, run, p, estimate, record),
        Err(refusal) => {
            let why = Some(refusal.to_string());
            end(st, run, p.mv.particle, "refused", why, Some(estimate), record, None);
        }
    }
}

/// [`judge`] with the strategy's scene `scene`.
fn judge_with(st: &AppState, scene: &Scene, run: u64, p: &Pending, estimate: [f64; 2], record: Recorded) {
    let id = p.mv.particle;
    let near = (estimate[0], estimate[1]);
    let plan = match route_move(scene, &st.surface_now(), near, p.radius, MoveTarget::Point(p.target)) {
        Ok(plan) => plan,
        Err(MoveError::NotFound { .. }) if let Some(lost) = &p.lost => {
            let why = format!("{lost}; the scan after push {} did not find particle {id}", p.attempt);
            return end(st, run, id, "particle_lost", Some(why), Some(estimate), record, None);
        }
        Err(MoveError::NotFound { .. }) => {
            let why = format!(
                "the scan after push {} did not find particle {id} near ({:.3}, {:.3}) µm, where the controller believed it",
                p.attempt,
                near.0 * 1e6,
                near.1 * 1e6
            );
            return end(st, run, id, "not_found", Some(why), Some(estimate), record, None);
        }
        Err(e) => {
            return end(
                st,
                run,
                id,
                "plan",
                Some(format!("particle {id}: {e}")),
                Some(estimate),
                record,
                None,
            );
        }
    };
    // The scan finds the blob nearest the estimate: it is this particle only if it has its size
    // (a push gone wrong can leave a neighbour nearer).
    let ratio = plan.located.radius / p.radius;
    if !(0.5..=2.0).contains(&ratio) {
        let why = format!(
            "the scan after push {} found a particle {:.1} nm in radius near ({:.3}, {:.3}) µm, not particle {id} ({:.1} nm)",
            p.attempt,
            plan.located.radius * 1e9,
            plan.located.x * 1e6,
            plan.located.y * 1e6,
            p.radius * 1e9
        );
        return end(st, run, id, "not_found", Some(why), Some(estimate), record, None);
    }
    let measured = [plan.located.x, plan.located.y];
    st.remember(id, measured);
    let verdict = Verdict::judge((measured[0], measured[1]), p.target, p.mv.tolerance);
    let judged = judged(&plan, p.target, p.mv.tolerance, p.attempt);
    let stopped = st.activity.generation.load(Relaxed) != p.mv.generation || st.activity.stopping.load(Relaxed);
    match verdict {
        Verdict::Ok { .. } => end(st, run, id, "ok", None, Some(measured), record, Some(judged)),
        Verdict::Missed { error } if stopped => {
            let why = format!(
                "stopped before a correction: the scan after push {} found particle {id} {} from the target",
                p.attempt,
                nm(error)
            );
            end(st, run, id, "stopped", Some(why), Some(measured), record, Some(judged));
        }
        Verdict::Missed { error } if p.attempt >= DEFAULT_ATTEMPTS || plan.legs.is_empty() => {
            let why = missed_words(id, error, p.mv.tolerance, p.attempt, plan.legs.is_empty());
            end(st, run, id, "missed", Some(why), Some(measured), record, Some(judged));
        }
        Verdict::Missed { error } if let Some(short) = p.prepared.short_of_drag(&plan.legs) => {
            // The stage's edge cut this push short of the retraction's drag, and would cut a
            // correction the same way.
            let why = format!(
                "{}: the push cannot go the {} further that the retraction's drag needs without carrying the particle off the stage",
                missed_words(id, error, p.mv.tolerance, p.attempt, false),
                nm(short)
            );
            end(st, run, id, "missed", Some(why), Some(measured), record, Some(judged));
        }
        Verdict::Missed { error } => {
            let why = format!(
                "the scan after found particle {id} {} from the target, beyond the {} tolerance: corrected by push {}",
                nm(error),
                nm(p.mv.tolerance),
                p.attempt + 1
            );
            // The record says `corrected` only once the correction has begun; one that cannot
            // begin (a stop since the scan, the tip unable to get behind) ends the move here.
            match launch(st, p.mv.clone(), scene, plan, p.attempt + 1) {
                Ok(()) => {
                    let (record, _) = amended(st, record, "corrected", Some(&why), Some(&judged));
                    st.audit.run_done(run, id, "corrected", Some(&why), record.as_deref());
                }
                Err((outcome, failure)) => {
                    let failure = format!(
                        "{failure}; the scan after push {} found particle {id} {} from the target",
                        p.attempt,
                        nm(error)
                    );
                    end(
                        st,
                        run,
                        id,
                        outcome,
                        Some(failure),
                        Some(measured),
                        record,
                        Some(judged),
                    );
                }
            }
        }
        // `judge` gives `Ok` or `Missed` only.
        Verdict::Failed { .. } | Verdict::NotFound => {}
    }
}

/// A move whose particle the first local scan found already within the planner's reach of the
/// target: judged there, without a push.
pub(crate) fn already_there(st: &AppState, mv: Move, plan: &MoveRoute) {
    let id = mv.particle;
    let measured = [plan.located.x, plan.located.y];
    st.remember(id, measured);
    let judged = judged(plan, plan.target, mv.tolerance, 0);
    let (outcome, why) = match Verdict::judge((measured[0], measured[1]), plan.target, mv.tolerance) {
        Verdict::Ok { error } => ("ok", format!("already {} from the target: nothing to push", nm(error))),
        _ => ("missed", missed_words(id, judged.error_m, mv.tolerance, 0, true)),
    };
    audit_early_end(st, &mv, id, outcome, Some(&why));
    st.push_ended(false);
    st.shared.busy.store(false, Relaxed);
    st.broadcast_event(&ServerMessage::RunDone {
        particle: id,
        outcome: outcome.into(),
        failure: (outcome != "ok").then_some(why),
        estimate: Some(measured),
        record: None,
        record_error: None,
        judged: Some(judged),
    });
}

/// What the scan found, for `run_done` and the record.
fn judged(plan: &MoveRoute, target: (f64, f64), tolerance: f64, attempts: u32) -> Judged {
    let (x, y) = (plan.located.x, plan.located.y);
    Judged {
        measured: [x, y],
        target: [target.0, target.1],
        error_m: (x - target.0).hypot(y - target.1),
        tolerance_m: tolerance,
        attempts,
    }
}

/// A distance in nm, in words.
fn nm(m: f64) -> String {
    format!("{:.1} nm", m * 1e9)
}

/// Why a move is `missed`, in words.
fn missed_words(id: u32, error: f64, tolerance: f64, pushes: u32, no_leg: bool) -> String {
    let after = if pushes == 0 {
        "the scan found".to_string()
    } else {
        format!(
            "after {pushes} push{} the scan found",
            if pushes == 1 { "" } else { "es" }
        )
    };
    let why = if no_leg {
        format!(
            ": closer than the {} a push can correct",
            nm(nanopush_instrument::control::moves::locate::DONE_WITHIN)
        )
    } else {
        String::new()
    };
    format!(
        "{after} particle {id} {} from the target, beyond the {} tolerance{why}",
        nm(error),
        nm(tolerance)
    )
}

/// The verdict written into the push's record (the loop wrote `pushed`): the record's name, and
/// why it is missing or could not take the verdict.
fn amended(
    st: &AppState,
    record: Recorded,
    outcome: &str,
    failure: Option<&str>,
    judged: Option<&Judged>,
) -> (Option<String>, Option<String>) {
    match record {
        Ok(name) => match records::amend(&st.cfg.data_dir, &name, outcome, failure, judged) {
            Ok(()) => (Some(name), None),
            Err(e) => {
                tracing::error!("records: {e}");
                st.shared.metrics.record_failures.fetch_add(1, Relaxed);
                (Some(name), Some(e))
            }
        },
        Err(why) => (None, Some(why)),
    }
}

/// The move ends with push `run`: the verdict into its record, the audit log, `run_done` to
/// everyone, and the instrument free.
#[allow(clippy::too_many_arguments)]
fn end(
    st: &AppState,
    run: u64,
    particle: u32,
    outcome: &str,
    failure: Option<String>,
    estimate: Option<[f64; 2]>,
    record: Recorded,
    judged: Option<Judged>,
) {
    let (record, record_error) = amended(st, record, outcome, failure.as_deref(), judged.as_ref());
    st.audit
        .run_done(run, particle, outcome, failure.as_deref(), record.as_deref());
    st.push_ended(true);
    st.shared.busy.store(false, Relaxed);
    st.broadcast_event(&ServerMessage::RunDone {
        particle,
        outcome: outcome.into(),
        failure,
        estimate,
        record,
        record_error,
        judged,
    });
}

#[cfg(test)]
mod tests {
    use std::sync::atomic::Ordering::Relaxed;

    use super::*;
    use crate::app_state::test_state;
    use crate::control_loop::LoopCommand;

    /// A test server whose particle 1 the loop left `off` (m, along x) from the target, which
    /// is 1 µm along +x from where the scene puts it; the move as `launch` registers it.
    fn left_off(off: f64, attempt: u32, tolerance: f64) -> (Arc<AppState>, Pending, [f64; 2]) {
        left_off_at(None, off, attempt, tolerance)
    }

    /// [`left_off`] with the target at `at` (m) instead.
    fn left_off_at(
        at: Option<(f64, f64)>,
        off: f64,
        attempt: u32,
        tolerance: f64,
    ) -> (Arc<AppState>, Pending, [f64; 2]) {
        let st = test_state();
        let part = st.scene.file.particles.iter().find(|p| p.id == 1).unwrap().clone();
        let target = at.unwrap_or((part.x_um * 1e-6 + 1e-6, part.y_um * 1e-6));
        {
            let mut snap = st.shared.snapshot.lock().unwrap();
            let p = snap.particles.iter_mut().find(|p| p.0 == 1).unwrap();
            (p.1, p.2) = (target.0 + off, target.1);
        }
        st.shared.busy.store(true, Relaxed);
        let mv = Move {
            particle: 1,
            tolerance,
            generation: st.activity.generation.load(Relaxed),
            by: 1,
            person: "alice".into(),
        };
        let scene = st.scene.clone();
        let params = scene.strategy_params(st.params.tick);
        let prepared = nanopush_instrument::control::Prepared::new(&scene, 1, part.radius_nm * 1e-9, &params).unwrap();
        let p = Pending {
            lost: None,
            mv,
            target,
            radius: part.radius_nm * 1e-9,
            attempt,
            prepared,
        };
        // The controller believes the particle is on the target.
        (st, p, [target.0, target.1])
    }

    fn run_done(rx: &mut tokio::sync::broadcast::Receiver<axum::extract::ws::Utf8Bytes>) -> serde_json::Value {
        while let Ok(m) = rx.try_recv() {
            let v: serde_json::Value = serde_json::from_str(m.as_str()).unwrap();
            if v["type"] == "run_done" {
                return v;
            }
        }
        panic!("no run_done")
    }

    /// A push the scan finds 30 nm off, at a 25 nm tolerance: a correction from where the scan
    /// found it, the instrument still busy, the first push's record saying `corrected`.
    #[test]
    fn a_push_outside_the_tolerance_is_corrected_from_where_it_was_found() {
        let (st, p, estimate) = left_off(30e-9, 1, 25e-9);
        let mut rx = st.channels.events.subscribe();
        let name = format!("push-judge-{}-r1-p1.json", std::process::id());
        let path = st.cfg.data_dir.join(&name);
        std::fs::write(&path, br#"{"run":1,"particle":1,"outcome":"pushed","truth":[0,0]}"#).unwrap();
        judge_with(&st, &st.scene.clone(), 1, &p, estimate, Ok(name.clone()));
        let Some(LoopCommand::Push(job)) = st.shared.commands.pop() else {
            panic!("a correction queued")
        };
        let from = job.legs[0].from;
        assert!(
            (from.0 - (p.target.0 + 30e-9)).abs() < 1e-9,
            "from where the scan found it: {from:?}"
        );
        assert!((job.legs.last().unwrap().to.0 - p.target.0).abs() < 1e-12);
        let started: serde_json::Value = serde_json::from_str(rx.try_recv().unwrap().as_str()).unwrap();
        assert_eq!(
            (started["type"].as_str(), started["attempt"].as_u64()),
            (Some("push_started"), Some(2))
        );
        assert!(st.shared.busy.load(Relaxed), "busy until the move is judged");
        let pending = st.activity.judging.lock().unwrap().get(&job.run).cloned().unwrap();
        assert_eq!((pending.attempt, pending.target), (2, p.target));
        let record: serde_json::Value = serde_json::from_slice(&std::fs::read(&path).unwrap()).unwrap();
        std::fs::remove_file(&path).unwrap();
        assert_eq!(record["outcome"], "corrected", "{record}");
        assert!(
            record["failure"].as_str().unwrap().contains("30.0 nm from the target"),
            "{record}"
        );
        assert_eq!(record["judged"]["attempts"], 1);
    }

    /// A correction that cannot begin (here the loop's queue is full; a stop does the same) ends
    /// the move with why, and the record of the push it would have corrected says so, never
    /// `corrected`.
    #[test]
    fn a_correction_that_cannot_begin_ends_the_move_and_its_record_says_why() {
        let (st, p, estimate) = left_off(30e-9, 1, 25e-9);
        while st
            .shared
            .commands
            .push(LoopCommand::Stop(crate::control_loop::StopReason::Operator))
            .is_ok()
        {}
        let mut rx = st.channels.events.subscribe();
        let name = format!("push-judge-full-{}-r1-p1.json", std::process::id());
        let path = st.cfg.data_dir.join(&name);
        std::fs::write(&path, br#"{"run":1,"particle":1,"outcome":"pushed"}"#).unwrap();
        judge_with(&st, &st.scene.clone(), 1, &p, estimate, Ok(name.clone()));
        let done = run_done(&mut rx);
        let record: serde_json::Value = serde_json::from_slice(&std::fs::read(&path).unwrap()).unwrap();
        std::fs::remove_file(&path).unwrap();
        assert_eq!(done["outcome"], "error", "{done}");
        let why = done["failure"].as_str().unwrap();
        assert!(
            why.contains("queue is full") && why.contains("30.0 nm from the target"),
            "{why}"
        );
        assert_eq!(record["outcome"], "error", "{record}");
        assert_eq!(done["record"], name.as_str());
        assert!(!st.shared.busy.load(Relaxed));
        assert!(st.activity.judging.lock().unwrap().is_empty(), "no move left pending");
    }

    /// The last push found outside the tolerance: `missed`, with the distance, and the
    /// instrument free. Within it: `ok` where the scan found it.
    #[test]
    fn the_last_push_outside_is_missed_and_one_inside_is_ok() {
        let (st, p, estimate) = left_off(30e-9, DEFAULT_ATTEMPTS, 25e-9);
        let mut rx = st.channels.events.subscribe();
        judge_with(&st, &st.scene.clone(), 3, &p, estimate, Err("no trace".into()));
        assert!(st.shared.commands.pop().is_none(), "no correction after the last push");
        let done = run_done(&mut rx);
        assert_eq!(done["outcome"], "missed", "{done}");
        let why = done["failure"].as_str().unwrap();
        assert!(
            why.contains(
                "after 3 pushes the scan found particle 1 30.0 nm from the target, beyond the 25.0 nm tolerance"
            ),
            "{why}"
        );
        assert!(
            (done["judged"]["error_m"].as_f64().unwrap() - 30e-9).abs() < 0.5e-9,
            "{done}"
        );
        assert!(!st.shared.busy.load(Relaxed));

        let (st, p, estimate) = left_off(20e-9, 1, 25e-9);
        let mut rx = st.channels.events.subscribe();
        judge_with(&st, &st.scene.clone(), 1, &p, estimate, Err("no trace".into()));
        let done = run_done(&mut rx);
        assert_eq!(done["outcome"], "ok", "{done}");
        assert!(done["failure"].is_null());
        let measured = done["estimate"][0].as_f64().unwrap();
        assert!(
            (measured - (p.target.0 + 20e-9)).abs() < 0.5e-9,
            "where the scan found it: {done}"
        );
        let believed = st.activity.estimates.lock().unwrap()[&1];
        assert_eq!(believed.0, measured, "the next push starts from the measured position");
        assert!(!st.shared.busy.load(Relaxed));
    }

    /// A target within the retraction's drag of the stage's edge: the push was cut short there
    /// (the drag then pulled the particle back 976 nm), and a correction would be cut the
    /// same way: `missed` at once, saying why.
    #[test]
    fn a_push_cut_short_by_the_stage_edge_is_missed_without_a_correction() {
        let (st, p, estimate) = left_off_at(Some((98.999e-6, 50e-6)), -976e-9, 1, 25e-9);
        let mut rx = st.channels.events.subscribe();
        judge_with(&st, &st.scene.clone(), 1, &p, estimate, Err("no trace".into()));
        assert!(st.shared.commands.pop().is_none(), "no correction");
        let done = run_done(&mut rx);
        assert_eq!(done["outcome"], "missed", "{done}");
        let why = done["failure"].as_str().unwrap();
        assert!(
            why.contains("after 1 push the scan found particle 1 976.0 nm from the target")
                && why.contains("the push cannot go the")
                && why.contains("without carrying the particle off the stage"),
            "{why}"
        );
    }

    /// A `stop` while the scan ran ends the move `stopped`; a particle the scan does not find is
    /// `not_found`, never `ok`.
    #[test]
    fn a_stop_ends_the_move_uncorrected_and_a_lost_particle_is_not_found() {
        let (st, p, estimate) = left_off(30e-9, 1, 25e-9);
        let mut rx = st.channels.events.subscribe();
        st.activity.generation.fetch_add(1, Relaxed);
        judge_with(&st, &st.scene.clone(), 1, &p, estimate, Err("no trace".into()));
        assert!(st.shared.commands.pop().is_none());
        let done = run_done(&mut rx);
        assert_eq!(done["outcome"], "stopped", "{done}");
        assert!(
            done["failure"].as_str().unwrap().contains("30.0 nm from the target"),
            "{done}"
        );

        let (st, p, estimate) = left_off(20e-6, 1, 25e-9);
        let mut rx = st.channels.events.subscribe();
        judge_with(&st, &st.scene.clone(), 1, &p, estimate, Err("no trace".into()));
        let done = run_done(&mut rx);
        assert_eq!(done["outcome"], "not_found", "{done}");
        assert!(
            done["failure"].as_str().unwrap().contains("did not find particle 1"),
            "{done}"
        );
        assert!(!st.shared.busy.load(Relaxed));
        // Another particle, a third the size, where this one was believed to be: not it.
        let (st, p, estimate) = left_off(20e-6, 1, 25e-9);
        st.shared
            .snapshot
            .lock()
            .unwrap()
            .particles
            .push((99, estimate[0] + 50e-9, estimate[1], 0.3e-6));
        let mut rx = st.channels.events.subscribe();
        judge_with(&st, &st.scene.clone(), 1, &p, estimate, Err("no trace".into()));
        let done = run_done(&mut rx);
        assert_eq!(done["outcome"], "not_found", "{done}");
        let why = done["failure"].as_str().unwrap();
        assert!(
            why.contains("found a particle 300") && why.contains("not particle 1 (1000.0 nm)"),
            "{why}"
        );
    }

    /// A push that read its particle as lost, judged by the scan after as a push that ran its
    /// legs: found 30 nm off, it is corrected (the instrument stays busy); not found, the move
    /// ends `particle_lost`, saying both.
    #[test]
    fn a_push_that_lost_its_particle_is_judged_by_the_scan_after_it() {
        let lost = "particle lost after 0.098 µm of push: the deflection fell back to the baseline";
        let (st, mut p, estimate) = left_off(30e-9, 1, 25e-9);
        p.lost = Some(lost.into());
        judge_with(&st, &st.scene.clone(), 1, &p, estimate, Err("no trace".into()));
        assert!(st.shared.commands.pop().is_some(), "a correction is queued");
        assert!(st.shared.busy.load(Relaxed));

        let (st, mut p, estimate) = left_off(20e-6, 1, 25e-9);
        p.lost = Some(lost.into());
        let mut rx = st.channels.events.subscribe();
        judge_with(&st, &st.scene.clone(), 1, &p, estimate, Err("no trace".into()));
        let done = run_done(&mut rx);
        assert_eq!(done["outcome"], "particle_lost", "{done}");
        let why = done["failure"].as_str().unwrap();
        assert!(
            why.starts_with(lost) && why.ends_with("the scan after push 1 did not find particle 1"),
            "{why}"
        );
        assert!(!st.shared.busy.load(Relaxed));
    }
}
