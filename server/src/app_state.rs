//! The server's shared state: its settings, the clients' places (viewers, operators, per
//! address), the lease, the broadcasts, and what a client that joins late is told.

use std::net::SocketAddr;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, AtomicU32, AtomicU64, Ordering::Relaxed};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use axum::extract::ws::{Message, Utf8Bytes};
use axum::http::StatusCode;
use nanopush_proto::ws::{AssemblyNow, ParticleNow, PushPath, Role, ScanNow, ServerMessage};
use tokio::sync::{broadcast, watch};

use crate::control_loop::Shared;
use crate::metrics::NetMetrics;
use nanopush_instrument::control::{Prepared, StrategyParams};
use nanopush_instrument::scan::{Sphere, Surface};
use nanopush_instrument::scene::Scene;

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
    /// Most TCP connections at once, before anything is read (None: what the open-files limit
    /// allows, `conn_limit::default_total`).
    pub max_connections: Option<u64>,
    /// Most TCP connections at once from one address (a trusted proxy excepted).
    pub max_connections_per_address: u64,
    /// A WebSocket ping every this long.
    pub ws_ping: Duration,
    /// A WebSocket peer silent for longer than this (no pong, nothing) is closed.
    pub ws_timeout: Duration,
    /// An HTTP request's headers must arrive within this long.
    pub header_timeout: Duration,
    /// Record directory.
    pub data_dir: PathBuf,
    /// The cap on the audit log's files in all (bytes; `audit.rs`).
    pub audit_max_bytes: u64,
    /// Static files of the web client.
    pub web_dir: PathBuf,
    /// The haptic link.
    pub haptic: crate::haptic::HapticMode,
    /// Scan line rate (Hz).
    pub scan_line_hz: f64,
    /// Telemetry rate to browsers (Hz).
    pub telemetry_hz: f64,
    /// Who may connect: the token file, the trusted proxies, TLS.
    pub access: AccessConfig,
    /// A real controller instead of the simulated AFM.
    pub instrument: Option<Arc<crate::instrument_loop::RealInstrument>>,
}

/// Access settings beyond the generated tokens.
#[derive(Debug, Clone, Default)]
pub struct AccessConfig {
    /// Named people with roles (`--token-file`); None: the generated operator token.
    pub token_file: Option<crate::auth::TokenFile>,
    /// Reverse proxies whose `X-Forwarded-For` is believed (`--trusted-proxy`).
    pub trusted_proxies: Vec<crate::client_addr::Cidr>,
    /// The server's own HTTPS (`--tls-cert`/`--tls-key`, `--tls-self-signed`); session cookies
    /// are then `Secure`.
    pub tls: Option<crate::tls::Tls>,
}

/// Everything the handlers share, grouped by job.
pub struct AppState {
    /// Settings.
    pub cfg: ServeConfig,
    /// The scene.
    pub scene: Scene,
    /// Strategy settings (for push preparation).
    pub params: StrategyParams,
    /// The loop's shared state.
    pub shared: Arc<Shared>,
    /// Network counters.
    pub net: NetMetrics,
    /// Bound address (for the Origin check).
    pub addr: Mutex<Option<SocketAddr>>,
    /// Who is connected, with which places, subscriptions and the lease.
    pub clients: Clients,
    /// What goes out to every client.
    pub channels: Channels,
    /// What the instrument is doing beside the loop: scans, push preparation, shutdown.
    pub activity: Activity,
    /// When this server started (Unix ms) and its instance id: a page that reconnects to a
    /// different instance knows the server restarted (and what it last saw is gone).
    pub instance: Instance,
    /// The haptic scales in force, in the protocol's units: the scene's, then each accepted
    /// `haptic scale` (`/api/status`'s `haptic_scales`).
    pub haptic_scales: Mutex<HapticScales>,
    /// Who is connecting: credentials, cookies, live sessions, failed attempts.
    pub auth: crate::auth::Auth,
    /// The audit log (off until the server opens it in its data directory).
    pub audit: crate::audit::Audit,
    /// The connection caps, counted before anything is read; the lease holder's address has
    /// room of its own.
    pub conn_limits: Arc<crate::conn_limit::ConnLimits>,
}

