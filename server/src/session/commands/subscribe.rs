//! `subscribe`: the streams a client receives (`tip`, `scan`), and the per-stream counters that
//! keep the server from producing what nobody wants.

use std::collections::HashSet;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering::Relaxed};

use nanopush_proto::ws::{ClientMessage, Stream as WsStream};

use super::{Accepted, Client, misrouted};
use crate::app_state::AppState;
use crate::command_checks::Refusal;

/// `subscribe`: the client's streams become the ones asked for; the counters follow.
pub(super) fn run(st: &Arc<AppState>, c: &mut Client, msg: ClientMessage) -> Result<Accepted, Refusal> {
    let ClientMessage::Subscribe { streams, .. } = msg else {
        return Err(misrouted(&msg));
    };
    let new: HashSet<WsStream> = streams.into_iter().collect();
    for s in c.streams.difference(&new) {
        counter(st, *s).fetch_sub(1, Relaxed);
    }
    for s in new.difference(&c.streams) {
        counter(st, *s).fetch_add(1, Relaxed);
    }
    c.streams = new;
    Ok(Accepted::PLAIN)
}

/// The subscriber counter of stream `s`.
pub(in crate::session) fn counter(st: &AppState, s: WsStream) -> &AtomicU64 {
    match s {
        WsStream::Tip => &st.clients.tip_subscribers,
        WsStream::Scan => &st.clients.scan_subscribers,
    }
}
