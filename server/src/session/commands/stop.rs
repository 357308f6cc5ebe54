//! `stop`: what runs now is aborted: a scan is cancelled, a push still being prepared is
//! dropped, and the loop stops a running push (the tip retracts).

use std::sync::Arc;
use std::sync::atomic::Ordering::Relaxed;

use nanopush_proto::ws::ClientMessage;

use super::instrument::to_loop;
use super::{Accepted, Client};
use crate::app_state::AppState;
use crate::command_checks::Refusal;
use crate::control_loop::{LoopCommand, StopReason};

/// `stop`, from the lease holder.
pub(super) fn run(st: &Arc<AppState>, _: &mut Client, _: ClientMessage) -> Result<Accepted, Refusal> {
    st.activity.scan_cancel.store(true, Relaxed);
    if let Some(real) = &st.cfg.instrument {
        real.cancel.store(true, Relaxed);
    }
    st.activity.generation.fetch_add(1, Relaxed);
    to_loop(st, LoopCommand::Stop(StopReason::Operator))?;
    Ok(Accepted::PLAIN)
}