/// The haptic scales in force, as the operator sets them.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct HapticScales {
    /// Tip nanometres per handle millimetre.
    pub nm_per_mm: f64,
    /// The force the hand feels at the pull-off force (N).
    pub pull_off_at_hand_n: f64,
}

/// One run of the server: its start (Unix ms) and an id no other run shares (the start and the
/// process id, in hex).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Instance {
    /// This server's id.
    pub id: String,
    /// When it started (ms since the Unix epoch).
    pub started_unix_ms: u64,
}

impl Instance {
    /// This process, now.
    pub fn now() -> Instance {
        let started_unix_ms = crate::clock::unix_ms();
        Instance {
            id: format!("{started_unix_ms:x}-{:x}", std::process::id()),
            started_unix_ms,
        }
    }
}

/// The connected clients.
pub struct Clients {
    /// Lease holder.
    pub lease: Mutex<Option<u32>>,
    pub(crate) next_client: AtomicU32,
    /// Clients subscribed to `tip`.
    pub tip_subscribers: AtomicU64,
    /// Clients subscribed to `scan`.
    pub scan_subscribers: AtomicU64,
    /// Places taken: viewers (up to `--max-clients`) and operators (up to [`OPERATOR_PLACES`],
    /// apart, so viewers can never lock the operator out), and viewers per remote address.
    places: Mutex<Places>,
}

/// The broadcasts every session reads.
pub struct Channels {
    /// Telemetry, serialized once per frame, with the frame's number.
    pub telemetry: broadcast::Sender<(u64, Utf8Bytes)>,
    /// The same frames for the lease holder alone, sent before everyone else's
    /// ([`crate::telemetry::telemetry_task`]).
    pub lease_telemetry: broadcast::Sender<(u64, Utf8Bytes)>,
    /// Events for everyone (lease, run_done, shutdown).
    pub events: broadcast::Sender<Utf8Bytes>,
    /// Scan stream (text and binary frames).
    pub scans: broadcast::Sender<Message>,
    /// Shutdown signal for sessions and tasks.
    pub shutdown: watch::Sender<bool>,
}

/// The instrument's work beside the control loop.
pub struct Activity {
    /// A scan runs.
    pub scanning: AtomicBool,
    /// Ask a running scan to stop.
    pub scan_cancel: AtomicBool,
    pub(crate) next_scan: AtomicU32,
    /// Shutdown has begun: commands are refused from now on.
    pub stopping: AtomicBool,
    /// Bumped by every `stop`: a push still being prepared when it changes is dropped.
    pub generation: AtomicU64,
    /// Where the controller believes each particle is (m): the scene's positions, then each
    /// push's final estimate. A push starts its local scan here (the operator's "click").
    pub estimates: Mutex<std::collections::HashMap<u32, (f64, f64)>>,
    /// The push running now (its planned path), for clients that join during it.
    pub push_now: Mutex<Option<PushPath>>,
    /// The latest scan (running or finished), for clients that join after it.
    pub latest_scan: Mutex<Option<ScanNow>>,
    /// The running scan's lines so far, as sent on the `scan` stream (binary frames): a client
    /// that subscribes mid-scan gets them first, so it shows the whole scan so far and counts
    /// its lines as they are. Empty while no scan runs (a finished scan is its record).
    pub scan_lines: Mutex<Vec<axum::body::Bytes>>,
    /// Each particle's strategy plan (or why none can push it) for a tolerance (its bits),
    /// derived once from the scene's model on the first push that asks for it: the scene does
    /// not change while the server runs.
    pub plans: Mutex<std::collections::HashMap<(u32, u64), PlanOutcome>>,
    /// The pushes the loop runs whose move is judged by the scan after them, by run number.
    pub judging: Mutex<std::collections::HashMap<u64, Pending>>,
    /// An assembly runs (from its command's `ok` to its `assembly_done`): the instrument is
    /// busy all along, between its moves too.
    pub assembling: AtomicBool,
    /// The assembly running, as a client that joins during it is told.
    pub assembly_now: Mutex<Option<AssemblyNow>>,
    pub(crate) next_assembly: AtomicU64,
}

