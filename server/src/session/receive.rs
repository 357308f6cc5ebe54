//! The receive loop of one session: each frame admitted (rate limit, binary frames, size
//! limit; an `ack`, read there, with a budget of its own), parsed as one command, run as its
//! entry in the table of commands says (`commands/mod.rs`), logged, and answered in order (`ok`
//! or a typed error; an `ack` only when refused).

use std::collections::HashSet;
use std::sync::Arc;
use std::time::Instant;

use axum::extract::ws::{Message, Utf8Bytes};
use futures_util::{Stream, StreamExt};
use nanopush_proto::ws::{ClientMessage, ErrorCode, ServerMessage, Stream as WsStream};
use tokio::sync::{mpsc, watch};
use tokio::task::JoinHandle;

use super::commands::route;
use super::{Client, REPLY_PATIENCE};
use crate::app_state::{AppState, ServeConfig, to_text};
use crate::command_checks::parse_command;

/// Why the receive loop ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Ended {
    /// The peer closed, failed, or read no reply for [`REPLY_PATIENCE`].
    Disconnected,
    /// The server is shutting down.
    ShuttingDown,
    /// The send loop ended first.
    SenderDone,
    /// The peer sent a message over [`super::HARD_CAP`]: the connection is closed with 1009.
    TooBig,
}

/// Whether `e`, a read error, is a message or frame over the size cap (tungstenite's
/// `Capacity` error, under axum's).
fn too_big(e: &(dyn std::error::Error + 'static)) -> bool {
    let mut cause = Some(e);
    while let Some(c) = cause {
        if let Some(tungstenite::Error::Capacity(_)) = c.downcast_ref::<tungstenite::Error>() {
            return true;
        }
        cause = c.source();
    }
    false
}

/// What becomes of one frame read.
#[derive(Debug, Clone, PartialEq)]
pub(super) enum Admit {
    /// A command's text, to parse.
    Command(Utf8Bytes),
    /// An `ack`, parsed already.
    Ack(ClientMessage),
    /// Nothing to answer (a ping or pong).
    Skip,
    /// The peer closes.
    Close,
    /// Refused with this error; the connection stays.
    Refuse(ErrorCode, String),
}

/// The acknowledgements a client may send a second (and in a burst): twice the telemetry rate,
/// so that one for every frame is always within it.
pub(super) fn ack_rate(cfg: &ServeConfig) -> f64 {
    2.0 * cfg.telemetry_hz
}

/// The longest `ack` (bytes): `{"type":"ack","seq":18446744073709551615}` and some spaces.
const ACK_MAX_BYTES: usize = 96;

/// `t` read as an `ack`, when it is one (a short text that names it).
fn as_ack(t: &str) -> Option<ClientMessage> {
    if t.len() > ACK_MAX_BYTES || !t.contains("\"ack\"") {
        return None;
    }
    parse_command(t).ok().filter(|m| matches!(m, ClientMessage::Ack { .. }))
}

/// Admits one frame at `now`: every data frame takes a token of the client's bucket
/// (`max_rate` per second, burst `max_rate`), an `ack` one of its own bucket ([`ack_rate`]);
/// binary frames are not commands; a text above `max_message_bytes` is refused.
pub(super) fn admit(cfg: &ServeConfig, c: &mut Client, msg: Message, now: Instant) -> Admit {
    let text = match msg {
        Message::Close(_) => return Admit::Close,
        Message::Text(t) => Ok(t),
        Message::Binary(b) => Err(b.len()),
        _ => return Admit::Skip,
    };
    if let Some(ack) = text.as_ref().ok().and_then(|t| as_ack(t)) {
        let rate = ack_rate(cfg);
        c.ack_tokens = (c.ack_tokens + now.duration_since(c.ack_last).as_secs_f64() * rate).min(rate);
        c.ack_last = now;
        if c.ack_tokens < 1.0 {
            return Admit::Refuse(
                ErrorCode::RateLimited,
                format!("more than {rate} acks per second (twice the telemetry rate); this one was dropped"),
            );
        }
        c.ack_tokens -= 1.0;
        return Admit::Ack(ack);
    }
    c.tokens = (c.tokens + now.duration_since(c.last).as_secs_f64() * cfg.max_rate).min(cfg.max_rate);
    c.last = now;
    if c.tokens < 1.0 {
        return Admit::Refuse(
            ErrorCode::RateLimited,
            format!("more than {} messages per second; this one was dropped", cfg.max_rate),
        );
    }
    c.tokens -= 1.0;
    match text {
        Err(len) => Admit::Refuse(
            ErrorCode::Malformed,
            format!("binary frames ({len} bytes) are not commands; send JSON text"),
        ),
        Ok(t) if t.len() > cfg.max_message_bytes => Admit::Refuse(
            ErrorCode::TooLarge,
            format!(
                "message of {} bytes; allowed: at most {} bytes",
                t.len(),
                cfg.max_message_bytes
            ),
        ),
        Ok(t) => Admit::Command(t),
    }
}

/// Where the receive loop answers and what it tells the send loop.
pub(super) struct Inbox<'a> {
    /// Replies, in order.
    pub replies: &'a mpsc::Sender<Utf8Bytes>,
    /// The client's subscriptions, for the send loop.
    pub streams: &'a watch::Sender<HashSet<WsStream>>,
    /// The newest ping the peer answered.
    pub answered: &'a super::keepalive::Answered,
}

