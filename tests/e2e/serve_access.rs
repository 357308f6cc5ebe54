//! Named operators and viewers. A token file made with `nanopush token add`,
//! each person's token naming them and their role; `nanopush token revoke` closes their sessions
//! on the running server; the page's token exchanged for an HttpOnly, SameSite=Strict cookie;
//! failed attempts limited per address (the real client's, behind a trusted proxy) and counted
//! in `/metrics`.

use std::io::Write;
use std::path::Path;
use std::time::{Duration, Instant};

use futures_util::StreamExt;
use nanopush_e2e::{run, text};
use serde_json::{Value, json};
use tokio_tungstenite::tungstenite::Message;
use tokio_tungstenite::tungstenite::client::IntoClientRequest;

use crate::util::{Server, TOKEN, Ws, http, is, ok, ok_and, reply, runtime, send, start, start_args, until};

/// `nanopush token add NAME --role ROLE --token-file FILE`: the token it prints (its last line).
pub(crate) fn add_token(file: &Path, name: &str, role: &str) -> String {
    let f = file.to_str().unwrap();
    let o = run(
        "nanopush",
        &["token", "add", name, "--role", role, "--token-file", f],
        None,
    );
    let (out, err) = text(&o);
    assert!(o.status.success(), "token add {name}: {err}");
    let token = out.lines().last().unwrap().trim().to_string();
    assert!(token.starts_with("npt_"), "{out}");
    token
}

/// A server with a token file of `people` (name, role): the server and each one's token.
pub(crate) fn named_server(tag: &str, people: &[(&str, &str)], extra: &[&str]) -> (Server, Vec<String>) {
    let mut tokens = Vec::new();
    let srv = start_args(tag, |dir| {
        let file = dir.join("tokens");
        tokens = people.iter().map(|(n, r)| add_token(&file, n, r)).collect();
        let mut a = vec!["--token-file".to_string(), file.to_str().unwrap().to_string()];
        a.extend(extra.iter().map(|s| s.to_string()));
        a
    });
    (srv, tokens)
}

/// A WebSocket upgrade with `token` and `headers`: the socket and its welcome, or the HTTP
/// status it was refused with.
pub(crate) async fn try_ws(addr: &str, token: Option<&str>, headers: &[(&str, &str)]) -> Result<(Ws, Value), u16> {
    let url = nanopush_e2e::client::ws_url(addr, token);
    let mut req = url.into_client_request().unwrap();
    for (k, v) in headers {
        let name: tokio_tungstenite::tungstenite::http::HeaderName = k.parse().unwrap();
        req.headers_mut().insert(name, v.parse().unwrap());
    }
    match tokio_tungstenite::connect_async(req).await {
        Ok((mut ws, _)) => {
            let w = until(&mut ws, 10.0, |m| is(m, "welcome")).await;
            Ok((ws, w))
        }
        Err(tokio_tungstenite::tungstenite::Error::Http(r)) => Err(r.status().as_u16()),
        Err(e) => panic!("upgrade failed without an HTTP answer: {e}"),
    }
}

/// A metric's value in the server's `/metrics`.
pub(crate) fn metric(addr: &str, name: &str) -> f64 {
    let (code, body) = crate::util::http_get(addr, "/metrics");
    assert_eq!(code, 200);
    let body = String::from_utf8(body).unwrap();
    body.lines()
        .find_map(|l| l.strip_prefix(&format!("{name} ")))
        .unwrap_or_else(|| panic!("{name} is not in /metrics"))
        .trim()
        .parse()
        .unwrap()
}

