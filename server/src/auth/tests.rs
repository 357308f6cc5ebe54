//! Access without a network: the generated tokens, the token file, cookies, revocation and the
//! per-address limit.

use super::*;

fn ip(s: &str) -> IpAddr {
    s.parse().unwrap()
}

#[tokio::test]
async fn without_a_token_file_the_generated_tokens_name_operator_and_viewer() {
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
async fn too_many_failures_refuse_even_the_right_token_from_that_address_only() {
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
    let t0 = std::time::Instant::now();
    assert!(!auth.reload_if_changed_at(t0), "unchanged: not re-read");

    table.revoke("alice").unwrap();
    table.write(&path).unwrap();
    assert!(
        !auth.reload_if_changed_at(t0),
        "a change is applied once it has settled"
    );
    assert!(!alice_session.has_changed().unwrap());
    assert!(auth.reload_if_changed_at(t0 + SETTLE));
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

/// Calls `reload_if_changed` as the server does (more often) until `done` or `within` is over;
/// whether `done` came.
fn polled_until(auth: &Auth, within: std::time::Duration, done: impl Fn() -> bool) -> bool {
    let t0 = std::time::Instant::now();
    while t0.elapsed() < within {
        auth.reload_if_changed();
        if done() {
            return true;
        }
        std::thread::sleep(std::time::Duration::from_millis(50));
    }
    false
}

/// `path` unreadable to the calling thread, its time, size and inode unchanged (what a `sudo
/// nanopush token revoke` leaves for a server running as another user: root:root 0600): as
/// root, the thread's file-system uid is another user's (its capabilities to read anything go
/// with it, for this thread only); otherwise, mode 000. Dropped: readable again, as after the
/// `chown` that fixes it.
struct Unreadable(std::path::PathBuf);

impl Unreadable {
    fn make(path: &std::path::Path) -> Unreadable {
        use std::os::unix::fs::PermissionsExt as _;
        // SAFETY: geteuid has no preconditions; setfsuid changes this thread's file access only.
        if unsafe { libc::geteuid() } == 0 {
            unsafe { libc::setfsuid(65534) };
        } else {
            std::fs::set_permissions(path, std::fs::Permissions::from_mode(0o000)).unwrap();
        }
        assert!(std::fs::read(path).is_err(), "{} is still readable", path.display());
        Unreadable(path.to_path_buf())
    }
}

impl Drop for Unreadable {
    fn drop(&mut self) {
        use std::os::unix::fs::PermissionsExt as _;
        // SAFETY: as in `make`.
        if unsafe { libc::geteuid() } == 0 {
            unsafe { libc::setfsuid(0) };
        } else {
            let _ = std::fs::set_permissions(&self.0, std::fs::Permissions::from_mode(0o600));
        }
    }
}

/// A revocation written into a file the server cannot read, then made readable by a `chown`
/// (which changes neither its time, size nor inode): the failure is said once, counted and
/// shown by `nanopush_auth_token_file_ok`, the file is tried on every poll (its stamp is kept
/// only once it is read), and the revocation takes effect once the file can be read.
#[test]
fn a_revocation_in_an_unreadable_file_takes_effect_once_it_is_readable() {
    let dir = std::env::temp_dir().join(format!("nanopush-auth-perm-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("tokens");
    let mut table = TokenTable::default();
    let alice = table.add("alice", Role::Operator).unwrap();
    table.add("bob", Role::Viewer).unwrap();
    table.write(&path).unwrap();
    let auth = Auth::new(
        "generated-op".into(),
        None,
        Some(TokenFile {
            path: path.clone(),
            table: table.clone(),
        }),
    );
    let a = auth.join(
        1,
        Arc::new(Person {
            name: "alice".into(),
            role: Role::Operator,
            key: table.verify(&alice).unwrap().id.clone(),
        }),
    );
    let metrics_say = |s: &str| auth.render_metrics().lines().any(|l| l == s);
    assert!(metrics_say("nanopush_auth_token_file_ok 1"));

    table.revoke("alice").unwrap();
    table.write(&path).unwrap();
    let kicked = || a.has_changed().unwrap();
    {
        let _unreadable = Unreadable::make(&path);
        let wait = SETTLE + 2 * FILE_POLL;
        assert!(!polled_until(&auth, wait, kicked), "nothing read, nothing applied");
        assert!(
            metrics_say("nanopush_auth_token_file_ok 0") && metrics_say("nanopush_auth_token_file_errors_total 1"),
            "the problem is shown, and counted once however often it is met:\n{}",
            auth.render_metrics()
        );
    }
    assert!(
        polled_until(&auth, std::time::Duration::from_secs(10), kicked),
        "readable again (its stamp unchanged): the revocation takes effect"
    );
    assert!(
        metrics_say("nanopush_auth_token_file_ok 1"),
        "{}",
        auth.render_metrics()
    );
    assert!(metrics_say("nanopush_auth_token_file_errors_total 1"));
    assert_eq!(auth.counters.revoked_sessions.load(Relaxed), 1);
    std::fs::remove_dir_all(&dir).unwrap();
}
