//! Credentials on HTTP, as a request carries them: `?token=` (programs), `Authorization:
//! Bearer` and the session cookie. What the server does with them (`/api/session`, the JSON
//! API's gate, the WebSocket upgrade) is the HTTP side's (`app`).

use axum::extract::Query;
use axum::http::{HeaderMap, header};

use super::COOKIE;

#[derive(Debug, serde::Deserialize)]
struct TokenQuery {
    token: Option<String>,
}

/// `?token=` of a URI, decoded once (`%2B` is '+', '+' a space); None when empty.
pub fn query_token(uri: &axum::http::Uri) -> Option<String> {
    Query::<TokenQuery>::try_from_uri(uri)
        .ok()
        .and_then(|q| q.0.token)
        .filter(|t| !t.is_empty())
}

/// The `Authorization: Bearer` token; None when empty.
pub fn bearer(headers: &HeaderMap) -> Option<String> {
    let v = headers.get(header::AUTHORIZATION)?.to_str().ok()?;
    let (scheme, token) = v.trim().split_once(' ')?;
    let token = token.trim();
    (scheme.eq_ignore_ascii_case("bearer") && !token.is_empty()).then(|| token.to_string())
}

/// The token a request carries: its `?token=`, else its bearer token (an empty one is none).
pub fn token(uri: &axum::http::Uri, headers: &HeaderMap) -> Option<String> {
    query_token(uri).or_else(|| bearer(headers))
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

    /// An empty `?token=` or `Bearer` carries no token: the other credentials are looked at, and
    /// no failed attempt is counted against the address.
    #[test]
    fn an_empty_token_is_no_token() {
        let uri = |s: &str| s.parse::<axum::http::Uri>().unwrap();
        assert_eq!(query_token(&uri("/ws?token=")), None);
        assert_eq!(query_token(&uri("/ws?token=npt_x_y")).as_deref(), Some("npt_x_y"));
        let mut h = HeaderMap::new();
        h.insert(header::AUTHORIZATION, "Bearer ".parse().unwrap());
        assert_eq!(bearer(&h), None);
        h.insert(header::AUTHORIZATION, "Bearer npt_x_y".parse().unwrap());
        assert_eq!(token(&uri("/ws?token="), &h).as_deref(), Some("npt_x_y"));
        assert_eq!(token(&uri("/ws?token=npt_a_b"), &h).as_deref(), Some("npt_a_b"));
    }
}