/// A move as the operator asked for it: the particle, the tolerance it must end within, the
/// `stop` generation it began in, and who asked.
#[derive(Debug, Clone, PartialEq)]
pub struct Move {
    /// Particle id.
    pub particle: u32,
    /// `ok` within this of the target, as the scan after the push measures it (m).
    pub tolerance: f64,
    /// [`Activity::generation`] when it was asked: a `stop` changes it.
    pub generation: u64,
    /// The client that asked.
    pub by: u32,
    /// Who that client is (the audit log's `person` for the move's pushes and its end, whenever
    /// they come: the client may be gone by then).
    pub person: Arc<str>,
}

/// A push the loop runs, whose move the scan after it judges (`push::judge`).
#[derive(Debug, Clone, PartialEq)]
pub struct Pending {
    /// The move it belongs to.
    pub mv: Move,
    /// The target (m).
    pub target: (f64, f64),
    /// The particle's radius in the scene (m): what the command's target was checked against,
    /// and the local scans' hint.
    pub radius: f64,
    /// Which push of the move this is (1, then the corrections).
    pub attempt: u32,
    /// Its model prediction and geometry.
    pub prepared: Prepared,
    /// Why the push read its particle as lost (`particle_lost`), when it did and the move had a
    /// push left to make: the scan after decides, and not finding the particle there ends the
    /// move `particle_lost` with this.
    pub lost: Option<String>,
}

/// A particle's strategy plan, or why none can push it.
pub type PlanOutcome =
    Result<nanopush_instrument::control::derive::DerivedStrategy, nanopush_instrument::control::derive::Refusal>;

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
pub(crate) struct Place {
    st: Arc<AppState>,
    role: Role,
    ip: std::net::IpAddr,
}