/// Reads and handles commands until the peer goes, the server shuts down, or the send loop
/// (`send`) ends.
pub(super) async fn receive_loop<R, E>(
    st: &Arc<AppState>,
    mut stream: R,
    client: &mut Client,
    inbox: Inbox<'_>,
    send: &mut JoinHandle<()>,
) -> Ended
where
    R: Stream<Item = Result<Message, E>> + Unpin,
    E: std::error::Error + 'static,
{
    let mut shutdown = st.channels.shutdown.subscribe();
    loop {
        let next = tokio::select! {
            m = stream.next() => m,
            _ = shutdown.changed() => return Ended::ShuttingDown,
            _ = &mut *send => return Ended::SenderDone,
        };
        let msg = match next {
            Some(Ok(msg)) => msg,
            Some(Err(e)) if too_big(&e) => return Ended::TooBig,
            _ => return Ended::Disconnected,
        };
        if let Message::Pong(payload) = &msg {
            super::keepalive::pong(inbox.answered, payload);
        }
        let parsed = match admit(&st.cfg, client, msg, Instant::now()) {
            Admit::Command(t) => match parse_command(t.as_str()) {
                Ok(m) => m,
                Err((id, why)) => {
                    if !reply(st, inbox.replies, id, ErrorCode::Malformed, why).await {
                        return Ended::Disconnected;
                    }
                    continue;
                }
            },
            Admit::Ack(m) => m,
            Admit::Skip => continue,
            Admit::Close => return Ended::Disconnected,
            Admit::Refuse(code, why) => {
                if !reply(st, inbox.replies, None, code, why).await {
                    return Ended::Disconnected;
                }
                continue;
            }
        };
        if !answer(st, client, &inbox, parsed).await {
            return Ended::Disconnected;
        }
    }
}

/// Handles one command and queues its answer; `false` when the client is gone.
async fn answer(st: &Arc<AppState>, client: &mut Client, inbox: &Inbox<'_>, parsed: ClientMessage) -> bool {
    let cid = parsed.id();
    let command = route(&parsed);
    let audited = command.audit_text(&parsed);
    let handled = command.run(st, client, parsed);
    // Queued before the answer is sent, written within one group commit (`audit.rs`). The `ok`
    // does not wait for the disk: the command's events (a lease change, a run_done) must not
    // overtake its answer, and a stop must not wait for anything.
    if let Some(cmd) = audited {
        let refused = handled.as_ref().err().map(|r| (r.code, r.message.as_str()));
        let _ = st.audit.command(&client.person, client.addr, client.id, cmd, refused);
    }
    match handled {
        // Not answered (an `ack`), and changes no subscription.
        Ok(accepted) if accepted.silent => true,
        Ok(accepted) => {
            let ok = ServerMessage::Ok {
                id: cid,
                scales: accepted.scales,
            };
            if !deliver(inbox.replies, to_text(&ok)).await {
                return false;
            }
            // Only a changed subscription wakes the sender (it resubscribes, dropping queued
            // frames of the streams it did not want).
            inbox.streams.send_if_modified(|cur| {
                let changed = *cur != client.streams;
                if changed {
                    cur.clone_from(&client.streams);
                }
                changed
            });
            true
        }
        Err(r) => reply(st, inbox.replies, cid, r.code, r.message).await,
    }
}

