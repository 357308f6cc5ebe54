//! `haptic`: z-control from the handle (`engage`, `release`, `recenter`) and its scales
//! (`scale`), checked against the link (`haptic::api`) and carried out by the control loop. A
//! `scale`'s `ok` carries the scales it puts in force; the server keeps them for `/api/status`.

use std::sync::Arc;
use std::sync::atomic::Ordering::Relaxed;

use nanopush_proto::ws::{ClientMessage, ErrorCode, HapticAction};

use super::instrument::to_loop;
use super::{Accepted, Client, misrouted};
use crate::app_state::AppState;
use crate::command_checks::Refusal;
use crate::control_loop::LoopCommand;
use crate::haptic::api::{haptic_command, scales_in_force};

/// The check of `haptic`'s fields: `nm_per_mm` and `pull_off_at_hand_n` belong to `scale` only
/// (else they would be dropped without a word).
pub(super) fn fields_apply(msg: &ClientMessage) -> Result<(), Refusal> {
    let ClientMessage::Haptic {
        action,
        nm_per_mm,
        pull_off_at_hand_n,
        ..
    } = msg
    else {
        return Err(misrouted(msg));
    };
    if *action == HapticAction::Scale {
        return Ok(());
    }
    let given = [
        ("nm_per_mm", nm_per_mm.is_some()),
        ("pull_off_at_hand_n", pull_off_at_hand_n.is_some()),
    ];
    match given.iter().find(|(_, g)| *g) {
        Some((field, _)) => {
            let name = serde_json::to_value(action)
                .ok()
                .and_then(|v| v.as_str().map(str::to_string))
                .unwrap_or_default();
            Err(Refusal::new(
                ErrorCode::Invalid,
                format!("{field} goes with action \"scale\" only; action \"{name}\" takes no other field"),
            ))
        }
        None => Ok(()),
    }
}

/// `haptic`, from the lease holder: the command for the loop; after a `scale`, the scales in
/// force (kept for `/api/status`, and said in the `ok`).
pub(super) fn run(st: &Arc<AppState>, _: &mut Client, msg: ClientMessage) -> Result<Accepted, Refusal> {
    let ClientMessage::Haptic {
        action,
        nm_per_mm,
        pull_off_at_hand_n,
        ..
    } = msg
    else {
        return Err(misrouted(&msg));
    };
    let h = &st.shared.metrics.haptic;
    let ts = st.scene.tip_sample();
    let cmd = haptic_command(
        h,
        st.shared.busy.load(Relaxed),
        ts.adhesion(),
        action,
        nm_per_mm,
        pull_off_at_hand_n,
    )?;
    to_loop(st, LoopCommand::Haptic(cmd))?;
    if action != HapticAction::Scale {
        return Ok(Accepted::PLAIN);
    }
    // Checked by `haptic_command`.
    if let Ok(mut s) = st.haptic_scales.lock() {
        s.nm_per_mm = nm_per_mm.unwrap_or(s.nm_per_mm);
        s.pull_off_at_hand_n = pull_off_at_hand_n.unwrap_or(s.pull_off_at_hand_n);
    }
    Ok(Accepted {
        scales: Some(scales_in_force(h, ts.k_c, ts.adhesion(), nm_per_mm, pull_off_at_hand_n)),
        silent: false,
    })
}