impl Place {
    /// Takes a place for `role` from `ip` (counted per address as the connection caps count it:
    /// an IPv6 client by its /64), or says why not.
    pub(crate) fn take(st: &Arc<AppState>, role: Role, ip: std::net::IpAddr) -> Result<Place, (StatusCode, String)> {
        let ip = crate::client_addr::limit_key(ip);
        let mut p = st.clients.places.lock().expect("places lock");
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
                            "{here} connections from {} already; allowed: {} per address (--max-clients-per-address)",
                            crate::client_addr::show_key(ip),
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
        let Ok(mut p) = self.st.clients.places.lock() else {
            return;
        };
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
            auth: crate::auth::Auth::new(
                cfg.operator_token.clone(),
                cfg.viewer_token.clone(),
                cfg.access.token_file.clone(),
            ),
            audit: crate::audit::Audit::off(),
            conn_limits: crate::conn_limit::ConnLimits::new(
                cfg.max_connections_per_address,
                cfg.max_connections.unwrap_or_else(|| {
                    crate::conn_limit::default_total(crate::conn_limit::open_files_limit().unwrap_or(1024))
                }),
                cfg.access.trusted_proxies.clone(),
            ),
            instance: Instance::now(),
            haptic_scales: Mutex::new(HapticScales {
                nm_per_mm: scene.file.haptic.nm_per_mm,
                pull_off_at_hand_n: scene.file.haptic.pull_off_at_hand_n,
            }),
            cfg,
            params,
            shared,
            net: NetMetrics::default(),
            addr: Mutex::new(None),
            clients: Clients {
                lease: Mutex::new(None),
                next_client: AtomicU32::new(1),
                tip_subscribers: AtomicU64::new(0),
                scan_subscribers: AtomicU64::new(0),
                places: Mutex::new(Places::default()),
            },
            channels: Channels {
                telemetry: broadcast::channel(64).0,
                lease_telemetry: broadcast::channel(64).0,
                events: broadcast::channel(256).0,
                scans: broadcast::channel(1024).0,
                shutdown: watch::channel(false).0,
            },
            activity: Activity {
                scanning: AtomicBool::new(false),
                scan_cancel: AtomicBool::new(false),
                next_scan: AtomicU32::new(1),
                plans: Mutex::new(std::collections::HashMap::new()),
                judging: Mutex::new(std::collections::HashMap::new()),
                assembling: AtomicBool::new(false),
                assembly_now: Mutex::new(None),
                next_assembly: AtomicU64::new(1),
                stopping: AtomicBool::new(false),
                generation: AtomicU64::new(0),
                estimates: Mutex::new(
                    scene
                        .file
                        .particles
                        .iter()
                        .map(|p| (p.id, (p.x_um * 1e-6, p.y_um * 1e-6)))
                        .collect(),
                ),
                push_now: Mutex::new(None),
                latest_scan: Mutex::new(None),
                scan_lines: Mutex::new(Vec::new()),
            },
            scene,
        }
    }

    /// Records where a particle is believed to be after a push.
    pub(crate) fn remember(&self, particle: u32, estimate: [f64; 2]) {
        if estimate.iter().all(|v| v.is_finite())
            && let Ok(mut e) = self.activity.estimates.lock()
        {
            e.insert(particle, (estimate[0], estimate[1]));
        }
    }

    pub(crate) fn broadcast_event(&self, m: &ServerMessage) {
        if let Ok(s) = serde_json::to_string(m) {
            let _ = self.channels.events.send(s.into());
        }
    }

    pub(crate) fn lease_holder(&self) -> Option<u32> {
        *self.clients.lease.lock().expect("lease lock")
    }

    /// The lease holder's name (their token's).
    pub(crate) fn lease_name(&self) -> Option<String> {
        self.lease_holder().and_then(|id| self.auth.name_of(id))
    }

    /// The phase now: the loop's, or, while it is idle, what runs beside it. The loop is idle
    /// while a push is prepared off it (a local scan, the plan: seconds on a crowded sample) and
    /// while a scan runs on its own thread: said as such.
    pub fn phase_now(&self) -> &'static str {
        let phase = self.shared.snapshot.lock().map(|s| s.phase).unwrap_or("idle");
        match phase {
            "idle" if self.activity.scanning.load(Relaxed) => "scanning",
            "idle" if self.activity.assembling.load(Relaxed) => "assembling",
            "idle" if self.shared.busy.load(Relaxed) => "preparing",
            other => other,
        }
    }

    /// The instrument behind the server, as the page is told of it.
    pub fn instrument_info(&self) -> nanopush_proto::ws::InstrumentInfo {
        match &self.cfg.instrument {
            Some(real) => real.info(),
            None => nanopush_proto::ws::InstrumentInfo {
                feed_rate_hz: 1.0 / self.params.tick,
                ..Default::default()
            },
        }
    }

    /// The instrument as it is now, for a client that has just connected: the particles where
    /// the controller believes they are, the tip, the phase, the lease, the push running and
    /// the latest scan.
    pub fn state_message(&self) -> ServerMessage {
        let estimates = self.activity.estimates.lock().map(|e| e.clone()).unwrap_or_default();
        let particles = self
            .scene
            .file
            .particles
            .iter()
            // A real controller's sample is not the scene's: no particle is known until it is
            // scanned.
            .filter(|_| self.cfg.instrument.is_none())
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
        let stage = self.shared.snapshot.lock().map(|s| s.stage).unwrap_or([0.0; 3]);
        let phase = self.phase_now();
        ServerMessage::State {
            particles,
            stage,
            phase: phase.into(),
            lease: self.lease_holder(),
            lease_name: self.lease_name(),
            push: self.activity.push_now.lock().ok().and_then(|p| p.clone()),
            scan: self.activity.latest_scan.lock().ok().and_then(|s| s.clone()),
            assembly: self.activity.assembly_now.lock().ok().and_then(|a| a.clone()),
        }
    }

    /// The sample as it is now (the loop's snapshot of the particles).
    pub(crate) fn surface_now(&self) -> Surface {
        let particles = self
            .shared
            .snapshot
            .lock()
            .map(|s| s.particles.clone())
            .unwrap_or_default();
        Surface {
            topography: self.scene.topography(),
            spheres: particles.iter().map(|&(_, x, y, r)| Sphere { x, y, r }).collect(),
        }
    }

    /// A push ended: it no longer runs, and if it moved anything the latest scan is stale.
    pub(crate) fn push_ended(&self, started: bool) {
        if let Ok(mut p) = self.activity.push_now.lock() {
            *p = None;
        }
        if started && let Ok(mut s) = self.activity.latest_scan.lock() {
            if let Some(s) = s.as_mut() {
                s.stale = true;
            }
        }
    }
}

