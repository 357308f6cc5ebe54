//! Signing in as the protocol documents it and as an attacker tries it: `Authorization: Bearer`
//! on the WebSocket, and what wrong secrets for a real token's id cost the server's memory.

use std::time::Duration;

use crate::serve_access::{named_server, try_ws};
use crate::util::{TOKEN, http, runtime, start};

/// The server's resident memory (MiB).
fn rss_mib(pid: u32) -> u64 {
    nanopush_e2e::procfs::status_field(&format!("/proc/{pid}/status"), "VmRSS").unwrap() / 1024
}

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
        assert_eq!(
            try_ws(&srv.addr, None, &[("authorization", &wrong)]).await.err(),
            Some(401)
        );
    });
    let srv = start("bearer-ws-generated", &["--viewer-token", "viewer-token-1"]);
    runtime().block_on(async {
        let bearer = format!("Bearer {TOKEN}");
        let (_ws, w) = try_ws(&srv.addr, None, &[("authorization", &bearer)])
            .await
            .expect("operator");
        assert_eq!(w["role"], "operator");
    });
}

/// Wrong secrets with a real token's id (`npt_<id>_<wrong>`: argon2 runs for each, 19 MiB) from
/// 60 addresses behind a trusted proxy, 24 one after the other and then 36 at once, leave the
/// server's memory within 64 MiB of where it was: argon2's memory is reused by the 2 checks that
/// run at a time, not kept by every thread that ran one (19 MiB a check, 413 MB after 24).
#[test]
fn failed_token_checks_leave_the_memory_where_it_was() {
    let (srv, tokens) = named_server("rss", &[("alice", "operator")], &["--trusted-proxy", "127.0.0.1"]);
    let pid = srv.child.id();
    let id = tokens[0].split('_').nth(1).unwrap().to_string();
    let attempt = move |addr: &str, i: usize| {
        let headers = [
            format!("Authorization: Bearer npt_{id}_{i:032x}"),
            format!("X-Forwarded-For: 192.0.2.{i}"),
        ];
        http(addr, "GET", "/api/status", &headers).0
    };
    // One check first: what every check shares (the pool, the first buffer) is in the baseline.
    assert_eq!(attempt(&srv.addr, 200), 401);
    std::thread::sleep(Duration::from_millis(200));
    let before = rss_mib(pid);
    for i in 0..24 {
        assert_eq!(attempt(&srv.addr, i), 401, "attempt {i}");
    }
    let after_serial = rss_mib(pid);
    let threads: Vec<_> = (24..60)
        .map(|i| {
            let (addr, attempt) = (srv.addr.clone(), attempt.clone());
            std::thread::spawn(move || attempt(&addr, i))
        })
        .collect();
    let codes: Vec<u16> = threads.into_iter().map(|t| t.join().unwrap()).collect();
    assert!(codes.iter().all(|&c| c == 401 || c == 503), "{codes:?}");
    std::thread::sleep(Duration::from_millis(500));
    let after_burst = rss_mib(pid);
    eprintln!(
        "failed checks: RSS {before} MiB, {after_serial} MiB after 24 one at a time, {after_burst} MiB after 36 at once"
    );
    assert!(
        after_serial.max(after_burst) < before + 64,
        "RSS grew from {before} MiB to {after_serial} MiB (24 checks one at a time) and {after_burst} MiB (36 at once)"
    );
}
