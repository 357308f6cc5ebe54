//! The network side: axum routes, the WebSocket sessions (roles, lease, limits, validation),
//! telemetry decimation, scans, and the graceful shutdown.

use std::collections::HashSet;
use std::net::SocketAddr;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, AtomicU32, AtomicU64, Ordering::Relaxed};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use axum::Router;
use axum::body::Bytes;
use axum::extract::ws::{CloseFrame, Message, Utf8Bytes, WebSocket, WebSocketUpgrade};
use axum::extract::{ConnectInfo, Path as UrlPath, Query, State};
use axum::http::{HeaderMap, StatusCode, header};
use axum::response::{IntoResponse, Response};
use axum::routing::get;
use futures_util::{SinkExt, StreamExt};
use nanopush_proto::ws::{
    ClientMessage, ErrorCode, ParticleNow, PushPath, Role, ScanLineHeader, ScanNow, ServerMessage, Stream as WsStream,
    Telemetry, WS_VERSION,
};
use tokio::sync::{broadcast, mpsc, watch};

use crate::control::{MoveTarget, Prepared, StrategyParams, plan_move};
use crate::scan::{ScanParams, Scanner, Sphere, Surface, Tip, find_particles, write_gsf};
use crate::scene::Scene;
use crate::serve::control_loop::{LoopCommand, LoopEvent, PushJob, Shared};
use crate::serve::haptic_api::{haptic_command, haptic_status, haptic_telemetry};
use crate::serve::metrics::{NetMetrics, render};
use crate::serve::records::{self, write_atomic};
use crate::serve::validate::{Refusal, number, parse_command, push_target};

/// Server settings.
#[derive(Debug, Clone)]
pub struct ServeConfig {
    /// Operator token.
    pub operator_token: String,
    /// Viewer token (None: viewers need none).
    pub viewer_token: Option<String>,
    /// Extra allowed browser origins.
    pub allow_origins: Vec<String>,
    /// Largest client message (bytes).
    pub max_message_bytes: usize,
    /// Messages per second per connection.
    pub max_rate: f64,
    /// Most viewer connections at once (operators have [`OPERATOR_PLACES`] of their own).
    pub max_clients: u64,
    /// Most viewer connections from one remote address.
    pub max_clients_per_address: u64,
    /// A WebSocket ping every this long.
    pub ws_ping: Duration,
    /// A WebSocket peer silent for longer than this (no pong, nothing) is closed.
    pub ws_timeout: Duration,
    /// An HTTP request's headers must arrive within this long.
    pub header_timeout: Duration,
    /// Record directory.
    pub data_dir: PathBuf,
    /// Static files of the web client.
    pub web_dir: PathBuf,
    /// The haptic link.
    pub haptic: crate::serve::haptic::HapticMode,
    /// Scan line rate (Hz).
    pub scan_line_hz: f64,
    /// Telemetry rate to browsers (Hz).
    pub telemetry_hz: f64,
}

/// Everything the handlers share.
pub struct AppState {
    /// Settings.
    pub cfg: ServeConfig,
    /// The scene.
    pub scene: Scene,
    /// The loop's shared state.
    pub shared: Arc<Shared>,
    /// Network counters.
    pub net: NetMetrics,
    /// Strategy settings (for push preparation).
    pub params: StrategyParams,
    /// Lease holder.
    pub lease: Mutex<Option<u32>>,
    next_client: AtomicU32,
    next_scan: AtomicU32,
    /// Clients subscribed to `tip`.
    pub tip_subscribers: AtomicU64,
    /// Clients subscribed to `scan`.
    pub scan_subscribers: AtomicU64,
    /// Telemetry, serialized once per frame.
    pub telemetry: broadcast::Sender<Utf8Bytes>,
    /// Events for everyone (lease, run_done, shutdown).
    pub events: broadcast::Sender<Utf8Bytes>,
    /// Scan stream (text and binary frames).
    pub scans: broadcast::Sender<Message>,
    /// A scan runs.
    pub scanning: AtomicBool,
    /// Ask a running scan to stop.
    pub scan_cancel: AtomicBool,
    /// Shutdown signal for sessions and tasks.
    pub shutdown: watch::Sender<bool>,
    /// Bound address (for the Origin check).
    pub addr: Mutex<Option<SocketAddr>>,
    /// Where the controller believes each particle is (m): the scene's positions, then each
    /// push's final estimate. A push starts its local scan here (the operator's "click").
    pub estimates: Mutex<std::collections::HashMap<u32, (f64, f64)>>,
    /// Shutdown has begun: commands are refused from now on.
    pub stopping: AtomicBool,
    /// Bumped by every `stop`: a push still being prepared when it changes is dropped.
    pub generation: AtomicU64,
    /// The push running now (its planned path), for clients that join during it.
    pub push_now: Mutex<Option<PushPath>>,
    /// The latest scan (running or finished), for clients that join after it.
    pub latest_scan: Mutex<Option<ScanNow>>,
    /// Places taken: viewers (up to `--max-clients`) and operators (up to [`OPERATOR_PLACES`],
    /// apart, so viewers can never lock the operator out), and viewers per remote address.
    places: Mutex<Places>,
}

