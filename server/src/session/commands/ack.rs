//! `ack`: the newest telemetry frame the client has read, for the window of what is in flight to
//! it (`session/window.rs`). Not answered: an `ok` for every acknowledgement would be one more
//! message to read for each one; a refusal is answered as any other.

use std::sync::Arc;
use std::sync::atomic::Ordering::Relaxed;

use nanopush_proto::ws::{ClientMessage, ErrorCode};

use super::{Accepted, Client, misrouted};
use crate::app_state::AppState;
use crate::command_checks::Refusal;

/// `ack`, from anyone: `seq` must be a frame sent to this client.
pub(super) fn run(_: &Arc<AppState>, c: &mut Client, msg: ClientMessage) -> Result<Accepted, Refusal> {
    let ClientMessage::Ack { seq } = msg else {
        return Err(misrouted(&msg));
    };
    let newest = c.acks.newest_sent.load(Relaxed);
    if newest == 0 {
        return Err(Refusal::new(
            ErrorCode::OutOfRange,
            format!("ack seq = {seq}: no telemetry frame has been sent to this client yet (subscribe to \"tip\")"),
        ));
    }
    if seq == 0 || seq > newest {
        return Err(Refusal::new(
            ErrorCode::OutOfRange,
            format!("ack seq = {seq} is out of range; allowed: [1, {newest}] (the frames sent to this client)"),
        ));
    }
    c.acks.acked.fetch_max(seq, Relaxed);
    Ok(Accepted::SILENT)
}
