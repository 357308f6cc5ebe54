//! Signing in over HTTP: `/api/session`, where the page exchanges the token of its URL for an
//! HttpOnly, SameSite=Strict cookie (Secure over HTTPS) and then removes the token from its
//! address bar; who a request is; and the gate of the JSON API.

use std::net::{IpAddr, SocketAddr};
use std::sync::Arc;

use axum::extract::{ConnectInfo, State};
use axum::http::{HeaderMap, StatusCode, header};
use axum::response::{IntoResponse, Response};

use crate::app_state::AppState;
use crate::auth::http::{bearer, cookie, token};
use crate::auth::tokens::role_name;
use crate::auth::{COOKIE, Person, Refused};
use crate::client_addr::{client_ip, forwarded_https};

/// The client's address for a request from `peer`.
pub fn client_of(st: &AppState, peer: IpAddr, headers: &HeaderMap) -> IpAddr {
    client_ip(peer, headers, &st.cfg.access.trusted_proxies)
}

/// Who a request is, from its `?token=`, its bearer token or its cookie.
pub async fn request_person(
    st: &AppState,
    peer: IpAddr,
    uri: &axum::http::Uri,
    headers: &HeaderMap,
) -> Result<Arc<Person>, Refused> {
    let ip = client_of(st, peer, headers);
    let token = token(uri, headers);
    st.auth
        .authenticate(ip, token.as_deref(), cookie(headers).as_deref())
        .await
}

/// The JSON API's gate: with a token file or a viewer token, a request needs a credential
/// (any role reads the API). `/api/session` does its own checking.
pub fn api_gate<'a>(
    st: &'a AppState,
    req: &axum::extract::Request,
) -> Option<impl std::future::Future<Output = Result<(), Response>> + Send + use<'a>> {
    if !st.auth.credential_required() || req.uri().path() == "/api/session" {
        return None;
    }
    let peer = req
        .extensions()
        .get::<ConnectInfo<SocketAddr>>()
        .map_or(IpAddr::from([0, 0, 0, 0]), |c| c.0.ip());
    // Owned: the request (its body) is not `Sync`, so no reference to it may cross an await.
    let (uri, headers) = (req.uri().clone(), req.headers().clone());
    Some(async move {
        request_person(st, peer, &uri, &headers)
            .await
            .map(|_| ())
            .map_err(|(code, why)| (code, why).into_response())
    })
}

fn whoami(p: &Person) -> serde_json::Value {
    serde_json::json!({ "name": p.name, "role": role_name(p.role) })
}

/// `POST /api/session` with `Authorization: Bearer TOKEN`: the token checked (failures counted
/// and rate-limited per address), then a session cookie set; answers `{name, role}`.
pub async fn login(
    State(st): State<Arc<AppState>>,
    ConnectInfo(peer): ConnectInfo<SocketAddr>,
    headers: HeaderMap,
) -> Response {
    let Some(token) = bearer(&headers) else {
        return (
            StatusCode::BAD_REQUEST,
            "POST /api/session needs the token in `Authorization: Bearer TOKEN`",
        )
            .into_response();
    };
    let ip = client_of(&st, peer.ip(), &headers);
    let person = match st.auth.authenticate(ip, Some(&token), None).await {
        Ok(p) => p,
        Err((code, why)) => return (code, why).into_response(),
    };
    let Some(value) = st.auth.login(&person) else {
        return (
            StatusCode::INTERNAL_SERVER_ERROR,
            "no key to sign session cookies (the kernel gave no random bytes); use ?token=",
        )
            .into_response();
    };
    let secure = st.cfg.access.tls.is_some() || forwarded_https(peer.ip(), &headers, &st.cfg.access.trusted_proxies);
    let set = format!(
        "{COOKIE}={value}; Path=/; HttpOnly; SameSite=Strict{}",
        if secure { "; Secure" } else { "" }
    );
    tracing::info!("{} ({}) signed in from {ip}", person.name, role_name(person.role));
    (
        [(header::SET_COOKIE, set), (header::CACHE_CONTROL, "no-store".into())],
        axum::Json(whoami(&person)),
    )
        .into_response()
}

/// `GET /api/session`: who this request's credential names, `{name, role}`, or 401.
pub async fn current(
    State(st): State<Arc<AppState>>,
    ConnectInfo(peer): ConnectInfo<SocketAddr>,
    req: axum::extract::Request,
) -> Response {
    match request_person(&st, peer.ip(), req.uri(), req.headers()).await {
        Ok(p) => axum::Json(whoami(&p)).into_response(),
        Err((code, why)) => (code, why).into_response(),
    }
}