/// Connections counted for admission.
#[derive(Debug, Default)]
struct Places {
    viewers: u64,
    operators: u64,
    per_address: std::collections::HashMap<std::net::IpAddr, u64>,
}

/// Connections kept for the operator token, beyond `--max-clients` (which counts viewers).
pub const OPERATOR_PLACES: u64 = 8;

/// A place taken at the upgrade, given back when the connection ends (or fails to upgrade).
struct Place {
    st: Arc<AppState>,
    role: Role,
    ip: std::net::IpAddr,
}

impl Place {
    /// Takes a place for `role` from `ip`, or says why not.
    fn take(st: &Arc<AppState>, role: Role, ip: std::net::IpAddr) -> Result<Place, (StatusCode, String)> {
        let mut p = st.places.lock().expect("places lock");
        match role {
            Role::Operator => {
                if p.operators >= OPERATOR_PLACES {
                    return Err((
                        StatusCode::SERVICE_UNAVAILABLE,
                        format!("{OPERATOR_PLACES} operator connections are open already"),
                    ));
                }
                p.operators += 1;
            }
            Role::Viewer => {
                let here = p.per_address.get(&ip).copied().unwrap_or(0);
                if here >= st.cfg.max_clients_per_address {
                    return Err((
                        StatusCode::TOO_MANY_REQUESTS,
                        format!(
                            "{here} connections from {ip} already; allowed: {} per address (--max-clients-per-address)",
                            st.cfg.max_clients_per_address
                        ),
                    ));
                }
                if p.viewers >= st.cfg.max_clients {
                    return Err((
                        StatusCode::SERVICE_UNAVAILABLE,
                        "too many clients (--max-clients)".into(),
                    ));
                }
                p.viewers += 1;
                *p.per_address.entry(ip).or_insert(0) += 1;
            }
        }
        st.net.clients.fetch_add(1, Relaxed);
        Ok(Place {
            st: st.clone(),
            role,
            ip,
        })
    }
}

impl Drop for Place {
    fn drop(&mut self) {
        let Ok(mut p) = self.st.places.lock() else { return };
        match self.role {
            Role::Operator => p.operators = p.operators.saturating_sub(1),
            Role::Viewer => {
                p.viewers = p.viewers.saturating_sub(1);
                if let Some(n) = p.per_address.get_mut(&self.ip) {
                    *n = n.saturating_sub(1);
                    if *n == 0 {
                        p.per_address.remove(&self.ip);
                    }
                }
            }
        }
        self.st.net.clients.fetch_sub(1, Relaxed);
    }
}