/// Each person's token names them and their role: the operator takes the lease, everyone is
/// told its holder by name, the viewer cannot command; no token, a wrong one or the generated
/// operator token is refused. Revoking the operator's token with `nanopush token revoke` closes
/// their session at once (an `error` saying why, then close code 1008), frees the lease, and
/// their token no longer opens anything.
#[test]
fn named_tokens_carry_their_roles_and_a_revoked_one_is_closed_at_once() {
    let (srv, tokens) = named_server("named", &[("alice", "operator"), ("bob", "viewer")], &[]);
    let (alice, bob) = (&tokens[0], &tokens[1]);
    runtime().block_on(async {
        let (mut a, w) = try_ws(&srv.addr, Some(alice), &[]).await.expect("alice connects");
        assert_eq!(
            (w["role"].as_str(), w["name"].as_str()),
            (Some("operator"), Some("alice")),
            "{w}"
        );
        // The `lease` broadcast may reach alice before or after the reply to her command.
        let lease = ok_and(&mut a, json!({"type": "take_lease", "id": 1}), 5.0, |m| is(m, "lease")).await;
        assert_eq!(lease["holder_name"], "alice", "{lease}");

        let (mut b, w) = try_ws(&srv.addr, Some(bob), &[]).await.expect("bob connects");
        assert_eq!(
            (w["role"].as_str(), w["name"].as_str()),
            (Some("viewer"), Some("bob")),
            "{w}"
        );
        assert_eq!(w["lease_name"], "alice", "the welcome names the lease holder: {w}");
        let st = until(&mut b, 5.0, |m| is(m, "state")).await;
        assert_eq!(st["lease_name"], "alice", "{st}");
        send(&mut b, json!({"type": "take_lease", "id": 2})).await;
        assert_eq!(reply(&mut b, 2).await["code"], "forbidden");

        assert_eq!(try_ws(&srv.addr, None, &[]).await.err(), Some(401), "no token");
        assert_eq!(
            try_ws(&srv.addr, Some(TOKEN), &[]).await.err(),
            Some(401),
            "not a token of the file"
        );
        // The last character changed (to `0`, or to `1` when it is `0`: a token that ended in
        // `0` was "forged" into itself, and CI failed one run in sixteen or so).
        let last = if alice.ends_with('0') { '1' } else { '0' };
        let forged = format!("{}{last}", &alice[..alice.len() - 1]);
        assert_ne!(&forged, alice);
        assert_eq!(
            try_ws(&srv.addr, Some(&forged), &[]).await.err(),
            Some(401),
            "alice's id, a wrong secret"
        );
        // The JSON API needs a credential too, and names the lease holder.
        assert_eq!(http(&srv.addr, "GET", "/api/status", &[]).0, 401);
        let (code, _, body) = http(&srv.addr, "GET", &format!("/api/status?token={bob}"), &[]);
        assert_eq!(code, 200, "{body}");
        let status: Value = serde_json::from_str(&body).unwrap();
        assert_eq!(status["lease_name"], "alice", "{status}");

        let file = srv.dir.join("tokens");
        let o = run(
            "nanopush",
            &["token", "revoke", "alice", "--token-file", file.to_str().unwrap()],
            None,
        );
        assert!(o.status.success(), "{}", text(&o).1);
        // Alice is told and closed with 1008; waited for (not timed) within a generous bound.
        let why = until(&mut a, 20.0, |m| is(m, "error") && m["id"].is_null()).await;
        assert_eq!(why["code"], "forbidden");
        assert!(
            why["message"]
                .as_str()
                .unwrap()
                .contains("the token of alice was revoked"),
            "{why}"
        );
        let close = tokio::time::timeout(Duration::from_secs(10), a.next())
            .await
            .expect("closed");
        match close {
            Some(Ok(Message::Close(Some(f)))) => assert_eq!(u16::from(f.code), 1008, "{f:?}"),
            other => panic!("expected a close frame with 1008, got {other:?}"),
        }
        // Everyone hears the lease is free; bob stays.
        let freed = until(&mut b, 10.0, |m| is(m, "lease")).await;
        assert!(freed["holder"].is_null(), "{freed}");
        assert_eq!(
            try_ws(&srv.addr, Some(alice), &[]).await.err(),
            Some(401),
            "a revoked token"
        );
        assert_eq!(metric(&srv.addr, "nanopush_auth_revoked_sessions_total"), 1.0);
        let list = run(
            "nanopush",
            &["token", "list", "--token-file", file.to_str().unwrap()],
            None,
        );
        let (out, _) = text(&list);
        assert!(out.contains("bob") && !out.contains("alice"), "{out}");
        assert!(!out.contains(bob.as_str()), "list never shows a token");
    });
}

