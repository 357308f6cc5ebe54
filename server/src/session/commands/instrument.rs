//! What the handlers that command the instrument share: whether it is free, and a command
//! queued for the control loop.

use std::sync::atomic::Ordering::Relaxed;

use nanopush_proto::ws::ErrorCode;

use crate::app_state::AppState;
use crate::command_checks::Refusal;
use crate::control_loop::LoopCommand;

/// Refused `busy` while an assembly, a push or a scan runs.
pub(super) fn busy(st: &AppState) -> Result<(), Refusal> {
    if st.activity.assembling.load(Relaxed) {
        return Err(Refusal::new(ErrorCode::Busy, "an assembly is running; send stop first"));
    }
    if st.shared.busy.load(Relaxed) {
        return Err(Refusal::new(ErrorCode::Busy, "a push is running; send stop first"));
    }
    if st.activity.scanning.load(Relaxed) {
        return Err(Refusal::new(ErrorCode::Busy, "a scan is running; send stop first"));
    }
    Ok(())
}

/// Queues a command for the control loop; a full queue is refused as `busy`.
pub(super) fn to_loop(st: &AppState, cmd: LoopCommand) -> Result<(), Refusal> {
    st.shared
        .command(cmd)
        .map_err(|_| Refusal::new(ErrorCode::Busy, "the control loop's command queue is full; try again"))
}

/// Refused `unavailable` when the server drives a real controller: pushes, scans and assemblies
/// from the server run on the simulated AFM only (`what` names the command).
pub(super) fn simulated(st: &AppState, what: &str) -> Result<(), Refusal> {
    match &st.cfg.instrument {
        Some(real) => Err(Refusal::new(
            ErrorCode::Unavailable,
            format!(
                "{what} from the server is not offered on a real controller ({}) yet; use nanopush {what} --instrument",
                real.caps.backend
            ),
        )),
        None => Ok(()),
    }
}
