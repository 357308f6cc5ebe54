//! The HTTP side: the routes, the loopback-host and token guard, the JSON API, and the
//! WebSocket upgrade (Origin, token, role, admission).

mod sign_in;

use std::net::SocketAddr;
use std::sync::atomic::Ordering::Relaxed;
use std::sync::{Arc, Mutex};

use axum::Router;
use axum::extract::ws::WebSocketUpgrade;
use axum::extract::{ConnectInfo, Path as UrlPath, Query, State};
use axum::http::{HeaderMap, StatusCode, header};
use axum::response::{IntoResponse, Response};
use axum::routing::get;
use nanopush_proto::ws::ServerMessage;

use crate::app_state::{AppState, Place};
use crate::haptic::api::haptic_status;
use crate::metrics::render;
use crate::record_routes;
use crate::session::{HARD_CAP, session};

/// What is wrong with the built web client in `web_dir`, in words, or None: not built (the page
/// cannot start), or built before a change of its sources (`web/src/`, after a `git pull`: the
/// page served is the old one). Both name the command that builds it.
pub fn web_build_problem(web_dir: &std::path::Path) -> Option<String> {
    let built = web_dir.join("dist").join("main.js");
    let how = format!(
        "build it with `cd {} && npm ci && npm run build` (or `make web`)",
        web_dir.display()
    );
    let Ok(built_at) = std::fs::metadata(&built).and_then(|m| m.modified()) else {
        return Some(format!(
            "the web client is not built ({} is missing): the page cannot start; {how}",
            built.display()
        ));
    };
    let newer = std::fs::read_dir(web_dir.join("src"))
        .into_iter()
        .flatten()
        .flatten()
        .filter(|e| e.metadata().and_then(|m| m.modified()).is_ok_and(|t| t > built_at))
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .min();
    newer.map(|name| {
        format!(
            "the web client is older than its sources (src/{name} changed since {} was built): the page served is the old one; {how}",
            built.display()
        )
    })
}

/// The router.
pub fn router(state: Arc<AppState>) -> Router {
    if let Some(problem) = web_build_problem(&state.cfg.web_dir) {
        tracing::warn!("{problem}");
    }
    let web = tower_http::services::ServeDir::new(&state.cfg.web_dir).append_index_html_on_directories(true);
    Router::new()
        .route("/ws", get(ws_upgrade))
        .route("/api/status", get(status))
        .route("/api/scene", get(scene_json))
        .route("/api/records", get(records_list))
        .route("/api/records/{name}", get(record_get))
        .route("/api/runs", get(runs))
        .route("/api/session", get(sign_in::current).post(sign_in::login))
        .route("/metrics", get(metrics))
        // Static files gzip-compressed when the browser accepts it (the minified page, three.js
        // included, is ~0.7 MB, ~0.2 MB on the wire): a remote operator's page loads in seconds.
        .fallback_service(tower_http::compression::Compression::new(web))
        .layer(axum::middleware::from_fn_with_state(state.clone(), guard))
        .with_state(state)
}

/// Every request: when the server listens on loopback, the `Host` must name loopback (a page on
/// another site that rebinds its DNS name to 127.0.0.1 is refused); with `--viewer-token` or a
/// token file, the JSON API needs a credential (`?token=`, a bearer token or the session
/// cookie; `sign_in.rs`). `/metrics` stays open for a local
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
    let gate = if req.uri().path().starts_with("/api/") {
        sign_in::api_gate(&st, &req)
    } else {
        None
    };
    if let Some(gate) = gate
        && let Err(refused) = gate.await
    {
        return refused;
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
        "instrument": st.instrument_info(),
        // Seconds since the real controller's last reading (null on the simulated AFM, or
        // before the first): telemetry that is not changing says why here.
        "instrument_reading_age_s": st.cfg.instrument.as_ref().and_then(|r| r.reading_age_s()),
        "instance": st.instance.id,
        "started_unix_ms": st.instance.started_unix_ms,
        "uptime_s": st.shared.start.elapsed().as_secs_f64(),
        "clients": st.net.clients.load(Relaxed),
        "lease": st.lease_holder(),
        "lease_name": st.lease_name(),
        "phase": st.phase_now(),
        "stage": s.stage,
        "volts": s.volts,
        "busy": st.shared.busy.load(Relaxed) || st.activity.scanning.load(Relaxed),
        "loop": {
            "ticks": m.ticks.load(Relaxed),
            "overruns": m.overruns.load(Relaxed),
            "realtime": m.realtime.load(Relaxed) == 1,
            "no_halt": m.no_halt.load(Relaxed) == 1,
            "period_error_p50_bound_s": m.period_error.quantile_bound(0.5),
            "period_error_p99_bound_s": m.period_error.quantile_bound(0.99),
            "period_error_max_s": m.period_error.max(),
        },
        "telemetry_sent": st.net.sent.load(Relaxed),
        "dropped_frames": st.net.dropped_frames.load(Relaxed),
        "haptic": haptic_status(&m.haptic),
        "haptic_scales": st.haptic_scales.lock().map(|s| *s).ok(),
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

/// A page of the records in the data directory, newest first (`record_routes.rs`).
async fn records_list(State(st): State<Arc<AppState>>, Query(page): Query<record_routes::Page>) -> Response {
    record_routes::list_page(st.cfg.data_dir.clone(), page).await
}

/// The pushes recorded in the data directory, newest first (at most [`crate::records::RUNS_MAX`]): the
/// run history a page or a monitor shows, which survives restarts.
async fn runs(State(st): State<Arc<AppState>>) -> Response {
    let dir = st.cfg.data_dir.clone();
    off_runtime("reading the run history", move || record_routes::run_history(&dir)).await
}

/// `read` (file system work) on a blocking thread, its result as JSON, or a 500 that says
/// `what` failed and why.
async fn off_runtime<T: serde::Serialize + Send + 'static>(
    what: &str,
    read: impl FnOnce() -> std::io::Result<T> + Send + 'static,
) -> Response {
    match tokio::task::spawn_blocking(read).await {
        Ok(Ok(v)) => axum::Json(v).into_response(),
        Ok(Err(e)) => (StatusCode::INTERNAL_SERVER_ERROR, format!("{what}: {e}")).into_response(),
        Err(e) => (StatusCode::INTERNAL_SERVER_ERROR, format!("{what}: {e}")).into_response(),
    }
}

