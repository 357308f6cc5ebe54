//! Access without a network: the generated tokens, the token file, cookies, revocation and the
//! per-address limit.

use super::*;

fn ip(s: &str) -> IpAddr {
    s.parse().unwrap()
}

#[tokio::test]
async fn without_a_token_file_the_generated_tokens_name_the_operator_and_the_viewer() {
    let open = Auth::new("op-secret-1".into(), None, None);
    let p = open
        .authenticate(ip("10.0.0.1"), Some("op-secret-1"), None)
        .await
        .unwrap();
    assert_eq!((p.name.as_str(), p.role), ("operator", Role::Operator));
    // No viewer token: anyone without a token is an anonymous viewer.
    let a = open.authenticate(ip("10.0.0.1"), None, None).await.unwrap();
    assert_eq!((a.name.as_str(), a.role), ("anonymous", Role::Viewer));
    let e = open
        .authenticate(ip("10.0.0.1"), Some("op-secret-2"), None)
        .await
        .unwrap_err();
    assert_eq!(e.0, StatusCode::UNAUTHORIZED);
    assert_eq!(open.counters.failures.load(Relaxed), 1);

    let closed = Auth::new("op-secret-1".into(), Some("view-1234".into()), None);
    let v = closed
        .authenticate(ip("10.0.0.1"), Some("view-1234"), None)
        .await
        .unwrap();
    assert_eq!(v.role, Role::Viewer);
    assert_eq!(
        closed.authenticate(ip("10.0.0.1"), None, None).await.unwrap_err().0,
        StatusCode::UNAUTHORIZED
    );
}

#[tokio::test]
async fn ten_failures_from_an_address_refuse_even_the_right_token_there_and_only_there() {
    let auth = Auth::new("op-secret-1".into(), None, None);
    for _ in 0..10 {
        auth.authenticate(ip("10.0.0.9"), Some("guess"), None)
            .await
            .unwrap_err();
    }
    let e = auth
        .authenticate(ip("10.0.0.9"), Some("op-secret-1"), None)
        .await
        .unwrap_err();
    assert_eq!(e.0, StatusCode::TOO_MANY_REQUESTS, "{}", e.1);
    assert!(e.1.contains("too many failed attempts from 10.0.0.9"), "{}", e.1);
    assert_eq!(auth.counters.failures.load(Relaxed), 10);
    assert_eq!(auth.counters.throttled.load(Relaxed), 1);
    auth.authenticate(ip("10.0.0.8"), Some("op-secret-1"), None)
        .await
        .unwrap();
}

#[tokio::test]
async fn a_revoked_token_closes_its_sessions_forgets_its_cookies_and_is_refused() {
    let dir = std::env::temp_dir().join(format!("nanopush-auth-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("tokens");
    let mut table = TokenTable::default();
    let alice = table.add("alice", Role::Operator).unwrap();
    let bob = table.add("bob", Role::Viewer).unwrap();
    table.write(&path).unwrap();
    let auth = Auth::new(
        "generated-op".into(),
        None,
        Some(TokenFile {
            path: path.clone(),
            table: table.clone(),
        }),
    );
    // The generated token is no key to a server with a token file, and nobody is anonymous.
    assert!(
        auth.authenticate(ip("10.0.0.1"), Some("generated-op"), None)
            .await
            .is_err()
    );
    assert!(auth.authenticate(ip("10.0.0.1"), None, None).await.is_err());
    let a = auth.authenticate(ip("10.0.0.1"), Some(&alice), None).await.unwrap();
    assert_eq!((a.name.as_str(), a.role), ("alice", Role::Operator));
    let b = auth.authenticate(ip("10.0.0.2"), Some(&bob), None).await.unwrap();
    let cookie = auth.login(&a).unwrap();
    assert_eq!(auth.person_for_cookie(&cookie).unwrap().name, "alice");
    let mut alice_session = auth.join(1, a);
    let bob_session = auth.join(2, b);
    assert_eq!(auth.name_of(1).as_deref(), Some("alice"));
    assert!(!auth.reload_if_changed(), "unchanged: not re-read");

    table.revoke("alice").unwrap();
    table.write(&path).unwrap();
    assert!(auth.reload_if_changed());
    alice_session.changed().await.unwrap();
    let why = alice_session.borrow().clone().unwrap();
    assert!(why.contains("the token of alice was revoked"), "{why}");
    assert!(!bob_session.has_changed().unwrap(), "bob's session stays");
    assert!(auth.person_for_cookie(&cookie).is_none(), "alice's cookie is forgotten");
    assert!(auth.authenticate(ip("10.0.0.1"), Some(&alice), None).await.is_err());
    auth.authenticate(ip("10.0.0.2"), Some(&bob), None).await.unwrap();
    assert_eq!(auth.counters.revoked_sessions.load(Relaxed), 1);
    std::fs::remove_dir_all(&dir).unwrap();
}