impl AppState {
    /// The state of a server.
    pub fn new(cfg: ServeConfig, scene: Scene, shared: Arc<Shared>, params: StrategyParams) -> AppState {
        AppState {
            cfg,
            shared,
            net: NetMetrics::default(),
            params,
            lease: Mutex::new(None),
            next_client: AtomicU32::new(1),
            next_scan: AtomicU32::new(1),
            tip_subscribers: AtomicU64::new(0),
            scan_subscribers: AtomicU64::new(0),
            telemetry: broadcast::channel(64).0,
            events: broadcast::channel(256).0,
            scans: broadcast::channel(1024).0,
            scanning: AtomicBool::new(false),
            scan_cancel: AtomicBool::new(false),
            shutdown: watch::channel(false).0,
            addr: Mutex::new(None),
            estimates: Mutex::new(
                scene
                    .file
                    .particles
                    .iter()
                    .map(|p| (p.id, (p.x_um * 1e-6, p.y_um * 1e-6)))
                    .collect(),
            ),
            stopping: AtomicBool::new(false),
            generation: AtomicU64::new(0),
            push_now: Mutex::new(None),
            latest_scan: Mutex::new(None),
            places: Mutex::new(Places::default()),
            scene,
        }
    }

    /// Records where a particle is believed to be after a push.
    fn remember(&self, particle: u32, estimate: [f64; 2]) {
        if estimate.iter().all(|v| v.is_finite())
            && let Ok(mut e) = self.estimates.lock()
        {
            e.insert(particle, (estimate[0], estimate[1]));
        }
    }

    fn broadcast_event(&self, m: &ServerMessage) {
        if let Ok(s) = serde_json::to_string(m) {
            let _ = self.events.send(s.into());
        }
    }

    fn lease_holder(&self) -> Option<u32> {
        *self.lease.lock().expect("lease lock")
    }

    /// The instrument as it is now, for a client that has just connected: the particles where
    /// the controller believes they are, the tip, the phase, the lease, the push running and
    /// the latest scan.
    pub fn state_message(&self) -> ServerMessage {
        let estimates = self.estimates.lock().map(|e| e.clone()).unwrap_or_default();
        let particles = self
            .scene
            .file
            .particles
            .iter()
            .map(|p| {
                let (x, y) = estimates.get(&p.id).copied().unwrap_or((p.x_um * 1e-6, p.y_um * 1e-6));
                ParticleNow {
                    id: p.id,
                    x,
                    y,
                    radius: p.radius_nm * 1e-9,
                }
            })
            .collect();
        let (stage, phase) = self
            .shared
            .snapshot
            .lock()
            .map(|s| (s.stage, s.phase))
            .unwrap_or(([0.0; 3], "idle"));
        let phase = if self.scanning.load(Relaxed) && phase == "idle" {
            "scanning"
        } else {
            phase
        };
        ServerMessage::State {
            particles,
            stage,
            phase: phase.into(),
            lease: self.lease_holder(),
            push: self.push_now.lock().ok().and_then(|p| p.clone()),
            scan: self.latest_scan.lock().ok().and_then(|s| s.clone()),
        }
    }

    /// A push ended: it no longer runs, and if it moved anything the latest scan is stale.
    fn push_ended(&self, started: bool) {
        if let Ok(mut p) = self.push_now.lock() {
            *p = None;
        }
        if started && let Ok(mut s) = self.latest_scan.lock() {
            if let Some(s) = s.as_mut() {
                s.stale = true;
            }
        }
    }
}

/// The router.
pub fn router(state: Arc<AppState>) -> Router {
    let packages = state.cfg.web_dir.join("node_modules");
    if !packages.join("three").is_dir() || !packages.join("uplot").is_dir() {
        tracing::warn!(
            "the web client's packages are missing ({} has no three/ or uplot/): the page cannot start; install them with `cd {} && npm ci` (or `make web`)",
            packages.display(),
            state.cfg.web_dir.display()
        );
    }
    let web = tower_http::services::ServeDir::new(&state.cfg.web_dir).append_index_html_on_directories(true);
    Router::new()
        .route("/ws", get(ws_upgrade))
        .route("/api/status", get(status))
        .route("/api/scene", get(scene_json))
        .route("/api/records", get(records_list))
        .route("/api/records/{name}", get(record_get))
        .route("/metrics", get(metrics))
        // Static files gzip-compressed when the browser accepts it (three.js's 1.3 MB module is
        // ~300 kB on the wire): a remote operator's page loads in seconds, not tens of seconds.
        .fallback_service(tower_http::compression::Compression::new(web))
        .layer(axum::middleware::from_fn_with_state(state.clone(), guard))
        .with_state(state)
}

