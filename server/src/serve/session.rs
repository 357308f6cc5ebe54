//! One WebSocket connection: the receive loop (rate limit, size limit, one command per
//! message, roles and the lease) and the send loop (replies with back-pressure, events,
//! telemetry and scan lines, keep-alive, the per-frame send budget); the commands' handling.

use std::collections::HashSet;
use std::net::SocketAddr;
use std::sync::atomic::{AtomicU64, Ordering::Relaxed};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use axum::body::Bytes;
use axum::extract::ws::{CloseFrame, Message, Utf8Bytes, WebSocket};
use futures_util::{SinkExt, StreamExt};
use nanopush_proto::ws::{ClientMessage, ErrorCode, Role, ServerMessage, Stream as WsStream, WS_VERSION};
use tokio::sync::{broadcast, mpsc, watch};

use crate::control::MoveTarget;
use crate::scan::ScanParams;
use crate::serve::control_loop::LoopCommand;
use crate::serve::frames::{Frames, Next};
use crate::serve::haptic_api::haptic_command;
use crate::serve::state::{AppState, to_text};
use crate::serve::tasks::{on_stage, prepare_push, run_done_failed, run_scan};
use crate::serve::validate::{Refusal, number, parse_command, push_target};

/// Per-connection state for message handling.
struct Client {
    id: u32,
    role: Role,
    streams: HashSet<WsStream>,
    tokens: f64,
    last: Instant,
}

