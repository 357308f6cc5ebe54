//! Credentials on HTTP: `?token=` (programs), `Authorization: Bearer` and the session cookie;
//! `/api/session`, where the page exchanges the token of its URL for an HttpOnly, SameSite=Strict
//! cookie (Secure over HTTPS) and then removes the token from its address bar; and the gate of
//! the JSON API.

use std::net::{IpAddr, SocketAddr};
use std::sync::Arc;

use axum::extract::{ConnectInfo, Query, State};
use axum::http::{HeaderMap, StatusCode, header};
use axum::response::{IntoResponse, Response};

use super::tokens::role_name;
use super::{COOKIE, Person, Refused};
use crate::app_state::AppState;
use crate::client_addr::{client_ip, forwarded_https};

#[derive(Debug, serde::Deserialize)]
struct TokenQuery {
    token: Option<String>,
}

/// `?token=` of a URI, decoded once (`%2B` is '+', '+' a space).
pub fn query_token(uri: &axum::http::Uri) -> Option<String> {
    Query::<TokenQuery>::try_from_uri(uri).ok().and_then(|q| q.0.token)
}

/// The `Authorization: Bearer` token.
pub fn bearer(headers: &HeaderMap) -> Option<String> {
    let v = headers.get(header::AUTHORIZATION)?.to_str().ok()?;
    let (scheme, token) = v.trim().split_once(' ')?;
    scheme.eq_ignore_ascii_case("bearer").then(|| token.trim().to_string())
}

/// The session cookie's value.
pub fn cookie(headers: &HeaderMap) -> Option<String> {
    headers
        .get_all(header::COOKIE)
        .iter()
        .filter_map(|v| v.to_str().ok())
        .flat_map(|v| v.split(';'))
        .filter_map(|kv| kv.trim().split_once('='))
        .find(|(k, _)| *k == COOKIE)
        .map(|(_, v)| v.to_string())
}

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
    let token = query_token(uri).or_else(|| bearer(headers));
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_cookie_and_the_bearer_token_are_found_among_others() {
        let mut h = HeaderMap::new();
        h.insert(header::COOKIE, "a=1; nanopush_session=abc ; b=2".parse().unwrap());
        h.insert(header::AUTHORIZATION, "Bearer npt_x_y".parse().unwrap());
        assert_eq!(cookie(&h).as_deref(), Some("abc"));
        assert_eq!(bearer(&h).as_deref(), Some("npt_x_y"));
        h.insert(header::AUTHORIZATION, "Basic xyz".parse().unwrap());
        assert_eq!(bearer(&h), None);
        assert_eq!(cookie(&HeaderMap::new()), None);
    }
}