/// Every request: when the server listens on loopback, the `Host` must name loopback (a page on
/// another site that rebinds its DNS name to 127.0.0.1 is refused); with `--viewer-token`, the
/// JSON API needs `?token=` (the viewer's or the operator's). `/metrics` stays open for a local
/// Prometheus, as is usual.
async fn guard(State(st): State<Arc<AppState>>, req: axum::extract::Request, next: axum::middleware::Next) -> Response {
    let addr = *st.addr.lock().expect("addr lock");
    if let Some(addr) = addr.filter(|a| a.ip().is_loopback()) {
        let host = req
            .headers()
            .get(header::HOST)
            .and_then(|h| h.to_str().ok())
            .unwrap_or("");
        let port = addr.port();
        let ok = [
            format!("127.0.0.1:{port}"),
            format!("localhost:{port}"),
            format!("[::1]:{port}"),
            addr.to_string(),
        ]
        .iter()
        .any(|h| h == host);
        if !ok {
            return (StatusCode::MISDIRECTED_REQUEST, "Host must name this loopback server").into_response();
        }
    }
    if let Some(viewer) = st.cfg.viewer_token.as_deref()
        && req.uri().path().starts_with("/api/")
    {
        // Decoded once, as the WebSocket route's query is (`%2B` is '+', '+' a space).
        let token = Query::<WsQuery>::try_from_uri(req.uri())
            .ok()
            .and_then(|q| q.0.token)
            .unwrap_or_default();
        if token != viewer && token != st.cfg.operator_token {
            return (StatusCode::UNAUTHORIZED, "this API needs ?token= (viewer or operator)").into_response();
        }
    }
    next.run(req).await
}

async fn status(State(st): State<Arc<AppState>>) -> Response {
    let snap = st.shared.snapshot.lock().map(|s| s.clone());
    let Ok(s) = snap else {
        return StatusCode::INTERNAL_SERVER_ERROR.into_response();
    };
    let m = &st.shared.metrics;
    let body = serde_json::json!({
        "scene": st.scene.file.name,
        "uptime_s": st.shared.start.elapsed().as_secs_f64(),
        "clients": st.net.clients.load(Relaxed),
        "lease": st.lease_holder(),
        "phase": s.phase,
        "stage": s.stage,
        "volts": s.volts,
        "busy": st.shared.busy.load(Relaxed) || st.scanning.load(Relaxed),
        "loop": {
            "ticks": m.ticks.load(Relaxed),
            "overruns": m.overruns.load(Relaxed),
            "realtime": m.realtime.load(Relaxed) == 1,
            "period_error_p50_bound_s": m.period_error.quantile_bound(0.5),
            "period_error_p99_bound_s": m.period_error.quantile_bound(0.99),
            "period_error_max_s": m.period_error.max(),
        },
        "telemetry_sent": st.net.sent.load(Relaxed),
        "dropped_frames": st.net.dropped_frames.load(Relaxed),
        "haptic": haptic_status(&m.haptic),
        // Where the controller believes each particle is (m), as the `state` message says.
        "particles": match st.state_message() {
            ServerMessage::State { particles, .. } => serde_json::to_value(particles).unwrap_or_default(),
            _ => serde_json::Value::Null,
        },
    });
    axum::Json(body).into_response()
}

async fn scene_json(State(st): State<Arc<AppState>>) -> Response {
    axum::Json(&st.scene.file).into_response()
}

async fn records_list(State(st): State<Arc<AppState>>) -> Response {
    match records::list(&st.cfg.data_dir) {
        Ok(l) => axum::Json(l).into_response(),
        Err(e) => (StatusCode::INTERNAL_SERVER_ERROR, format!("listing records: {e}")).into_response(),
    }
}