/// The page's exchange: `POST /api/session` with the token in `Authorization: Bearer` sets an
/// HttpOnly, SameSite=Strict session cookie (not Secure over plain HTTP); the cookie alone then
/// opens the API and the WebSocket as the same person. A revoked token's cookie stops working.
#[test]
fn a_token_is_exchanged_for_an_http_only_same_site_strict_cookie() {
    let (srv, tokens) = named_server("cookie", &[("carol", "operator")], &[]);
    let auth = format!("Authorization: Bearer {}", tokens[0]);
    let (code, head, body) = http(&srv.addr, "POST", "/api/session", &[auth]);
    assert_eq!(code, 200, "{body}");
    let me: Value = serde_json::from_str(&body).unwrap();
    assert_eq!(me, json!({"name": "carol", "role": "operator"}));
    let set = head
        .lines()
        .find_map(|l| l.strip_prefix("set-cookie: "))
        .expect("a set-cookie header")
        .to_string();
    assert!(
        set.contains("httponly") && set.contains("samesite=strict") && set.contains("path=/"),
        "{set}"
    );
    assert!(!set.contains("secure"), "plain HTTP: not Secure ({set})");
    let value = set.split(';').next().unwrap().trim().to_string();
    let cookie = format!("Cookie: {value}");
    assert_eq!(
        http(&srv.addr, "GET", "/api/status", std::slice::from_ref(&cookie)).0,
        200
    );
    let (code, _, who) = http(&srv.addr, "GET", "/api/session", std::slice::from_ref(&cookie));
    assert_eq!((code, who.contains("carol")), (200, true), "{who}");
    let raw_cookie = value.clone();
    runtime().block_on(async {
        let (_ws, w) = try_ws(&srv.addr, None, &[("cookie", raw_cookie.as_str())])
            .await
            .expect("the cookie opens the WebSocket");
        assert_eq!(
            (w["name"].as_str(), w["role"].as_str()),
            (Some("carol"), Some("operator"))
        );
    });
    assert_eq!(
        http(
            &srv.addr,
            "POST",
            "/api/session",
            &["Authorization: Bearer npt_00000000_00".into()]
        )
        .0,
        401
    );
    let file = srv.dir.join("tokens");
    assert!(
        run(
            "nanopush",
            &["token", "revoke", "carol", "--token-file", file.to_str().unwrap()],
            None
        )
        .status
        .success()
    );
    let deadline = Instant::now() + Duration::from_secs(20);
    while http(&srv.addr, "GET", "/api/status", std::slice::from_ref(&cookie)).0 == 200 {
        assert!(
            Instant::now() < deadline,
            "a revoked token's cookie still opens the API"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// Failed attempts are limited per address: ten wrong tokens from one client (named by a trusted
/// proxy's X-Forwarded-For) and its eleventh attempt is refused with 429 even with the right
/// token, while another client behind the same proxy gets in; the failures and the refusal are
/// counted in /metrics. Without the file, the generated token still works (`make run`).
#[test]
fn failed_attempts_are_limited_per_real_client_address_and_counted() {
    let srv = start(
        "ratelimit",
        &["--viewer-token", "viewer-token-1", "--trusted-proxy", "127.0.0.1"],
    );
    let from = |ip: &str| format!("X-Forwarded-For: {ip}");
    for i in 0..10 {
        let (code, _, body) = http(
            &srv.addr,
            "GET",
            &format!("/api/status?token=wrong{i}"),
            &[from("192.0.2.10")],
        );
        assert_eq!(code, 401, "attempt {i}: {body}");
    }
    let (code, _, body) = http(
        &srv.addr,
        "GET",
        &format!("/api/status?token={TOKEN}"),
        &[from("192.0.2.10")],
    );
    assert_eq!(code, 429, "{body}");
    assert!(body.contains("too many failed attempts from 192.0.2.10"), "{body}");
    let (code, _, body) = http(
        &srv.addr,
        "GET",
        &format!("/api/status?token={TOKEN}"),
        &[from("192.0.2.11")],
    );
    assert_eq!(code, 200, "another client behind the proxy: {body}");
    assert_eq!(metric(&srv.addr, "nanopush_auth_failures_total"), 10.0);
    assert_eq!(metric(&srv.addr, "nanopush_auth_throttled_total"), 1.0);
    runtime().block_on(async {
        let (_ws, w) = try_ws(&srv.addr, Some(TOKEN), &[("x-forwarded-for", "192.0.2.11")])
            .await
            .expect("the generated operator token");
        assert_eq!(
            (w["role"].as_str(), w["name"].as_str()),
            (Some("operator"), Some("operator"))
        );
        assert_eq!(
            try_ws(&srv.addr, Some(TOKEN), &[("x-forwarded-for", "192.0.2.10")])
                .await
                .err(),
            Some(429),
            "the WebSocket is limited as the API is"
        );
    });
}

/// An attempt is counted against its address before its token is verified (argon2, on a
/// blocking thread), not after: wrong tokens sent at once from one address would otherwise all
/// pass the check. Each check with a known id (a viewer knows their own) runs argon2 (19 MiB) on
/// a blocking thread: 200 at once would take a server from 27 MB to 986 MB RSS (kept afterwards,
/// 115 threads) and slow everyone's telemetry (gaps of 435 ms). 60 wrong tokens at once from
/// 127.0.0.1 cost at most the burst of 10 checks; the rest are refused with 429 unchecked.
#[test]
fn wrong_tokens_sent_at_once_from_one_address_are_held_to_the_burst() {
    let (srv, tokens) = named_server("burst", &[("alice", "operator")], &[]);
    // Alice's id (not secret) with a wrong secret: argon2 runs for each.
    let id = tokens[0].split('_').nth(1).unwrap().to_string();
    let threads: Vec<_> = (0..60)
        .map(|i| {
            let (addr, id) = (srv.addr.clone(), id.clone());
            std::thread::spawn(move || {
                let bearer = format!("Authorization: Bearer npt_{id}_{i:032x}");
                http(&addr, "GET", "/api/status", &[bearer]).0
            })
        })
        .collect();
    let codes: Vec<u16> = threads.into_iter().map(|t| t.join().unwrap()).collect();
    let checked = codes.iter().filter(|&&c| c == 401).count();
    let throttled = codes.iter().filter(|&&c| c == 429).count();
    assert_eq!(checked + throttled, 60, "{codes:?}");
    assert!(
        checked <= 10,
        "{checked} wrong tokens from one address were checked (argon2 each), the limit is 10; \
         failures_total {}",
        metric(&srv.addr, "nanopush_auth_failures_total")
    );
}

/// `nanopush token add|revoke` read the file, change it and write it back under a lock: run at
/// once (a script adding a class, `xargs -P`), each person said added is in the file (without
/// the lock the file keeps one of them, and a `revoke` while an `add` hashes is undone by the
/// add's write).
#[test]
fn token_adds_run_at_once_all_reach_the_file() {
    let dir = crate::util::tmp("tokens-at-once");
    let file = dir.join("tokens");
    let names: Vec<String> = (0..6).map(|i| format!("student{i}")).collect();
    let threads: Vec<_> = names
        .iter()
        .map(|n| {
            let (n, f) = (n.clone(), file.clone());
            std::thread::spawn(move || add_token(&f, &n, "viewer"))
        })
        .collect();
    for t in threads {
        t.join().unwrap();
    }
    let o = run(
        "nanopush",
        &["token", "list", "--token-file", file.to_str().unwrap()],
        None,
    );
    let (out, _) = text(&o);
    let missing: Vec<&String> = names.iter().filter(|n| !out.contains(n.as_str())).collect();
    let _ = std::fs::remove_dir_all(&dir);
    assert!(
        missing.is_empty(),
        "each add said it added its person; the file lacks {missing:?}:\n{out}"
    );
}

/// The token file edited in place (truncated, then written 0.4 s later: `echo >`, an editor
/// saving over it) is not read as an empty file that revokes everyone: a change is applied once
/// the file has stayed the same for a second, and the operator stays. A deleted file revokes
/// nobody either (said in the log and `/metrics`); `nanopush token revoke` still closes her
/// session.
#[test]
fn an_edited_or_deleted_token_file_keeps_everyone_and_revokes_still_close() {
    let (srv, tokens) = named_server("inplace", &[("alice", "operator"), ("bob", "viewer")], &[]);
    let file = srv.dir.join("tokens");
    let body = std::fs::read_to_string(&file).unwrap();
    // Longer than the settling (1 s) and a few polls (0.25 s): what would be applied is.
    let settled = Duration::from_millis(2500);
    runtime().block_on(async {
        let (mut a, _) = try_ws(&srv.addr, Some(&tokens[0]), &[]).await.expect("alice connects");
        ok(&mut a, json!({"type": "take_lease", "id": 1})).await;

        // In place, in two steps.
        std::fs::OpenOptions::new()
            .write(true)
            .truncate(true)
            .open(&file)
            .unwrap();
        tokio::time::sleep(Duration::from_millis(400)).await;
        std::fs::OpenOptions::new()
            .write(true)
            .open(&file)
            .unwrap()
            .write_all(body.as_bytes())
            .unwrap();
        tokio::time::sleep(settled).await;
        ok(&mut a, json!({"type": "stop", "id": 2})).await;
        assert_eq!(metric(&srv.addr, "nanopush_auth_revoked_sessions_total"), 0.0);
        assert_eq!(metric(&srv.addr, "nanopush_auth_token_file_ok"), 1.0);

        // Deleted: the tokens read before stay, the problem is shown; put back, it is gone.
        std::fs::remove_file(&file).unwrap();
        tokio::time::sleep(settled).await;
        ok(&mut a, json!({"type": "stop", "id": 3})).await;
        assert_eq!(metric(&srv.addr, "nanopush_auth_token_file_ok"), 0.0);
        assert_eq!(metric(&srv.addr, "nanopush_auth_token_file_errors_total"), 1.0);
        let (code, _, _) = http(&srv.addr, "GET", &format!("/api/status?token={}", tokens[1]), &[]);
        assert_eq!(code, 200, "bob's token still opens the API");
        std::fs::write(&file, &body).unwrap();
        let t0 = Instant::now();
        while metric(&srv.addr, "nanopush_auth_token_file_ok") != 1.0 {
            assert!(
                t0.elapsed() < Duration::from_secs(20),
                "the file put back is never read"
            );
            tokio::time::sleep(Duration::from_millis(100)).await;
        }
        ok(&mut a, json!({"type": "stop", "id": 4})).await;
        assert_eq!(metric(&srv.addr, "nanopush_auth_revoked_sessions_total"), 0.0);

        let o = run(
            "nanopush",
            &["token", "revoke", "alice", "--token-file", file.to_str().unwrap()],
            None,
        );
        assert!(o.status.success(), "{}", text(&o).1);
        let why = until(&mut a, 20.0, |m| is(m, "error") && m["id"].is_null()).await;
        assert!(
            why["message"]
                .as_str()
                .unwrap()
                .contains("the token of alice was revoked"),
            "{why}"
        );
        assert_eq!(metric(&srv.addr, "nanopush_auth_revoked_sessions_total"), 1.0);
    });
}
