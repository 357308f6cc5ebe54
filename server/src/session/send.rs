//! The send loop of one session: replies (with back-pressure), events, telemetry and scan lines
//! (on subscribing mid-scan, the lines so far first) merged onto the socket, numbered pings judged by their pongs (`keepalive.rs`: the dead-peer
//! time-out, and telemetry skipped for a client that has not read what was sent half a second
//! ago), the window of telemetry in flight to a client that acknowledges what it read
//! (`window.rs`), and the per-frame send budget. A slow client skips telemetry and is told how
//! many frames (`lagged`) before the next one it gets; one that acknowledges is not told (the
//! numbers passed over in `seq` are the frames skipped), so that its reading goes to frames.

use std::collections::HashSet;
use std::sync::Arc;
use std::sync::atomic::Ordering::Relaxed;
use std::time::Instant;

use axum::extract::ws::{CloseFrame, Message, Utf8Bytes};
use futures_util::{Sink, SinkExt};
use nanopush_proto::ws::{ErrorCode, Role, ServerMessage, Stream as WsStream};
use tokio::sync::{broadcast, mpsc, watch};

use super::SEND_BUDGET;
use super::keepalive::{Answered, KeepAlive, PROBE};
use super::window::{Acks, Window};
use crate::app_state::{AppState, to_text};
use crate::frames::{Frames, Next};

/// What the send loop reads besides the server's broadcasts.
pub(super) struct Outbox {
    /// The client's id.
    pub id: u32,
    /// Its role (only an operator can hold the lease).
    pub role: Role,
    /// Replies to its commands, in order.
    pub replies: mpsc::Receiver<Utf8Bytes>,
    /// The streams it subscribed to.
    pub streams: watch::Receiver<HashSet<WsStream>>,
    /// The newest ping the peer answered.
    pub answered: Answered,
    /// The close frame to end with once the replies are sent, when the receive side ended the
    /// session for a reason the peer must be told (a message too big: 1009).
    pub closing: Closing,
    /// Changes to the reason when the person's token is revoked: the session is closed.
    pub kicked: watch::Receiver<Option<String>>,
    /// What the client acknowledged reading (written by the receive loop), and the newest frame
    /// sent to it (written here).
    pub acks: Arc<Acks>,
}