/// One record, streamed (`record_routes.rs`).
async fn record_get(State(st): State<Arc<AppState>>, UrlPath(name): UrlPath<String>) -> Response {
    record_routes::download(st.cfg.data_dir.clone(), name).await
}

async fn metrics(State(st): State<Arc<AppState>>) -> Response {
    let mut text = render(
        &st.shared.metrics,
        &st.net,
        nanopush_proto::haptic::monotonic_ns(),
        crate::metrics::disk_space(&st.cfg.data_dir),
    );
    text.push_str(&st.auth.render_metrics());
    text.push_str(&st.audit.render_metrics());
    text.push_str(&st.conn_limits.render_metrics());
    ([(header::CONTENT_TYPE, "text/plain; version=0.0.4")], text).into_response()
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
    let scheme = if st.cfg.access.tls.is_some() { "https" } else { "http" };
    [
        format!("{scheme}://127.0.0.1:{port}"),
        format!("{scheme}://localhost:{port}"),
        format!("{scheme}://{addr}"),
    ]
    .iter()
    .any(|o| o == origin)
}

async fn ws_upgrade(
    State(st): State<Arc<AppState>>,
    ConnectInfo(peer): ConnectInfo<SocketAddr>,
    uri: axum::http::Uri,
    headers: HeaderMap,
    ws: WebSocketUpgrade,
) -> Response {
    if *st.channels.shutdown.borrow() {
        return (StatusCode::SERVICE_UNAVAILABLE, "shutting down").into_response();
    }
    if let Some(origin) = headers.get(header::ORIGIN) {
        let ok = origin.to_str().map(|o| origin_allowed(&st, o)).unwrap_or(false);
        if !ok {
            return (StatusCode::FORBIDDEN, "origin not allowed; see --allow-origin").into_response();
        }
    }
    // The client behind a trusted proxy; its token (`?token=` or `Authorization: Bearer`, as on
    // `/api/*`; checked, failures rate-limited per address) or its session cookie.
    let ip = sign_in::client_of(&st, peer.ip(), &headers);
    let cookie = crate::auth::http::cookie(&headers);
    let token = crate::auth::http::token(&uri, &headers);
    let person = match st.auth.authenticate(ip, token.as_deref(), cookie.as_deref()).await {
        Ok(p) => p,
        Err((code, why)) => return (code, why).into_response(),
    };
    let role = person.role;
    let peer = SocketAddr::new(ip, peer.port());
    // Counted here, under one lock, so simultaneous upgrades cannot pass the cap together; the
    // session (or a failed upgrade) gives the place back when it drops it.
    let place = match Place::take(&st, role, ip) {
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
            session(st, socket, person, peer).await;
            drop(held);
        })
}

#[cfg(test)]
mod tests {
    use super::web_build_problem;

    /// A web client not built, or built before its sources changed, is said at start with the
    /// command that builds it (after a `git pull`, the old page would be served without a word).
    #[test]
    fn a_web_client_missing_or_stale_is_named_with_its_build_command() {
        let web = std::env::temp_dir().join(format!("nanopush-webbuild-{}", std::process::id()));
        std::fs::create_dir_all(web.join("src")).unwrap();
        std::fs::create_dir_all(web.join("dist")).unwrap();
        std::fs::write(web.join("src/app.js"), "1").unwrap();
        let p = web_build_problem(&web).expect("not built");
        assert!(p.contains("is not built") && p.contains("npm run build"), "{p}");
        std::fs::write(web.join("dist/main.js"), "1").unwrap();
        let built = std::fs::metadata(web.join("dist/main.js")).unwrap().modified().unwrap();
        let before = built - std::time::Duration::from_secs(60);
        let after = built + std::time::Duration::from_secs(60);
        std::fs::File::options()
            .write(true)
            .open(web.join("src/app.js"))
            .unwrap()
            .set_modified(before)
            .unwrap();
        assert_eq!(web_build_problem(&web), None, "built after its sources");
        std::fs::File::options()
            .write(true)
            .open(web.join("src/app.js"))
            .unwrap()
            .set_modified(after)
            .unwrap();
        let p = web_build_problem(&web).expect("older than its sources");
        assert!(p.contains("src/app.js changed") && p.contains("make web"), "{p}");
        std::fs::remove_dir_all(&web).unwrap();
    }
}
