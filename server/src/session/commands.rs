//! The commands of one session: each checked (role, lease, ranges) and then carried out, or
//! refused with a [`Refusal`] naming what was wrong and the allowed range.

use std::collections::HashSet;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering::Relaxed};

use nanopush_proto::ws::{ClientMessage, ErrorCode, HapticAction, Stream as WsStream};

use super::lease::{self, require_lease};
use super::{Client, MIN_SCAN_UM};
use crate::app_state::AppState;
use crate::command_checks::{Refusal, fields_apply, number, on_stage, push_target, push_tolerance};
use crate::control_loop::{LoopCommand, StopReason};
use crate::haptic::api::haptic_command;
use crate::app_state::Move;
use crate::push::launch::run_done_failed;
use crate::push::prepare::prepare_push;
use crate::scan_job::run_scan;
use nanopush_instrument::control::MoveTarget;
use nanopush_instrument::scan::ScanParams;

/// Handles one valid-JSON command.
pub(super) fn handle(st: &Arc<AppState>, c: &mut Client, msg: ClientMessage) -> Result<(), Refusal> {
    fields_apply(&msg)?;
    match msg {
        ClientMessage::Haptic {
            action,
            nm_per_mm,
            pull_off_at_hand_n,
            ..
        } => {
            require_lease(st, c)?;
            let cmd = haptic_command(
                &st.shared.metrics.haptic,
                st.shared.busy.load(Relaxed),
                st.scene.tip_sample().adhesion(),
                action,
                nm_per_mm,
                pull_off_at_hand_n,
            )?;
            to_loop(st, LoopCommand::Haptic(cmd))?;
            // Checked by `haptic_command`: the scales in force, for `/api/status`.
            if let (HapticAction::Scale, Ok(mut s)) = (action, st.haptic_scales.lock()) {
                s.nm_per_mm = nm_per_mm.unwrap_or(s.nm_per_mm);
                s.pull_off_at_hand_n = pull_off_at_hand_n.unwrap_or(s.pull_off_at_hand_n);
            }
            Ok(())
        }
        ClientMessage::Ping { .. } => Ok(()),
        ClientMessage::Subscribe { streams, .. } => {
            subscribe(st, c, streams.into_iter().collect());
            Ok(())
        }
        ClientMessage::TakeLease { .. } => lease::take(st, c),
        ClientMessage::ReleaseLease { .. } => lease::release(st, c),
        ClientMessage::Stop { .. } => {
            require_lease(st, c)?;
            st.activity.scan_cancel.store(true, Relaxed);
            st.activity.generation.fetch_add(1, Relaxed);
            to_loop(st, LoopCommand::Stop(StopReason::Operator))
        }
        ClientMessage::Push {
            particle,
            distance_um,
            direction_deg,
            to_x_um,
            to_y_um,
            tolerance_nm,
            ..
        } => push(
            st,
            c,
            particle,
            push_target(
                distance_um,
                direction_deg,
                to_x_um,
                to_y_um,
                st.scene.file.stage.range_um,
            ),
            tolerance_nm,
        ),
        ClientMessage::Scan {
            centre_x_um,
            centre_y_um,
            size_um,
            pixels,
            ..
        } => scan(st, c, centre_x_um, centre_y_um, size_um, pixels),
    }
}

/// `subscribe`: the client's streams become `new`; the per-stream counters follow.
fn subscribe(st: &AppState, c: &mut Client, new: HashSet<WsStream>) {
    for s in c.streams.difference(&new) {
        counter(st, *s).fetch_sub(1, Relaxed);
    }
    for s in new.difference(&c.streams) {
        counter(st, *s).fetch_add(1, Relaxed);
    }
    c.streams = new;
}

/// The subscriber counter of stream `s`.
pub(super) fn counter(st: &AppState, s: WsStream) -> &AtomicU64 {
    match s {
        WsStream::Tip => &st.clients.tip_subscribers,
        WsStream::Scan => &st.clients.scan_subscribers,
    }
}