/// Queues a reply, waiting for room: a client that sends faster than it reads its replies is
/// slowed down (its messages wait in its own socket), never answered with silence. `false` when
/// the client has read nothing for [`REPLY_PATIENCE`] (or is gone): the session ends.
pub(super) async fn deliver(tx: &mpsc::Sender<Utf8Bytes>, text: Utf8Bytes) -> bool {
    tx.send_timeout(text, REPLY_PATIENCE).await.is_ok()
}

async fn reply(st: &AppState, tx: &mpsc::Sender<Utf8Bytes>, id: Option<u32>, code: ErrorCode, message: String) -> bool {
    st.net.refused.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    deliver(tx, to_text(&ServerMessage::Error { id, code, message })).await
}

#[cfg(test)]
mod tests {
    use std::time::Duration;

    use axum::body::Bytes;
    use nanopush_proto::ws::Role;

    use super::*;
    use crate::app_state::test_state;
    use crate::session::tests::client;

    #[test]
    fn data_frames_spend_the_rate_budget_and_control_frames_do_not() {
        let st = test_state();
        let mut c = client(1, Role::Operator);
        let t0 = c.last;
        let rate = st.cfg.max_rate as usize;
        for _ in 0..rate {
            assert!(matches!(
                admit(&st.cfg, &mut c, Message::Text("{}".into()), t0),
                Admit::Command(_)
            ));
        }
        assert_eq!(admit(&st.cfg, &mut c, Message::Ping(Bytes::new()), t0), Admit::Skip);
        match admit(&st.cfg, &mut c, Message::Text("{}".into()), t0) {
            Admit::Refuse(ErrorCode::RateLimited, why) => assert!(why.contains("messages per second"), "{why}"),
            other => panic!("{other:?}"),
        }
        // One second later the bucket is full again.
        let later = t0 + Duration::from_secs(1);
        assert!(matches!(
            admit(&st.cfg, &mut c, Message::Text("{}".into()), later),
            Admit::Command(_)
        ));
    }

    /// Acknowledgements have a budget of their own, twice the telemetry rate: one for every
    /// frame spends nothing of the commands' budget.
    #[test]
    fn acks_spend_a_budget_of_their_own() {
        let st = test_state();
        let mut c = client(1, Role::Viewer);
        let t0 = c.last;
        for seq in 1..=120 {
            let ack = Message::Text(format!(r#"{{"type":"ack","seq":{seq}}}"#).into());
            assert_eq!(
                admit(&st.cfg, &mut c, ack, t0),
                Admit::Ack(ClientMessage::Ack { seq }),
                "read once, here"
            );
        }
        match admit(&st.cfg, &mut c, Message::Text(r#"{"type":"ack","seq":121}"#.into()), t0) {
            Admit::Refuse(ErrorCode::RateLimited, why) => assert!(why.contains("120 acks per second"), "{why}"),
            other => panic!("{other:?}"),
        }
        assert!(matches!(
            admit(&st.cfg, &mut c, Message::Text(r#"{"type":"ping"}"#.into()), t0),
            Admit::Command(_)
        ));
        assert_eq!(c.tokens, 49.0, "the commands' budget is untouched by acks");
    }

    #[test]
    fn binary_and_oversized_frames_are_refused_and_a_close_ends() {
        let st = test_state();
        let mut c = client(1, Role::Viewer);
        let now = c.last;
        assert_eq!(
            admit(&st.cfg, &mut c, Message::Binary(Bytes::from_static(b"abc")), now),
            Admit::Refuse(
                ErrorCode::Malformed,
                "binary frames (3 bytes) are not commands; send JSON text".into()
            )
        );
        let big = "x".repeat(st.cfg.max_message_bytes + 1);
        match admit(&st.cfg, &mut c, Message::Text(big.into()), now) {
            Admit::Refuse(ErrorCode::TooLarge, why) => {
                assert!(
                    why.contains(&format!("at most {} bytes", st.cfg.max_message_bytes)),
                    "{why}"
                )
            }
            other => panic!("{other:?}"),
        }
        assert_eq!(admit(&st.cfg, &mut c, Message::Close(None), now), Admit::Close);
    }
}