/// A close code and reason, set once.
pub(super) type Closing = Arc<std::sync::OnceLock<(u16, &'static str)>>;

/// Sends until the replies close, the server shuts down (after saying so), the peer leaves a ping
/// unanswered past the dead-peer time-out, or a frame waits past [`SEND_BUDGET`].
pub(super) async fn send_loop<S>(st: Arc<AppState>, mut sink: S, mut out: Outbox)
where
    S: Sink<Message> + Unpin,
{
    let id = out.id;
    let mut ping = tokio::time::interval(st.cfg.ws_ping.min(PROBE));
    let mut keepalive = KeepAlive::new(out.answered.clone(), Instant::now());
    let mut window = Window::new();
    // Telemetry frames skipped since the last one sent (the client lagging).
    let mut skipped = 0u64;
    ping.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    ping.tick().await;
    let mut events = st.channels.events.subscribe();
    // Telemetry: the lease holder's frames come first, on a channel of its own read while
    // this client holds the lease (`frames.rs`).
    let mut telemetry = Frames::new(st.channels.telemetry.subscribe());
    let mut scans = st.channels.scans.subscribe();
    let mut shutdown = st.channels.shutdown.subscribe();
    let mut wants = HashSet::new();
    let mut kick_open = true;
    loop {
        // Only an operator can hold the lease: a viewer's session never looks (500 of them
        // would each take the lease's lock for every message).
        if out.role == Role::Operator {
            telemetry.hold(st.lease_holder() == Some(id), &st.channels.lease_telemetry);
        }
        let msg = tokio::select! {
            r = out.replies.recv() => match r {
                Some(m) => Message::Text(m),
                None => {
                    if let Some(&(code, reason)) = out.closing.get() {
                        let _ = send_within_budget(&mut sink, close(code, reason), id).await;
                    }
                    break;
                }
            },
            r = events.recv() => match r {
                Ok(m) => Message::Text(m),
                Err(broadcast::error::RecvError::Lagged(n)) => lagged(&st, n),
                Err(broadcast::error::RecvError::Closed) => break,
            },
            r = telemetry.next(), if wants.contains(&WsStream::Tip) => match r {
                Next::Frame(seq, m) => {
                    let now = Instant::now();
                    // Not queued to be read seconds late (the pongs say the socket is behind,
                    // or the client has not read what is in flight): skipped, the next sent is
                    // the newest.
                    if keepalive.behind(now) || !window.open(&out.acks, now) {
                        skipped += 1;
                        st.net.dropped_frames.fetch_add(1, Relaxed);
                        continue;
                    }
                    if skipped > 0 && !window.on(&out.acks) {
                        let told = Message::Text(to_text(&ServerMessage::Lagged { skipped }));
                        if !send_within_budget(&mut sink, told, id).await {
                            break;
                        }
                    }
                    skipped = 0;
                    window.sent(&out.acks, seq);
                    st.net.sent.fetch_add(1, Relaxed);
                    Message::Text(m)
                }
                Next::Lagged(n) if window.on(&out.acks) => {
                    st.net.dropped_frames.fetch_add(n, Relaxed);
                    continue;
                }
                Next::Lagged(n) => lagged(&st, n),
                Next::Closed => break,
            },
            r = scans.recv(), if wants.contains(&WsStream::Scan) => match r {
                Ok(m) => m,
                Err(broadcast::error::RecvError::Lagged(n)) => lagged(&st, n),
                Err(broadcast::error::RecvError::Closed) => break,
            },
            r = out.streams.changed() => {
                if r.is_err() {
                    break;
                }
                let had_scans = wants.contains(&WsStream::Scan);
                wants = out.streams.borrow_and_update().clone();
                // Drop what queued before the subscription.
                telemetry.renew();
                skipped = 0;
                scans = scans.resubscribe();
                // Subscribed mid-scan: the lines so far first (read after subscribing, so none
                // falls between; a line in both comes twice, and a client keeps one).
                if !had_scans && wants.contains(&WsStream::Scan) {
                    let so_far = st.activity.scan_lines.lock().map(|l| l.clone()).unwrap_or_default();
                    for frame in so_far {
                        if !send_within_budget(&mut sink, Message::Binary(frame), id).await {
                            return;
                        }
                    }
                }
                continue;
            }
            _ = ping.tick() => {
                let now = Instant::now();
                let silent = keepalive.unanswered_for(now);
                if silent > st.cfg.ws_timeout {
                    tracing::info!("client {id}: a ping unanswered for {:.1} s; closing (a dead peer)", silent.as_secs_f64());
                    let _ = sink.send(close(1001, "no answer to pings")).await;
                    break;
                }
                match keepalive.due(now, wants.contains(&WsStream::Tip), st.cfg.ws_ping) {
                    Some(payload) => Message::Ping(payload),
                    None => continue,
                }
            }
            r = out.kicked.changed(), if kick_open => {
                let Ok(()) = r else {
                    kick_open = false;
                    continue;
                };
                let why = out.kicked.borrow().clone().unwrap_or_default();
                let refused = to_text(&ServerMessage::Error { id: None, code: ErrorCode::Forbidden, message: why });
                let _ = sink.send(Message::Text(refused)).await;
                let _ = sink.send(close(1008, "access revoked")).await;
                break;
            }
            _ = shutdown.changed() => {
                let bye = to_text(&ServerMessage::Shutdown { reason: "server shutting down".into() });
                let _ = sink.send(Message::Text(bye)).await;
                let _ = sink.send(close(1001, "server shutting down")).await;
                break;
            }
        };
        if !send_within_budget(&mut sink, msg, id).await {
            break;
        }
    }
}

/// The send budget: a peer that takes more than [`SEND_BUDGET`] to take one frame (it stopped
/// reading and its socket is full) is dropped; the others never wait for it.
async fn send_within_budget<S: Sink<Message> + Unpin>(sink: &mut S, msg: Message, id: u32) -> bool {
    match tokio::time::timeout(SEND_BUDGET, sink.send(msg)).await {
        Ok(Ok(())) => true,
        Ok(Err(_)) => false,
        Err(_) => {
            tracing::info!(
                "client {id}: a frame waited over {} s to be sent; closing (a reader that stopped reading)",
                SEND_BUDGET.as_secs()
            );
            false
        }
    }
}

fn close(code: u16, reason: &'static str) -> Message {
    Message::Close(Some(CloseFrame {
        code,
        reason: reason.into(),
    }))
}

/// Frames skipped by a slow client, counted and announced.
fn lagged(st: &AppState, n: u64) -> Message {
    st.net.dropped_frames.fetch_add(n, Relaxed);
    Message::Text(to_text(&ServerMessage::Lagged { skipped: n }))
}