/// One WebSocket connection: a receive loop handling commands, and a send loop merging replies,
/// events, telemetry and scans (a slow client skips telemetry and is told how many frames).
pub(crate) async fn session(st: Arc<AppState>, socket: WebSocket, role: Role, peer: SocketAddr) {
    let id = st.next_client.fetch_add(1, Relaxed);
    tracing::info!("client {id} ({role:?}) connected from {peer}");
    let (mut sink, mut stream) = socket.split();
    let (reply_tx, mut reply_rx) = mpsc::channel::<Utf8Bytes>(64);
    let (streams_tx, mut streams_rx) = watch::channel(HashSet::<WsStream>::new());
    let welcome = ServerMessage::Welcome {
        version: WS_VERSION,
        client: id,
        role,
        lease: st.lease_holder(),
        scene: st.scene.file.name.clone(),
        tick_hz: 1.0 / st.params.tick,
    };
    let _ = reply_tx.try_send(to_text(&welcome));
    let _ = reply_tx.try_send(to_text(&st.state_message()));

    // When the peer last sent anything (a command, a pong): the sender's keep-alive closes a
    // connection whose peer stayed silent past the dead-peer time-out.
    let heard = Arc::new(Mutex::new(Instant::now()));
    let heard_by_sender = heard.clone();
    let send_state = st.clone();
    let mut send = tokio::spawn(async move {
        let st = send_state;
        let mut ping = tokio::time::interval(st.cfg.ws_ping);
        ping.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
        ping.tick().await;
        let mut events = st.events.subscribe();
        // Telemetry: the lease holder's frames come first, on a channel of its own read while
        // this client holds the lease (`frames.rs`).
        let mut telemetry = Frames::new(st.telemetry.subscribe());
        let mut scans = st.scans.subscribe();
        let mut shutdown = st.shutdown.subscribe();
        let mut wants = HashSet::new();
        loop {
            // Only an operator can hold the lease: a viewer's session never looks (500 of them
            // would each take the lease's lock for every message).
            if role == Role::Operator {
                telemetry.hold(st.lease_holder() == Some(id), &st.lease_telemetry);
            }
            let msg = tokio::select! {
                r = reply_rx.recv() => match r {
                    Some(m) => Message::Text(m),
                    None => break,
                },
                r = events.recv() => match r {
                    Ok(m) => Message::Text(m),
                    Err(broadcast::error::RecvError::Lagged(n)) => lagged(&st, n),
                    Err(broadcast::error::RecvError::Closed) => break,
                },
                r = telemetry.next(), if wants.contains(&WsStream::Tip) => match r {
                    Next::Frame(_, m) => {
                        st.net.sent.fetch_add(1, Relaxed);
                        Message::Text(m)
                    }
                    Next::Lagged(n) => lagged(&st, n),
                    Next::Closed => break,
                },
                r = scans.recv(), if wants.contains(&WsStream::Scan) => match r {
                    Ok(m) => m,
                    Err(broadcast::error::RecvError::Lagged(n)) => lagged(&st, n),
                    Err(broadcast::error::RecvError::Closed) => break,
                },
                r = streams_rx.changed() => {
                    if r.is_err() {
                        break;
                    }
                    wants = streams_rx.borrow_and_update().clone();
                    // Drop what queued before the subscription.
                    telemetry.renew();
                    scans = scans.resubscribe();
                    continue;
                }
                _ = ping.tick() => {
                    let silent = heard_by_sender.lock().map_or(Duration::ZERO, |t| t.elapsed());
                    if silent > st.cfg.ws_timeout {
                        tracing::info!("client {id}: nothing heard for {:.0} s; closing (a dead peer)", silent.as_secs_f64());
                        let _ = sink
                            .send(Message::Close(Some(CloseFrame { code: 1001, reason: "no answer to pings".into() })))
                            .await;
                        break;
                    }
                    Message::Ping(Bytes::from_static(b"nanopush"))
                }
                _ = shutdown.changed() => {
                    let bye = to_text(&ServerMessage::Shutdown { reason: "server shutting down".into() });
                    let _ = sink.send(Message::Text(bye)).await;
                    let _ = sink
                        .send(Message::Close(Some(CloseFrame { code: 1001, reason: "server shutting down".into() })))
                        .await;
                    break;
                }
            };
            // The send budget: a peer that takes more than this to take one frame (it stopped
            // reading and its socket is full) is dropped; the others never wait for it.
            match tokio::time::timeout(SEND_BUDGET, sink.send(msg)).await {
                Ok(Ok(())) => {}
                Ok(Err(_)) => break,
                Err(_) => {
                    tracing::info!(
                        "client {id}: a frame waited over {} s to be sent; closing (a reader that stopped reading)",
                        SEND_BUDGET.as_secs()
                    );
                    break;
                }
            }
        }
    });

    let mut client = Client {
        id,
        role,
        streams: HashSet::new(),
        tokens: st.cfg.max_rate,
        last: Instant::now(),
    };
    let mut recv_shutdown = st.shutdown.subscribe();
    let mut send_done = false;
    let mut shutting_down = false;
    loop {
        let next = tokio::select! {
            m = stream.next() => m,
            _ = recv_shutdown.changed() => {
                shutting_down = true;
                break;
            }
            _ = &mut send => {
                send_done = true;
                break;
            }
        };
        let Some(Ok(msg)) = next else { break };
        if let Ok(mut t) = heard.lock() {
            *t = Instant::now();
        }
        if matches!(msg, Message::Close(_)) {
            break;
        }
        if !matches!(msg, Message::Text(_) | Message::Binary(_)) {
            continue;
        }
        // Rate limit (every data frame counts): a token bucket of `max_rate` per second, burst
        // `max_rate`.
        let now = Instant::now();
        client.tokens =
            (client.tokens + now.duration_since(client.last).as_secs_f64() * st.cfg.max_rate).min(st.cfg.max_rate);
        client.last = now;
        if client.tokens < 1.0 {
            if !reply(
                &st,
                &reply_tx,
                None,
                ErrorCode::RateLimited,
                format!(
                    "more than {} messages per second; this one was dropped",
                    st.cfg.max_rate
                ),
            )
            .await
            {
                break;
            }
            continue;
        }
        client.tokens -= 1.0;
        let text = match msg {
            Message::Text(t) => t,
            Message::Binary(b) => {
                if !reply(
                    &st,
                    &reply_tx,
                    None,
                    ErrorCode::Malformed,
                    format!("binary frames ({} bytes) are not commands; send JSON text", b.len()),
                )
                .await
                {
                    break;
                }
                continue;
            }
            Message::Close(_) => break,
            _ => continue,
        };
        if text.len() > st.cfg.max_message_bytes {
            if !reply(
                &st,
                &reply_tx,
                None,
                ErrorCode::TooLarge,
                format!(
                    "message of {} bytes; allowed: at most {} bytes",
                    text.len(),
                    st.cfg.max_message_bytes
                ),
            )
            .await
            {
                break;
            }
            continue;
        }
        let parsed = match parse_command(text.as_str()) {
            Ok(m) => m,
            Err((id, why)) => {
                if !reply(&st, &reply_tx, id, ErrorCode::Malformed, why).await {
                    break;
                }
                continue;
            }
        };
        let cid = parsed.id();
        match handle(&st, &mut client, parsed) {
            Ok(()) => {
                if !deliver(&reply_tx, to_text(&ServerMessage::Ok { id: cid })).await {
                    break;
                }
                // Only a changed subscription wakes the sender (it resubscribes, dropping queued
                // frames of the streams it did not want).
                streams_tx.send_if_modified(|cur| {
                    let changed = *cur != client.streams;
                    if changed {
                        cur.clone_from(&client.streams);
                    }
                    changed
                });
            }
            Err(r) => {
                if !reply(&st, &reply_tx, cid, r.code, r.message).await {
                    break;
                }
            }
        }
    }
    // Disconnected: the lease goes with it, and so does what it commanded. Nobody watches a
    // push or scan whose operator is gone, so it is stopped (the tip retracts); the push ends
    // in a `run_done` with outcome `stopped`, recorded like any other.
    {
        let mut lease = st.lease.lock().expect("lease lock");
        if *lease == Some(id) {
            *lease = None;
            drop(lease);
            let pushing = st.shared.busy.load(Relaxed);
            let scanning = st.scanning.load(Relaxed);
            if pushing || scanning {
                st.scan_cancel.store(true, Relaxed);
                st.generation.fetch_add(1, Relaxed);
                if pushing && st.shared.commands.push(LoopCommand::Stop).is_err() {
                    st.shared.metrics.dropped_commands.fetch_add(1, Relaxed);
                }
            }
            let what = match (pushing, scanning) {
                (true, _) => "; its push was stopped",
                (_, true) => "; its scan was stopped",
                _ => "",
            };
            tracing::info!("client {id} held the lease and disconnected{what}");
            st.broadcast_event(&ServerMessage::Lease {
                holder: None,
                reason: Some(format!("client {id}, which held the lease, disconnected{what}")),
            });
        }
    }
    for s in &client.streams {
        counter(&st, *s).fetch_sub(1, Relaxed);
    }
    // On shutdown the send task says `shutdown` and closes before the reply queue goes (else it
    // could see the queue closed first and end silently); on a disconnect the closed queue is
    // what ends it. (A finished JoinHandle must not be polled again.)
    if shutting_down && !send_done {
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

fn lagged(st: &AppState, n: u64) -> Message {
    st.net.dropped_frames.fetch_add(n, Relaxed);
    Message::Text(to_text(&ServerMessage::Lagged { skipped: n }))
}

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

/// Queues a reply, waiting for room: a client that sends faster than it reads its replies is
/// slowed down (its messages wait in its own socket), never answered with silence. `false` when
/// the client has read nothing for [`REPLY_PATIENCE`] (or is gone): the session ends.
async fn deliver(tx: &mpsc::Sender<Utf8Bytes>, text: Utf8Bytes) -> bool {
    tx.send_timeout(text, REPLY_PATIENCE).await.is_ok()
}

async fn reply(st: &AppState, tx: &mpsc::Sender<Utf8Bytes>, id: Option<u32>, code: ErrorCode, message: String) -> bool {
    st.net.refused.fetch_add(1, Relaxed);
    deliver(tx, to_text(&ServerMessage::Error { id, code, message })).await
}

fn counter(st: &AppState, s: WsStream) -> &AtomicU64 {
    match s {
        WsStream::Tip => &st.tip_subscribers,
        WsStream::Scan => &st.scan_subscribers,
    }
}

fn require_lease(st: &AppState, c: &Client) -> Result<(), Refusal> {
    if c.role != Role::Operator {
        return Err(Refusal::new(
            ErrorCode::Forbidden,
            "viewers cannot command; connect with the operator token",
        ));
    }
    if st.lease_holder() != Some(c.id) {
        return Err(Refusal::new(
            ErrorCode::NoLease,
            "this command needs the control lease: send take_lease first",
        ));
    }
    if st.stopping.load(Relaxed) || *st.shutdown.borrow() {
        return Err(Refusal::new(ErrorCode::ShuttingDown, "the server is shutting down"));
    }
    Ok(())
}

fn busy(st: &AppState) -> Result<(), Refusal> {
    if st.shared.busy.load(Relaxed) {
        return Err(Refusal::new(ErrorCode::Busy, "a push is running; send stop first"));
    }
    if st.scanning.load(Relaxed) {
        return Err(Refusal::new(ErrorCode::Busy, "a scan is running; send stop first"));
    }
    Ok(())
}

/// Handles one valid-JSON command.
fn handle(st: &Arc<AppState>, c: &mut Client, msg: ClientMessage) -> Result<(), Refusal> {
    match msg {
        ClientMessage::Haptic {
            action,
            nm_per_mm,
            pull_off_at_hand_n,
            ..
        } => {
            require_lease(st, c)?;
            haptic_command(st, action, nm_per_mm, pull_off_at_hand_n)
        }
        ClientMessage::Ping { .. } => Ok(()),
        ClientMessage::Subscribe { streams, .. } => {
            let new: HashSet<WsStream> = streams.into_iter().collect();
            for s in c.streams.difference(&new) {
                counter(st, *s).fetch_sub(1, Relaxed);
            }
            for s in new.difference(&c.streams) {
                counter(st, *s).fetch_add(1, Relaxed);
            }
            c.streams = new;
            Ok(())
        }
        ClientMessage::TakeLease { .. } => {
            if c.role != Role::Operator {
                return Err(Refusal::new(
                    ErrorCode::Forbidden,
                    "viewers cannot take the lease; connect with the operator token",
                ));
            }
            let mut lease = st.lease.lock().expect("lease lock");
            match *lease {
                Some(h) if h == c.id => Ok(()),
                Some(h) => Err(Refusal::new(
                    ErrorCode::LeaseHeld,
                    format!("client {h} holds the lease"),
                )),
                None => {
                    *lease = Some(c.id);
                    drop(lease);
                    st.broadcast_event(&ServerMessage::Lease {
                        holder: Some(c.id),
                        reason: None,
                    });
                    Ok(())
                }
            }
        }
        ClientMessage::ReleaseLease { .. } => {
            let mut lease = st.lease.lock().expect("lease lock");
            if *lease != Some(c.id) {
                return Err(Refusal::new(ErrorCode::NoLease, "this client does not hold the lease"));
            }
            *lease = None;
            drop(lease);
            st.broadcast_event(&ServerMessage::Lease {
                holder: None,
                reason: None,
            });
            Ok(())
        }
        ClientMessage::Stop { .. } => {
            require_lease(st, c)?;
            st.scan_cancel.store(true, Relaxed);
            st.generation.fetch_add(1, Relaxed);
            if st.shared.commands.push(LoopCommand::Stop).is_err() {
                st.shared.metrics.dropped_commands.fetch_add(1, Relaxed);
                return Err(Refusal::new(
                    ErrorCode::Busy,
                    "the control loop's command queue is full; try again",
                ));
            }
            Ok(())
        }
        ClientMessage::Push {
            particle,
            distance_um,
            direction_deg,
            to_x_um,
            to_y_um,
            ..
        } => {
            require_lease(st, c)?;
            let f = &st.scene.file;
            let range = f.stage.range_um;
            let target = push_target(distance_um, direction_deg, to_x_um, to_y_um, range)?;
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
            let generation = st.generation.load(Relaxed);
            let by = c.id;
            tokio::task::spawn_blocking(move || {
                let prepared = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
                    prepare_push(&st2, particle, target, generation, by)
                }));
                if prepared.is_err() {
                    run_done_failed(
                        &st2,
                        particle,
                        "error",
                        "preparing the push failed (internal error)".into(),
                    );
                }
            });
            Ok(())
        }
        ClientMessage::Scan {
            centre_x_um,
            centre_y_um,
            size_um,
            pixels,
            ..
        } => {
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
            st.scanning.store(true, Relaxed);
            st.scan_cancel.store(false, Relaxed);
            let params = ScanParams {
                centre_x: cx,
                centre_y: cy,
                size,
                pixels: px,
                line_rate: st.cfg.scan_line_hz,
                ..base
            };
            let st2 = st.clone();
            std::thread::spawn(move || {
                if std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| run_scan(&st2, params))).is_err() {
                    tracing::error!("scan failed (internal error)");
                    st2.scanning.store(false, Relaxed);
                }
            });
            Ok(())
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::serve::state::OPERATOR_PLACES;

    /// README, "The teleoperation server": the operator token's 8 places, idle HTTP connections
    /// closed after 60 s, a 5 s send budget per frame, a client that reads no reply for 30 s
    /// closed, messages up to 8 MiB refused with `too_large` (above it the connection closes),
    /// SCHED_FIFO priority 50 for the loop. (The 8 places are also tested end to end:
    /// `tests/e2e/serve_hostile.rs::the_operator_token_has_8_places_and_a_ninth_is_refused`.)
    #[test]
    fn the_readmes_server_limits_8_places_60_s_idle_5_s_send_30_s_replies_8_mib_fifo_50() {
        assert_eq!(OPERATOR_PLACES, 8);
        assert_eq!(crate::serve::IDLE_HTTP, Duration::from_secs(60));
        assert_eq!(SEND_BUDGET, Duration::from_secs(5));
        assert_eq!(REPLY_PATIENCE, Duration::from_secs(30));
        assert_eq!(HARD_CAP, 8 * 1024 * 1024);
        assert_eq!(crate::serve::realtime::LOOP_PRIORITY, 50);
    }
}