fn busy(st: &AppState) -> Result<(), Refusal> {
    if st.shared.busy.load(Relaxed) {
        return Err(Refusal::new(ErrorCode::Busy, "a push is running; send stop first"));
    }
    if st.activity.scanning.load(Relaxed) {
        return Err(Refusal::new(ErrorCode::Busy, "a scan is running; send stop first"));
    }
    Ok(())
}

/// Queues a command for the control loop; a full queue is refused as `busy`.
fn to_loop(st: &AppState, cmd: LoopCommand) -> Result<(), Refusal> {
    st.shared
        .command(cmd)
        .map_err(|_| Refusal::new(ErrorCode::Busy, "the control loop's command queue is full; try again"))
}

/// `push`: checked here (lease first, then the target, the particle, the stage, a free
/// instrument), prepared off the async workers (local scan, model prediction, plan), then run
/// by the control loop.
fn push(
    st: &Arc<AppState>,
    c: &Client,
    particle: u32,
    target: Result<MoveTarget, Refusal>,
    tolerance_nm: Option<f64>,
) -> Result<(), Refusal> {
    require_lease(st, c)?;
    let f = &st.scene.file;
    let range = f.stage.range_um;
    let target = target?;
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
    let by = c.id;
    let mv = Move {
        particle,
        tolerance,
        generation: st.activity.generation.load(Relaxed),
        by,
    };
    tokio::task::spawn_blocking(move || {
        let prepared = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| prepare_push(&st2, mv, target)));
        if prepared.is_err() {
            run_done_failed(
                &st2,
                by,
                particle,
                "error",
                "preparing the push failed (internal error)".into(),
            );
        }
    });
    Ok(())
}

/// `scan`: the square checked in the protocol's units, then a scan on its own thread.
fn scan(
    st: &Arc<AppState>,
    c: &Client,
    centre_x_um: Option<f64>,
    centre_y_um: Option<f64>,
    size_um: Option<f64>,
    pixels: Option<u32>,
) -> Result<(), Refusal> {
    require_lease(st, c)?;
    let f = &st.scene.file;
    let range = f.stage.range_um;
    let base = ScanParams::from_scene(&st.scene);
    // Checked in the protocol's units (µm), converted once: a full-range square about the
    // default centre was refused by the rounding of a µm → m → µm round trip. The side
    // is at least 10 nm (below that a pixel is a fraction of an atom).
    let size_um = number(
        "size_um",
        size_um.unwrap_or(base.size * 1e6),
        MIN_SCAN_UM,
        range,
        false,
        "µm",
    )?;
    let cx_um = number(
        "centre_x_um",
        centre_x_um.unwrap_or(base.centre_x * 1e6),
        0.0,
        range,
        false,
        "µm",
    )?;
    let cy_um = number(
        "centre_y_um",
        centre_y_um.unwrap_or(base.centre_y * 1e6),
        0.0,
        range,
        false,
        "µm",
    )?;
    let px = number(
        "pixels",
        pixels.map_or(base.pixels.min(256) as f64, f64::from),
        8.0,
        512.0,
        false,
        "",
    )? as usize;
    let eps = 1e-9 * range;
    let half = size_um / 2.0;
    if cx_um - half < -eps || cy_um - half < -eps || cx_um + half > range + eps || cy_um + half > range + eps {
        return Err(Refusal::new(
            ErrorCode::OutOfRange,
            format!(
                "the scan square (centre ({cx_um}, {cy_um}) µm, side {size_um} µm) must lie within the stage, [0, {range}] µm"
            ),
        ));
    }
    let (size, cx, cy) = (size_um * 1e-6, cx_um * 1e-6, cy_um * 1e-6);
    busy(st)?;
    st.activity.scanning.store(true, Relaxed);
    st.activity.scan_cancel.store(false, Relaxed);
    let params = ScanParams {
        centre_x: cx,
        centre_y: cy,
        size,
        pixels: px,
        line_rate: st.cfg.scan_line_hz,
        ..base
    };
    let st2 = st.clone();
    let by = c.person.name.clone();
    std::thread::spawn(move || {
        if std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| run_scan(&st2, params, &by))).is_err() {
            tracing::error!("scan failed (internal error)");
            st2.activity.scanning.store(false, Relaxed);
        }
    });
    Ok(())
}
