//! The server's life: bind, start the control loop (and wait for its haptic link), the
//! recorder and the haptic supervisor, serve HTTP and WebSockets, and shut down in order.

use std::net::SocketAddr;
use std::sync::Arc;
use std::sync::atomic::Ordering::Relaxed;
use std::time::{Duration, Instant};

use crate::app_state::{AppState, Instance, ServeConfig};
use crate::control_loop::{ControlLoop, LoopCommand, LoopConfig, Shared};
use crate::haptic::{HapticMode, Supervisor};
use crate::{app, audit, auth, guard, records, telemetry};
use nanopush_instrument::afm::Afm;
use nanopush_instrument::scene::Scene;

/// A plain HTTP connection idle this long is closed (WebSockets keep themselves alive with pings).
pub const IDLE_HTTP: Duration = Duration::from_secs(60);

/// Why the server could not run.
#[derive(Debug, thiserror::Error)]
pub enum ServeError {
    /// Binding or serving failed.
    #[error("{context}: {source}")]
    Io {
        /// What was being done.
        context: String,
        /// Cause.
        source: std::io::Error,
    },
    /// The haptic link could not be opened.
    #[error("{0}")]
    Haptic(String),
    /// The data directory is held by another server, or cannot be written.
    #[error(transparent)]
    DataDir(#[from] crate::data_dir::DataDirError),
}

/// A running server's address and the operator's URL.
#[derive(Debug, Clone)]
pub struct Started {
    /// Bound address.
    pub addr: SocketAddr,
    /// `http://ADDR/?token=TOKEN` (`https` with TLS).
    pub url: String,
}

/// Runs the server until `shutdown` resolves: the control loop thread, the recorder thread and
/// the HTTP/WebSocket side. `started` is called once the socket is bound. On shutdown the loop
/// stops any push and retracts the tip, the haptic force is released, records are finished and
/// flushed, then every client gets a `shutdown` message and its socket is closed.
pub async fn run(
    scene: Scene,
    cfg: ServeConfig,
    loop_cfg: LoopConfig,
    bind: SocketAddr,
    started: impl FnOnce(&Started),
    shutdown: impl std::future::Future<Output = ()> + Send + 'static,
) -> Result<(), ServeError> {
    // Bound first: a port in use must stop the start before the loop takes its core.
    let (listener, addr) = bind_to(bind).await?;
    raise_open_files();
    // Held for the whole run (`data_dir.rs`): no second server writes here, and records can be.
    let _held = crate::data_dir::hold(&cfg.data_dir)?;
    // Its holder's to clean, before anything is recorded: a dead server's unfinished records.
    let cleaned = records::clean_partials(&cfg.data_dir);
    if cleaned > 0 {
        tracing::warn!(
            "records: removed {cleaned} unfinished .partial file(s) left in {} by an earlier run",
            cfg.data_dir.display()
        );
    }
    let tick = 1.0 / loop_cfg.rate_hz;
    let params = scene.strategy_params(tick);
    let (shared, loop_thread) = start_loop(&scene, loop_cfg, cfg.instrument.as_deref())?;
    let (ev_tx, ev_rx) = tokio::sync::mpsc::unbounded_channel();
    let rec_shared = shared.clone();
    let dir = cfg.data_dir.clone();
    // This run of the server, named in its records' summaries and in `welcome`.
    let instance = Instance::now();
    let rec_instance = instance.id.clone();
    // Who ran each push: the audit log's and the records'.
    let people = audit::RunPeople::default();
    let rec_people = people.clone();
    let recorder = match std::thread::Builder::new()
        .name("recorder".into())
        .spawn(move || records::run_recorder(rec_shared, dir, rec_instance, rec_people, ev_tx))
    {
        Ok(r) => r,
        Err(source) => {
            // The loop ends as at shutdown (the tip parked, its core given back).
            let _ = shared.commands.push(LoopCommand::Shutdown);
            let _ = loop_thread.join();
            return Err(ServeError::Io {
                context: "starting the recorder thread".into(),
                source,
            });
        }
    };
    let supervisor = match &cfg.haptic {
        HapticMode::Sim(bin) => Some(Supervisor::start(Some(bin.clone()), shared.clone())),
        HapticMode::External => Some(Supervisor::start(None, shared.clone())),
        HapticMode::None => None,
    };
    let mut state = AppState::new(cfg, scene, shared, params);
    state.instance = instance;
    state.audit = audit::Audit::open(&state.cfg.data_dir, people, state.cfg.audit_max_bytes);
    let auth_dir = state.cfg.data_dir.join("auth");
    if let Err(e) = state.auth.keep_cookies_in(&auth_dir) {
        tracing::error!(
            "cannot keep the session cookies' key in {}: {e}; pages sign in again after a restart",
            auth_dir.display()
        );
    }
    let state = Arc::new(state);
    *state.addr.lock().expect("addr lock") = Some(addr);
    if let Some(nofile) = crate::conn_limit::open_files_limit()
        && state.conn_limits.total() + crate::conn_limit::FILES_RESERVED > nofile
    {
        tracing::warn!(
            "--max-connections {} leaves less than {} of the open-files limit ({nofile}) to the server's own files: a flood of connections could leave it none (raise LimitNOFILE, or lower --max-connections)",
            state.conn_limits.total(),
            crate::conn_limit::FILES_RESERVED
        );
    }
    // With a token file each person opens the page with their own token.
    let scheme = if state.cfg.access.tls.is_some() {
        "https"
    } else {
        "http"
    };
    let url = if state.auth.is_named() {
        format!("{scheme}://{addr}/ (each person adds ?token=THEIR_TOKEN)")
    } else {
        format!("{scheme}://{addr}/?token={}", state.cfg.operator_token)
    };
    started(&Started { addr, url });
    let telemetry = tokio::spawn(telemetry::telemetry_task(state.clone(), ev_rx));
    tokio::spawn(watch_token_file(state.clone()));
    let threads = Threads {
        recorder,
        control_loop: loop_thread,
        supervisor,
    };
    let graceful = graceful_shutdown(state.clone(), shutdown, threads);
    let served = serve_http(listener, state, graceful).await;
    let _ = tokio::time::timeout(Duration::from_secs(2), telemetry).await;
    served.map_err(|source| ServeError::Io {
        context: "serving".into(),
        source,
    })
}

/// Looks at the token file every [`auth::FILE_POLL`] while the server runs.
async fn watch_token_file(st: Arc<AppState>) {
    if !st.auth.is_named() {
        return;
    }
    let mut shutdown = st.channels.shutdown.subscribe();
    let mut tick = tokio::time::interval(auth::FILE_POLL);
    tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    loop {
        tokio::select! {
            _ = tick.tick() => {
                let st2 = st.clone();
                let _ = tokio::task::spawn_blocking(move || st2.auth.reload_if_changed()).await;
            }
            _ = shutdown.changed() => break,
        }
    }
}

/// Raises the soft limit of open files to the hard one (as nginx's `worker_rlimit_nofile`): the
/// default `--max-connections` is what that limit leaves beyond the server's own files
/// (`conn_limit.rs`), and at Debian's default soft limit of 1024 it would be a few hundred.
fn raise_open_files() {
    let mut lim = libc::rlimit {
        rlim_cur: 0,
        rlim_max: 0,
    };
    // SAFETY: getrlimit/setrlimit with a valid rlimit struct.
    unsafe {
        if libc::getrlimit(libc::RLIMIT_NOFILE, &mut lim) == 0 && lim.rlim_cur < lim.rlim_max {
            let from = lim.rlim_cur;
            lim.rlim_cur = lim.rlim_max;
            if libc::setrlimit(libc::RLIMIT_NOFILE, &lim) == 0 {
                tracing::info!("open files: soft limit raised from {from} to {}", lim.rlim_max);
            }
        }
    }
}

/// Binds the listening socket; returns it with the address it got.
async fn bind_to(bind: SocketAddr) -> Result<(tokio::net::TcpListener, SocketAddr), ServeError> {
    let listener = tokio::net::TcpListener::bind(bind)
        .await
        .map_err(|source| ServeError::Io {
            context: format!("binding {bind}"),
            source,
        })?;
    let addr = listener.local_addr().map_err(|source| ServeError::Io {
        context: "reading the bound address".into(),
        source,
    })?;
    Ok((listener, addr))
}

/// Starts the control loop's thread on the scene's instrument and waits for its answer: a
/// haptic link that cannot be opened (another server holds it) stops the start, since a clear
/// refusal is better than a server that says its link is down.
fn start_loop(
    scene: &Scene,
    loop_cfg: LoopConfig,
    real: Option<&crate::instrument_loop::RealInstrument>,
) -> Result<(Arc<Shared>, std::thread::JoinHandle<()>), ServeError> {
    let tick = 1.0 / loop_cfg.rate_hz;
    let base = nanopush_instrument::scan::ScanParams::from_scene(scene);
    let afm = Afm::from_scene(scene, base.centre_x, base.centre_y, tick);
    let shared = Arc::new(Shared::new(&afm));
    if let Some(real) = real {
        // A real controller: its loop instead of the simulation's; the scene's particles are
        // not the sample's.
        if let Ok(mut s) = shared.snapshot.lock() {
            s.particles.clear();
        }
        let thread = crate::instrument_loop::start(real, shared.clone()).map_err(|source| ServeError::Io {
            context: "starting the instrument loop thread".into(),
            source,
        })?;
        return Ok((shared, thread));
    }
    let (ready_tx, ready_rx) = std::sync::mpsc::sync_channel(1);
    let control = ControlLoop::new(afm, scene.bilateral_params(tick)).with_ready(ready_tx);
    let loop_shared = shared.clone();
    let loop_thread = std::thread::Builder::new()
        .name("control-loop".into())
        .spawn(move || control.run(loop_shared, loop_cfg))
        .map_err(|source| ServeError::Io {
            context: "starting the control loop thread".into(),
            source,
        })?;
    match ready_rx.recv_timeout(Duration::from_secs(10)) {
        Ok(Ok(())) => Ok((shared, loop_thread)),
        failed => {
            let why = match failed {
                Ok(Err(why)) => why,
                _ => "the control loop did not start within 10 s".to_string(),
            };
            let _ = shared.commands.push(LoopCommand::Shutdown);
            let _ = loop_thread.join();
            Err(ServeError::Haptic(why))
        }
    }
}

/// The threads that end with the server.
struct Threads {
    recorder: std::thread::JoinHandle<()>,
    control_loop: std::thread::JoinHandle<()>,
    supervisor: Option<Supervisor>,
}

/// Once `shutdown` resolves: commands refused, the loop stopped (the push ends, the tip
/// retracts, the haptic force goes to zero), a scan's record finished, the threads joined, then
/// every session told and closed, and waited for.
async fn graceful_shutdown(st: Arc<AppState>, shutdown: impl std::future::Future<Output = ()>, threads: Threads) {
    shutdown.await;
    tracing::info!("shutting down: stopping the loop and retracting the tip");
    // From now on commands are refused and a push still being prepared is dropped.
    st.activity.stopping.store(true, Relaxed);
    // A real controller's scan ends now, so that its loop hears the shutdown and withdraws.
    if let Some(real) = &st.cfg.instrument {
        real.cancel.store(true, Relaxed);
    }
    let deadline = Instant::now() + Duration::from_secs(20);
    while st.shared.commands.push(LoopCommand::Shutdown).is_err() && Instant::now() < deadline {
        tokio::time::sleep(Duration::from_millis(1)).await;
    }
    while !st.shared.finished.load(std::sync::atomic::Ordering::Acquire) && Instant::now() < deadline {
        tokio::time::sleep(Duration::from_millis(5)).await;
    }
    st.activity.scan_cancel.store(true, Relaxed);
    // A scan being written finishes its record (rename) before the process ends, and so does an
    // assembly (its last frame and its record).
    while (st.activity.scanning.load(Relaxed) || st.activity.assembling.load(Relaxed)) && Instant::now() < deadline {
        tokio::time::sleep(Duration::from_millis(5)).await;
    }
    let _ = tokio::task::spawn_blocking(move || {
        let _ = threads.recorder.join();
        let _ = threads.control_loop.join();
        // The loop has parked the tip and published zero force; now the monitor and the
        // simulated bridge go, reaped.
        if let Some(s) = threads.supervisor {
            s.shutdown();
        }
    })
    .await;
    // Let the last run_done reach the clients, then close every session, and wait for them:
    // axum's graceful shutdown does not track upgraded (WebSocket) connections, so without
    // this wait the process could exit before a session has sent its `shutdown` and close.
    tokio::time::sleep(Duration::from_millis(100)).await;
    let _ = st.channels.shutdown.send(true);
    let closing = Instant::now() + Duration::from_secs(5);
    while st.net.clients.load(Relaxed) > 0 && Instant::now() < closing {
        tokio::time::sleep(Duration::from_millis(5)).await;
    }
}

/// Serves the routes on `listener` until `graceful` ends.
async fn serve_http(
    listener: tokio::net::TcpListener,
    state: Arc<AppState>,
    graceful: impl std::future::Future<Output = ()> + Send + 'static,
) -> std::io::Result<()> {
    let app = app::router(state.clone()).into_make_service_with_connect_info::<SocketAddr>();
    // The connection caps, before anything is read (`conn_limit.rs`).
    let limits = state.conn_limits.clone();
    let admission: guard::Admission =
        std::sync::Arc::new(move |ip| limits.admit(ip).ok().map(|permit| Box::new(permit) as guard::Held));
    // TCP_NODELAY on every connection: with Nagle's algorithm a client's message waited for the
    // ACK of the reply before the next telemetry frames went out (docs/server.md).
    // Slowloris: each request's headers within the header time-out, a plain HTTP connection
    // idle for a minute closed (WebSockets keep themselves alive with pings).
    if let Some(tls) = &state.cfg.access.tls {
        // HTTPS: the handshakes on tasks of their own, the guard over the decrypted bytes.
        let listener = crate::tls::TlsListener::new(listener, tls, state.cfg.header_timeout, IDLE_HTTP, admission)?;
        // (`tap_io`, with nothing to do: axum gives `ConnectInfo<SocketAddr>` to a tapped
        // listener; TCP_NODELAY is set before the handshake.)
        let listener = axum::serve::ListenerExt::tap_io(listener, |_: &mut crate::tls::TlsIo| {});
        return axum::serve(listener, app).with_graceful_shutdown(graceful).await;
    }
    let guarded = guard::GuardedListener::new(listener, state.cfg.header_timeout, IDLE_HTTP, admission);
    let listener = axum::serve::ListenerExt::tap_io(guarded, |io: &mut guard::Guarded| {
        if let Err(e) = io.tcp().set_nodelay(true) {
            tracing::debug!("TCP_NODELAY refused on a connection: {e}");
        }
    });
    axum::serve(listener, app).with_graceful_shutdown(graceful).await
}
