//! `push`: checked here (the target, the tolerance, the particle, the stage, a free instrument),
//! prepared off the async workers (local scan, model prediction, plan: `push::prepare`), then
//! run by the control loop.

use std::sync::Arc;
use std::sync::atomic::Ordering::Relaxed;

use nanopush_proto::ws::{ClientMessage, ErrorCode};

use super::instrument::busy;
use super::{Accepted, Client, misrouted};
use crate::app_state::{AppState, Move};
use crate::command_checks::{Refusal, on_stage, push_target, push_tolerance};
use crate::push::launch::run_done_failed;
use crate::push::prepare::prepare_push;
use nanopush_instrument::control::MoveTarget;

/// `push`: the move checked, then prepared on a blocking task; its end comes as `run_done`.
pub(super) fn run(st: &Arc<AppState>, c: &mut Client, msg: ClientMessage) -> Result<Accepted, Refusal> {
    super::instrument::simulated(st, "push")?;
    let ClientMessage::Push {
        particle,
        distance_um,
        direction_deg,
        to_x_um,
        to_y_um,
        tolerance_nm,
        ..
    } = msg
    else {
        return Err(misrouted(&msg));
    };
    let f = &st.scene.file;
    let range = f.stage.range_um;
    let target = push_target(distance_um, direction_deg, to_x_um, to_y_um, range)?;
    let tolerance = push_tolerance(tolerance_nm)?;
    let Some(part) = f.particles.iter().find(|p| p.id == particle) else {
        let ids: Vec<String> = f.particles.iter().map(|p| p.id.to_string()).collect();
        return Err(Refusal::new(
            ErrorCode::UnknownParticle,
            format!("particle = {particle}: no such particle; ids: {}", ids.join(", ")),
        ));
    };
    if let MoveTarget::Point(p) = target {
        on_stage(p, part.radius_nm * 1e-9, range * 1e-6)?;
    }
    busy(st)?;
    st.shared.busy.store(true, Relaxed);
    let st2 = st.clone();
    let mv = Move {
        particle,
        tolerance,
        generation: st.activity.generation.load(Relaxed),
        by: c.id,
        person: c.person.name.as_str().into(),
    };
    tokio::task::spawn_blocking(move || {
        let asked = mv.clone();
        let prepared = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| prepare_push(&st2, mv, target)));
        if prepared.is_err() {
            run_done_failed(
                &st2,
                &asked,
                particle,
                "error",
                "preparing the push failed (internal error)".into(),
            );
        }
    });
    Ok(Accepted::PLAIN)
}
