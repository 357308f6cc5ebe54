//! Signing in as the protocol documents it and as an attacker tries it: `Authorization: Bearer`
//! on the WebSocket.

use crate::serve_access::{named_server, try_ws};
use crate::util::{TOKEN, runtime, start};

/// `Authorization: Bearer TOKEN` opens `/ws` as it opens `/api/*` (proto/README.md, "Credentials"):
/// a named token names its person and role, the generated operator token makes an operator, and a
/// wrong one is refused with 401.
#[test]
fn a_bearer_token_opens_the_websocket_as_it_opens_the_api() {
    let (srv, tokens) = named_server("bearer-ws", &[("alice", "operator"), ("bob", "viewer")], &[]);
    runtime().block_on(async {
        for (token, name, role) in [(&tokens[0], "alice", "operator"), (&tokens[1], "bob", "viewer")] {
            let bearer = format!("Bearer {token}");
            let (_ws, w) = try_ws(&srv.addr, None, &[("authorization", &bearer)])
                .await
                .unwrap_or_else(|code| panic!("{name}'s bearer token refused on /ws with {code}"));
            assert_eq!((w["name"].as_str(), w["role"].as_str()), (Some(name), Some(role)));
        }
        let wrong = format!("Bearer {}x", tokens[1]);
        assert_eq!(try_ws(&srv.addr, None, &[("authorization", &wrong)]).await.err(), Some(401));
    });
    let srv = start("bearer-ws-generated", &["--viewer-token", "viewer-token-1"]);
    runtime().block_on(async {
        let bearer = format!("Bearer {TOKEN}");
        let (_ws, w) = try_ws(&srv.addr, None, &[("authorization", &bearer)]).await.expect("operator");
        assert_eq!(w["role"], "operator");
    });
}
