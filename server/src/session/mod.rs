//! One WebSocket connection: a receive loop (`receive.rs`: rate limit, size limit, one command
//! per message, run as its entry in the table of commands says, `commands/`; the lease lost
//! with the connection, `lease.rs`) and a send loop (`send.rs`: replies with back-pressure,
//! events, telemetry and scan lines, keep-alive, the per-frame send budget, and the window of
//! telemetry in flight to a client that acknowledges what it read, `window.rs`). Both are generic
//! over `Sink`/`Stream`, so a session runs over plain channels in the tests.

mod commands;
mod keepalive;
mod lease;
mod receive;
mod send;
#[cfg(test)]
pub(crate) mod tests;
mod window;

use std::collections::HashSet;
use std::net::SocketAddr;
use std::sync::Arc;
use std::sync::atomic::Ordering::Relaxed;
use std::time::{Duration, Instant};

use axum::extract::ws::{Message, Utf8Bytes, WebSocket};
use futures_util::{Sink, Stream, StreamExt};
use nanopush_proto::ws::{Bounds, Role, ServerMessage, Stream as WsStream, WS_VERSION};
use tokio::sync::{mpsc, watch};

use crate::app_state::{AppState, to_text};
use crate::audit::Happened;
use crate::auth::Person;
use receive::{Ended, Inbox};
use send::Outbox;

/// Longest a single frame may wait to be sent to a client before the client is dropped.
pub const SEND_BUDGET: Duration = Duration::from_secs(5);

/// The smallest scan side (µm): 10 nm.
pub const MIN_SCAN_UM: f64 = 0.01;

/// The largest WebSocket message a session reads (bytes): anything above `--max-message-bytes`
/// and up to this gets `too_large` and the connection stays; above it the connection is closed.
pub const HARD_CAP: usize = 8 << 20;

/// How long a reply may wait for room in a client's reply queue before the client, which has
/// read none of its replies for that long, is disconnected.
pub const REPLY_PATIENCE: Duration = Duration::from_secs(30);

/// Per-connection state for message handling.
pub(crate) struct Client {
    id: u32,
    role: Role,
    /// Who (the audit log's `person`) and from where (behind a trusted proxy, the client's
    /// address it forwarded).
    person: Arc<Person>,
    addr: std::net::IpAddr,
    streams: HashSet<WsStream>,
    /// The rate limit's token bucket.
    tokens: f64,
    /// When the bucket was last filled.
    last: Instant,
    /// The acknowledgements' own bucket (`ack` does not spend the commands' budget), and when
    /// it was last filled.
    ack_tokens: f64,
    ack_last: Instant,
    /// What it acknowledged reading, and the newest frame sent to it (shared with the sender).
    acks: Arc<window::Acks>,
}

/// One WebSocket connection of `person` from `peer`.
pub(crate) async fn session(st: Arc<AppState>, socket: WebSocket, person: Arc<Person>, peer: SocketAddr) {
    let (sink, stream) = socket.split();
    run(st, sink, stream, person, peer).await;
}

/// A session over any sink and stream of WebSocket messages: the welcome and the state first,
/// then the receive loop here and the send loop on a task of its own; when either ends, the
/// lease and the subscriptions are given back and the send loop is given 2 s to finish.
pub(crate) async fn run<S, R, E>(st: Arc<AppState>, sink: S, stream: R, person: Arc<Person>, peer: SocketAddr)
where
    S: Sink<Message> + Unpin + Send + 'static,
    R: Stream<Item = Result<Message, E>> + Unpin,
    E: std::error::Error + 'static,
{
    let id = st.clients.next_client.fetch_add(1, Relaxed);
    let role = person.role;
    tracing::info!("client {id} ({}, {role:?}) connected from {peer}", person.name);
    // Closed at once if the person's token is revoked.
    let kicked = st.auth.join(id, person.clone());
    let (reply_tx, replies) = mpsc::channel::<Utf8Bytes>(64);
    let (streams_tx, streams) = watch::channel(HashSet::<WsStream>::new());
    let welcome = ServerMessage::Welcome {
        version: WS_VERSION,
        client: id,
        role,
        lease: st.lease_holder(),
        lease_name: st.lease_name(),
        name: person.name.clone(),
        scene: st.scene.file.name.clone(),
        tick_hz: 1.0 / st.params.tick,
        instrument: st.instrument_info(),
        instance: st.instance.id.clone(),
        started_unix_ms: st.instance.started_unix_ms,
        push_tolerance_nm: Bounds::PUSH_TOLERANCE_NM,
    };
    let _ = reply_tx.try_send(to_text(&welcome));
    let _ = reply_tx.try_send(to_text(&st.state_message()));

    // The newest ping the peer answered (`keepalive.rs`): the sender closes a peer that left a
    // ping unanswered past the dead-peer time-out, and skips telemetry for one that lags.
    let answered = keepalive::Answered::default();
    let closing = send::Closing::default();
    let acks = Arc::new(window::Acks::default());
    let outbox = Outbox {
        id,
        role,
        replies,
        streams,
        answered: answered.clone(),
        closing: closing.clone(),
        kicked,
        acks: acks.clone(),
    };
    let mut send = tokio::spawn(send::send_loop(st.clone(), sink, outbox));
    let mut client = Client {
        id,
        role,
        person: person.clone(),
        addr: peer.ip(),
        streams: HashSet::new(),
        tokens: st.cfg.max_rate,
        last: Instant::now(),
        ack_tokens: receive::ack_rate(&st.cfg),
        ack_last: Instant::now(),
        acks,
    };
    let inbox = Inbox {
        replies: &reply_tx,
        streams: &streams_tx,
        answered: &answered,
    };
    let ended = receive::receive_loop(&st, stream, &mut client, inbox, &mut send).await;
    if st.lease_holder() == Some(id) {
        st.audit.event(Happened {
            person: &person.name,
            address: Some(peer.ip()),
            client: Some(id),
            command: "lease_lost",
            args: serde_json::Map::new(),
            outcome: "ok",
            message: Some("the lease holder's connection closed"),
        });
    }
    lease::on_disconnect(&st, id);
    st.auth.leave(id);
    for s in &client.streams {
        commands::counter(&st, *s).fetch_sub(1, Relaxed);
    }
    // A message too big: the send task ends with a 1009 close once the queue goes.
    if ended == Ended::TooBig {
        tracing::info!("client {id}: a message over {HARD_CAP} bytes; closing (1009)");
        let _ = closing.set((1009, "message over 8 MiB"));
    }
    // On shutdown the send task says `shutdown` and closes before the reply queue goes (else it
    // could see the queue closed first and end silently); on a disconnect the closed queue is
    // what ends it. (A finished JoinHandle must not be polled again.)
    let mut send_done = ended == Ended::SenderDone;
    if ended == Ended::ShuttingDown {
        if tokio::time::timeout(Duration::from_secs(2), &mut send).await.is_err() {
            send.abort();
        }
        send_done = true;
    }
    drop(reply_tx);
    if !send_done && tokio::time::timeout(Duration::from_secs(2), &mut send).await.is_err() {
        // A peer that stopped reading: do not leave its sender behind.
        send.abort();
    }
    tracing::info!("client {id} disconnected");
}
