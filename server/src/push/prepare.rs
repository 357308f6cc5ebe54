//! A push prepared off the loop and off the async workers: a quick local scan locates the
//! particle, the move is planned and the model predicts it; then the first push goes to the loop
//! ([`super::launch`]), or, with the particle already on the target, the move is judged where the
//! scan found it ([`super::judge`]).

use crate::app_state::{AppState, Move};
use crate::command_checks::on_stage;
use nanopush_instrument::control::{MoveTarget, route_move};

use super::judge;
use super::launch::{launch, run_done_failed, strategy_scene};

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
        Err(refusal) => return run_done_failed(st, &mv, particle, "refused", refusal.to_string()),
    };
    let plan = match route_move(&scene, &st.surface_now(), nominal, part.radius_nm * 1e-9, target) {
        Ok(p) => p,
        Err(e) => return run_done_failed(st, &mv, particle, "plan", format!("particle {particle}: {e}")),
    };
    // A target the particle cannot reach whole, with the tip behind it, fails now, not after a
    // push that runs into the stage's edge until its time-out.
    // Against the scene's radius, as the command's check stated the range (the located one
    // differs by a fraction of a nanometre: a target on the stated edge would be accepted, then
    // refused here with other bounds).
    if let Err(r) = on_stage(plan.target, part.radius_nm * 1e-9, f.stage.range_um * 1e-6) {
        return run_done_failed(st, &mv, particle, "plan", format!("particle {particle}: {}", r.message));
    }
    if plan.legs.is_empty() {
        // Already there (within the planner's 10 nm): judged where the scan found it, no push.
        return judge::already_there(st, mv, &plan);
    }
    if let Err((outcome, failure)) = launch(st, mv.clone(), &scene, plan, 1) {
        run_done_failed(st, &mv, particle, outcome, failure);
    }
}