/// A server message as the text frame every client is sent, serialized once.
pub(crate) fn to_text(m: &ServerMessage) -> Utf8Bytes {
    serde_json::to_string(m).unwrap_or_else(|_| "{}".into()).into()
}

/// A server's state on the default scene, with no loop running.
#[cfg(test)]
pub(crate) fn test_state() -> Arc<AppState> {
    let scene = Scene::default_scene();
    let tick = 1e-3;
    let base = nanopush_instrument::scan::ScanParams::from_scene(&scene);
    let afm = nanopush_instrument::afm::Afm::from_scene(&scene, base.centre_x, base.centre_y, tick);
    let shared = Arc::new(Shared::new(&afm));
    let cfg = ServeConfig {
        operator_token: "op".into(),
        viewer_token: None,
        allow_origins: Vec::new(),
        max_message_bytes: 64 * 1024,
        max_rate: 50.0,
        max_clients: 64,
        max_clients_per_address: 16,
        max_connections: None,
        max_connections_per_address: 128,
        ws_ping: Duration::from_secs(10),
        ws_timeout: Duration::from_secs(30),
        header_timeout: Duration::from_secs(10),
        data_dir: std::env::temp_dir(),
        audit_max_bytes: crate::audit::MAX_BYTES_DEFAULT,
        web_dir: std::env::temp_dir(),
        haptic: crate::haptic::HapticMode::None,
        scan_line_hz: 100.0,
        telemetry_hz: 60.0,
        access: Default::default(),
        instrument: None,
    };
    let params = scene.strategy_params(tick);
    Arc::new(AppState::new(cfg, scene, shared, params))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A viewer's places are counted per address as the connection caps count them: an IPv6
    /// client by its /64 (rotating its addresses gets it no more than one address's places), an
    /// IPv4-mapped one as its IPv4 address.
    #[test]
    fn viewer_places_count_an_ipv6_client_by_its_64() {
        let st = test_state();
        let ip = |s: String| s.parse::<std::net::IpAddr>().unwrap();
        let cap = st.cfg.max_clients_per_address;
        let held: Vec<Place> = (1..=cap)
            .map(|k| Place::take(&st, Role::Viewer, ip(format!("2001:db8:1:2::{k:x}"))).unwrap())
            .collect();
        let (code, why) = Place::take(&st, Role::Viewer, ip("2001:db8:1:2:ffff::1".into()))
            .err()
            .expect("one more address of the same /64 is refused");
        assert_eq!(code, StatusCode::TOO_MANY_REQUESTS);
        assert!(why.contains("2001:db8:1:2::/64"), "{why}");
        assert!(Place::take(&st, Role::Viewer, ip("2001:db8:1:3::1".into())).is_ok());
        drop(held);
        let v4: Vec<Place> = (0..cap)
            .map(|_| Place::take(&st, Role::Viewer, ip("10.0.0.1".into())).unwrap())
            .collect();
        assert!(Place::take(&st, Role::Viewer, ip("::ffff:10.0.0.1".into())).is_err());
        drop(v4);
        assert!(
            st.clients.places.lock().unwrap().per_address.is_empty(),
            "every place given back"
        );
    }
}