async fn record_get(State(st): State<Arc<AppState>>, UrlPath(name): UrlPath<String>) -> Response {
    if !records::valid_name(&name) {
        return (
            StatusCode::BAD_REQUEST,
            "a record name is letters, digits, '-', '_' and '.', with no path",
        )
            .into_response();
    }
    // A plain file in the data directory, never a symlink (to anywhere).
    let path = st.cfg.data_dir.join(&name);
    if !tokio::fs::symlink_metadata(&path)
        .await
        .is_ok_and(|m| m.file_type().is_file())
    {
        return (StatusCode::NOT_FOUND, format!("no record named {name}")).into_response();
    }
    match tokio::fs::read(&path).await {
        Ok(bytes) => {
            let ctype = match name.rsplit('.').next() {
                Some("json") => "application/json",
                Some("csv") => "text/csv",
                _ => "application/octet-stream",
            };
            (
                [
                    (header::CONTENT_TYPE, ctype.to_string()),
                    (header::CONTENT_DISPOSITION, format!("attachment; filename=\"{name}\"")),
                ],
                bytes,
            )
                .into_response()
        }
        Err(_) => (StatusCode::NOT_FOUND, format!("no record named {name}")).into_response(),
    }
}

async fn metrics(State(st): State<Arc<AppState>>) -> Response {
    (
        [(header::CONTENT_TYPE, "text/plain; version=0.0.4")],
        render(
            &st.shared.metrics,
            &st.net,
            nanopush_proto::haptic::monotonic_ns(),
            crate::serve::metrics::disk_space(&st.cfg.data_dir),
        ),
    )
        .into_response()
}

#[derive(Debug, serde::Deserialize)]
struct WsQuery {
    token: Option<String>,
}

/// Whether a browser origin may connect: the server's own addresses, or one allowed by flag.
fn origin_allowed(st: &AppState, origin: &str) -> bool {
    if st.cfg.allow_origins.iter().any(|o| o == origin) {
        return true;
    }
    let Some(addr) = *st.addr.lock().expect("addr lock") else {
        return false;
    };
    let port = addr.port();
    [
        format!("http://127.0.0.1:{port}"),
        format!("http://localhost:{port}"),
        format!("http://{addr}"),
    ]
    .iter()
    .any(|o| o == origin)
}

async fn ws_upgrade(
    State(st): State<Arc<AppState>>,
    ConnectInfo(peer): ConnectInfo<SocketAddr>,
    Query(q): Query<WsQuery>,
    headers: HeaderMap,
    ws: WebSocketUpgrade,
) -> Response {
    if *st.shutdown.borrow() {
        return (StatusCode::SERVICE_UNAVAILABLE, "shutting down").into_response();
    }
    if let Some(origin) = headers.get(header::ORIGIN) {
        let ok = origin.to_str().map(|o| origin_allowed(&st, o)).unwrap_or(false);
        if !ok {
            return (StatusCode::FORBIDDEN, "origin not allowed; see --allow-origin").into_response();
        }
    }
    let role = match q.token.as_deref() {
        Some(t) if t == st.cfg.operator_token => Role::Operator,
        Some(t) if st.cfg.viewer_token.as_deref() == Some(t) => Role::Viewer,
        None if st.cfg.viewer_token.is_none() => Role::Viewer,
        _ => return (StatusCode::UNAUTHORIZED, "invalid or missing token").into_response(),
    };
    // Counted here, under one lock, so simultaneous upgrades cannot pass the cap together; the
    // session (or a failed upgrade) gives the place back when it drops it.
    let place = match Place::take(&st, role, peer.ip()) {
        Ok(p) => std::sync::Arc::new(Mutex::new(Some(p))),
        Err((code, why)) => return (code, why).into_response(),
    };
    let failed = place.clone();
    // A hard cap far above the protocol's limit: larger messages are refused with a typed error
    // by the session (the connection stays); only absurd ones, over 8 MiB, close it (1009).
    let cap = HARD_CAP.max(st.cfg.max_message_bytes);
    ws.max_message_size(cap)
        .max_frame_size(cap)
        .on_failed_upgrade(move |_| {
            if let Ok(mut p) = failed.lock() {
                p.take();
            }
        })
        .on_upgrade(move |socket| async move {
            let held = place.lock().ok().and_then(|mut p| p.take());
            session(st, socket, role, peer).await;
            drop(held);
        })
}

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
async fn session(st: Arc<AppState>, socket: WebSocket, role: Role, peer: SocketAddr) {
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
        let mut telemetry = st.telemetry.subscribe();
        let mut scans = st.scans.subscribe();
        let mut shutdown = st.shutdown.subscribe();
        let mut wants = HashSet::new();
        loop {
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
                r = telemetry.recv(), if wants.contains(&WsStream::Tip) => match r {
                    Ok(m) => {
                        st.net.sent.fetch_add(1, Relaxed);
                        Message::Text(m)
                    }
                    Err(broadcast::error::RecvError::Lagged(n)) => lagged(&st, n),
                    Err(broadcast::error::RecvError::Closed) => break,
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
                    telemetry = telemetry.resubscribe();
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

fn to_text(m: &ServerMessage) -> Utf8Bytes {
    serde_json::to_string(m).unwrap_or_else(|_| "{}".into()).into()
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

/// The sample as it is now (the loop's snapshot of the particles).
fn surface_now(st: &AppState) -> Surface {
    let particles = st
        .shared
        .snapshot
        .lock()
        .map(|s| s.particles.clone())
        .unwrap_or_default();
    Surface {
        topography: st.scene.topography(),
        spheres: particles.iter().map(|&(_, x, y, r)| Sphere { x, y, r }).collect(),
    }
}

/// Whether a particle of radius `r` (m) can be pushed to `p` (m): its centre at least a radius
/// inside the stage's `[0, range]` square, so the particle stays on the stage and the tip, which
/// stays inside it, can reach behind it.
fn on_stage(p: (f64, f64), r: f64, range: f64) -> Result<(), Refusal> {
    let inside = |v: f64| v >= r && v <= range - r;
    if inside(p.0) && inside(p.1) {
        return Ok(());
    }
    Err(Refusal::new(
        ErrorCode::OutOfRange,
        format!(
            "target ({:.3}, {:.3}) µm is out of range for a particle {:.3} µm in radius; allowed: [{:.3}, {:.3}] µm in x and y",
            p.0 * 1e6,
            p.1 * 1e6,
            r * 1e6,
            r * 1e6,
            (range - r) * 1e6
        ),
    ))
}

fn run_done_failed(st: &AppState, particle: u32, outcome: &str, failure: String) {
    st.push_ended(false);
    st.shared.busy.store(false, Relaxed);
    st.broadcast_event(&ServerMessage::RunDone {
        particle,
        outcome: outcome.into(),
        failure: Some(failure),
        estimate: None,
        record: None,
        record_error: None,
    });
}

/// Off the loop: locate the particle in a quick local scan, plan, predict; then hand the job
/// to the loop.
fn prepare_push(st: &AppState, particle: u32, target: MoveTarget, generation: u64, by: u32) {
    let f = &st.scene.file;
    let Some(part) = f.particles.iter().find(|p| p.id == particle) else {
        return;
    };
    let nominal = st
        .estimates
        .lock()
        .ok()
        .and_then(|e| e.get(&particle).copied())
        .unwrap_or((part.x_um * 1e-6, part.y_um * 1e-6));
    let plan = match plan_move(&st.scene, &surface_now(st), nominal, part.radius_nm * 1e-9, target) {
        Ok(p) => p,
        Err(e) => return run_done_failed(st, particle, "plan", format!("particle {particle}: {e}")),
    };
    // A target the particle cannot reach whole, with the tip behind it, fails now, not after a
    // push that runs into the stage's edge until its time-out.
    if let Err(r) = on_stage(plan.target, plan.located.radius, f.stage.range_um * 1e-6) {
        return run_done_failed(st, particle, "plan", format!("particle {particle}: {}", r.message));
    }
    let (located, legs) = (plan.located, plan.legs);
    if legs.is_empty() {
        // Already there (within 10 nm): nothing to push.
        st.remember(particle, [located.x, located.y]);
        st.push_ended(false);
        st.shared.busy.store(false, Relaxed);
        st.broadcast_event(&ServerMessage::RunDone {
            particle,
            outcome: "ok".into(),
            failure: None,
            estimate: Some([located.x, located.y]),
            record: None,
            record_error: None,
        });
        return;
    }
    let prepared = match Prepared::new(&st.scene, particle, located.radius, &st.params) {
        Ok(p) => p,
        Err(e) => return run_done_failed(st, particle, "error", e.to_string()),
    };
    if st.generation.load(Relaxed) != generation || st.stopping.load(Relaxed) {
        return run_done_failed(st, particle, "stopped", "stopped before the push began".into());
    }
    let run = st.shared.runs.fetch_add(1, Relaxed) + 1;
    let mut path = vec![[located.x, located.y]];
    path.extend(legs.iter().map(|l| [l.to.0, l.to.1]));
    let started = PushPath { particle, path, by };
    let job = PushJob {
        run,
        particle,
        legs,
        prepared,
    };
    // Said after the job is queued: a `stop` sent on hearing `push_started` reaches the loop
    // after the push, and stops it.
    if let Ok(mut p) = st.push_now.lock() {
        *p = Some(started.clone());
    }
    if st.shared.commands.push(LoopCommand::Push(Box::new(job))).is_err() {
        st.shared.metrics.dropped_commands.fetch_add(1, Relaxed);
        run_done_failed(st, particle, "error", "the control loop's command queue is full".into());
        return;
    }
    st.broadcast_event(&ServerMessage::PushStarted(started));
}

/// A scan on its own thread: lines at the scan line rate to the `scan` stream, then the GSF
/// record. Tapping never moves particles: it images a snapshot of the sample.
fn run_scan(st: &AppState, params: ScanParams) {
    let scan_id = st.next_scan.fetch_add(1, Relaxed);
    let surface = surface_now(st);
    let tip = Tip::from_scene(&st.scene);
    let img0 = params.empty_image();
    let send_text = |m: &ServerMessage| {
        if st.scan_subscribers.load(Relaxed) > 0 {
            let _ = st.scans.send(Message::Text(to_text(m)));
        }
    };
    let previous = st.latest_scan.lock().ok().and_then(|s| s.clone());
    let now = ScanNow {
        scan: scan_id,
        xres: img0.xres as u32,
        yres: img0.yres as u32,
        x_offset: img0.x_offset,
        y_offset: img0.y_offset,
        x_real: img0.x_real,
        y_real: img0.y_real,
        done: false,
        record: None,
        stale: false,
    };
    if let Ok(mut s) = st.latest_scan.lock() {
        *s = Some(now.clone());
    }
    send_text(&ServerMessage::ScanStart {
        scan: scan_id,
        xres: img0.xres as u32,
        yres: img0.yres as u32,
        x_offset: img0.x_offset,
        y_offset: img0.y_offset,
        x_real: img0.x_real,
        y_real: img0.y_real,
    });
    let mut img = img0;
    let mut scanner = Scanner::new(&surface, tip, params);
    let line_period = Duration::from_secs_f64(1.0 / params.line_rate);
    let mut next = Instant::now();
    let mut cancelled = false;
    while let Some(line) = scanner.next_line() {
        img.data.extend_from_slice(&line.heights);
        if st.scan_cancel.load(Relaxed) || st.stopping.load(Relaxed) {
            cancelled = true;
            break;
        }
        if st.scan_subscribers.load(Relaxed) > 0 {
            let heights: Vec<f32> = line.heights.iter().map(|&h| h as f32).collect();
            let h = ScanLineHeader {
                scan: scan_id,
                line: line.index as u32,
                xres: heights.len() as u32,
                yres: params.pixels as u32,
                y: line.y,
            };
            let _ = st.scans.send(Message::Binary(Bytes::from(h.encode(&heights))));
        }
        next += line_period;
        let now = Instant::now();
        if next > now {
            std::thread::sleep(next - now);
        }
    }
    let (mut record, mut record_error) = (None, None);
    if !cancelled {
        let stem = format!("scan-{}-{scan_id}", records::unix_now());
        let mut gsf = Vec::new();
        let prepared = write_gsf(&mut gsf, &img, &stem)
            .map_err(|e| e.to_string())
            .and_then(|()| std::fs::create_dir_all(&st.cfg.data_dir).map_err(|e| e.to_string()))
            .map_err(|e| format!("preparing the record in {}: {e}", st.cfg.data_dir.display()));
        if let Err(e) = &prepared {
            tracing::error!("records: scan {scan_id}: {e}");
            st.shared.metrics.record_failures.fetch_add(1, Relaxed);
            record_error = Some(e.clone());
        }
        if prepared.is_ok() {
            let gsf_name = format!("{stem}.gsf");
            let summary = serde_json::json!({
                "schema": "scan-record",
                "scan": scan_id,
                "gsf": gsf_name,
                "xres": img.xres, "yres": img.yres,
                "x_offset": img.x_offset, "y_offset": img.y_offset,
                "x_real": img.x_real, "y_real": img.y_real,
                "z_range": img.z_range(),
                "particles": find_particles(&img, &tip).iter().map(|l| serde_json::json!({"x": l.x, "y": l.y, "radius": l.radius})).collect::<Vec<_>>(),
            });
            let json_name = format!("{stem}.json");
            let ok = write_atomic(&st.cfg.data_dir.join(&gsf_name), &gsf)
                .and_then(|()| write_atomic(&st.cfg.data_dir.join(&json_name), summary.to_string().as_bytes()));
            match ok {
                Ok(()) => record = Some(gsf_name),
                Err(e) => {
                    tracing::error!("records: scan {scan_id}: {e}");
                    st.shared.metrics.record_failures.fetch_add(1, Relaxed);
                    record_error = Some(format!("writing {stem} in {}: {e}", st.cfg.data_dir.display()));
                }
            }
        }
    }
    if let Ok(mut s) = st.latest_scan.lock() {
        // A cancelled scan is not the latest picture of the sample: the one before stays.
        *s = if cancelled {
            previous
        } else {
            Some(ScanNow {
                done: true,
                record: record.clone(),
                ..now
            })
        };
    }
    // Free before it is announced: a client that starts the next scan on hearing `scan_done`
    // must not be told the last one is still running.
    st.scanning.store(false, Relaxed);
    send_text(&ServerMessage::ScanDone {
        scan: scan_id,
        record,
        record_error,
    });
}

/// A record's name, or the reason it is missing, as the two fields of a message.
fn split(r: records::Recorded) -> (Option<String>, Option<String>) {
    match r {
        Ok(name) => (Some(name), None),
        Err(why) => (None, Some(why)),
    }
}

/// Telemetry at `telemetry_hz`, produced only while someone subscribes to `tip`; and loop
/// events forwarded to everyone.
pub async fn telemetry_task(st: Arc<AppState>, mut events: mpsc::UnboundedReceiver<(LoopEvent, records::Recorded)>) {
    let mut tick = tokio::time::interval(Duration::from_secs_f64(1.0 / st.cfg.telemetry_hz));
    tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Skip);
    let mut shutdown = st.shutdown.subscribe();
    loop {
        tokio::select! {
            _ = tick.tick() => {
                if st.tip_subscribers.load(Relaxed) == 0 {
                    continue;
                }
                let s = match st.shared.snapshot.lock() {
                    Ok(s) => Telemetry { t: s.t, stage: s.stage, volts: s.volts, phase: if st.scanning.load(Relaxed) && s.phase == "idle" { "scanning".into() } else { s.phase.into() }, estimate: s.estimate, tip_force_n: st.shared.metrics.haptic.tip_force_n(), haptic: haptic_telemetry(&st.shared.metrics.haptic) },
                    Err(_) => continue,
                };
                let _ = st.telemetry.send(to_text(&ServerMessage::Telemetry(s)));
            }
            e = events.recv() => {
                let Some((LoopEvent::RunDone { particle, outcome, failure, estimate, .. }, record)) = e else { break };
                st.remember(particle, estimate);
                st.push_ended(true);
                let (record, record_error) = split(record);
                st.broadcast_event(&ServerMessage::RunDone { particle, outcome: outcome.into(), failure, estimate: Some(estimate), record, record_error });
            }
            _ = shutdown.changed() => {
                // Forward what the recorder still finishes (the aborted run's record).
                while let Some((LoopEvent::RunDone { particle, outcome, failure, estimate, .. }, record)) = events.recv().await {
                    let (record, record_error) = split(record);
                    st.broadcast_event(&ServerMessage::RunDone { particle, outcome: outcome.into(), failure, estimate: Some(estimate), record, record_error });
                }
                break;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

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
        assert_eq!(crate::serve::control_loop::LOOP_PRIORITY, 50);
    }
}
