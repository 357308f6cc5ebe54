//! The token file as a careless or hostile administrator may leave it: replaced by a FIFO, whose
//! open and read block until someone writes to it, or a device that never ends. The server reads
//! only regular files of a bounded size, on a thread of its own, and nothing else waits for it:
//! telemetry, `/metrics`, the API and new connections go on, and `/metrics` says the file cannot
//! be used.

use std::path::Path;
use std::time::{Duration, Instant};

use futures_util::StreamExt;
use serde_json::{Value, json};
use tokio_tungstenite::tungstenite::Message;

use crate::serve_access::{metric, named_server, try_ws};
use crate::util::{http_within, is, ok, runtime, until, wait_exit};

/// Makes a FIFO at `path` (nothing is ever written to it).
fn mkfifo(path: &Path) {
    let c = std::ffi::CString::new(path.to_str().unwrap()).unwrap();
    // SAFETY: a NUL-terminated path.
    assert_eq!(
        unsafe { libc::mkfifo(c.as_ptr(), 0o600) },
        0,
        "mkfifo {}",
        path.display()
    );
}

/// Telemetry frames read from `ws` in `secs`.
async fn frames_in(ws: &mut crate::util::Ws, secs: f64) -> u32 {
    let end = Instant::now() + Duration::from_secs_f64(secs);
    let mut n = 0;
    while let Ok(Some(Ok(m))) = tokio::time::timeout(end.saturating_duration_since(Instant::now()), ws.next()).await {
        if let Message::Text(t) = m
            && serde_json::from_str::<Value>(&t).is_ok_and(|v| is(&v, "telemetry"))
        {
            n += 1;
        }
    }
    n
}

/// The token file replaced by a FIFO while the server runs (`rm T; mkfifo T`): telemetry keeps
/// its rate, `/metrics`, `/api/status` and a new connection answer within 2 s each,
/// `nanopush_auth_token_file_ok` is 0 and the log says the file is not a regular file; the file
/// put back without the operator's line, her session is closed (revocations apply again).
#[test]
fn a_token_file_replaced_by_a_fifo_freezes_nothing() {
    let (srv, tokens) = named_server(
        "fifo",
        &[("alice", "operator"), ("bob", "viewer")],
        &["--telemetry-hz", "60"],
    );
    let file = srv.dir.join("tokens");
    let body = std::fs::read_to_string(&file).unwrap();
    runtime().block_on(async {
        let (mut a, _) = try_ws(&srv.addr, Some(&tokens[0]), &[]).await.expect("alice connects");
        ok(&mut a, json!({"type": "subscribe", "id": 1, "streams": ["tip"]})).await;
        ok(&mut a, json!({"type": "take_lease", "id": 2})).await;
        let before = frames_in(&mut a, 1.5).await;

        std::fs::remove_file(&file).unwrap();
        mkfifo(&file);
        // Past the settling (1 s) and a few polls: the watcher has looked at the FIFO.
        tokio::time::sleep(Duration::from_millis(2000)).await;
        let during = frames_in(&mut a, 1.5).await;
        assert!(
            during >= before * 2 / 3,
            "telemetry fell from {before} to {during} frames in 1.5 s with a FIFO as the token file"
        );
        let bearer = vec![format!("Authorization: Bearer {}", tokens[1])];
        for path in ["/metrics", "/api/status", "/metrics"] {
            let headers: &[String] = if path == "/metrics" { &[] } else { &bearer };
            let t0 = Instant::now();
            let answer = http_within(&srv.addr, path, headers, 2.0);
            assert_eq!(
                answer.as_ref().map(|a| a.0),
                Some(200),
                "GET {path} not answered within 2 s (after {:.1} s) with a FIFO as the token file",
                t0.elapsed().as_secs_f64()
            );
        }
        let t0 = Instant::now();
        let joined = tokio::time::timeout(Duration::from_secs(2), try_ws(&srv.addr, Some(&tokens[1]), &[])).await;
        assert!(
            matches!(joined, Ok(Ok(_))),
            "bob could not connect within 2 s ({:.1} s)",
            t0.elapsed().as_secs_f64()
        );
        assert_eq!(metric(&srv.addr, "nanopush_auth_token_file_ok"), 0.0);
        let log = std::fs::read_to_string(srv.dir.join("server.log")).unwrap();
        assert!(log.contains("not a regular file"), "the log does not say why:\n{log}");

        // Put back without alice's line: the revocation is applied.
        std::fs::remove_file(&file).unwrap();
        let without: String = body
            .lines()
            .filter(|l| !l.starts_with("alice "))
            .map(|l| format!("{l}\n"))
            .collect();
        std::fs::write(&file, without).unwrap();
        let why = until(&mut a, 10.0, |m| is(m, "error") && m["id"].is_null()).await;
        assert!(
            why["message"]
                .as_str()
                .unwrap()
                .contains("the token of alice was revoked"),
            "{why}"
        );
        assert_eq!(metric(&srv.addr, "nanopush_auth_token_file_ok"), 1.0);
    });
}

/// A FIFO given as the token file at start (where the start once hung, silently) stops the start
/// within 10 s with an error that names the file and says it is not a regular file.
#[test]
fn a_fifo_as_the_token_file_at_start_is_refused_with_why() {
    let dir = crate::util::tmp("fifo-start");
    let file = dir.join("tokens");
    mkfifo(&file);
    let mut child = std::process::Command::new(nanopush_e2e::bin("nanopush"))
        .current_dir(nanopush_e2e::workspace())
        .args(["serve", "--port", "0", "--haptic", "none", "--token-file"])
        .arg(&file)
        .arg("--data-dir")
        .arg(dir.join("records"))
        .stdout(std::process::Stdio::null())
        .stderr(std::fs::File::create(dir.join("server.log")).unwrap())
        .spawn()
        .unwrap();
    let t0 = Instant::now();
    let exited = loop {
        if let Some(st) = child.try_wait().unwrap() {
            break Some(st);
        }
        if t0.elapsed() > Duration::from_secs(10) {
            break None;
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    if exited.is_none() {
        nanopush_e2e::stop(&mut child);
        let _ = wait_exit(&mut child, 5.0);
    }
    let log = std::fs::read_to_string(dir.join("server.log")).unwrap_or_default();
    let _ = std::fs::remove_dir_all(&dir);
    let st = exited.unwrap_or_else(|| panic!("the server was still starting after 10 s:\n{log}"));
    assert!(
        !st.success(),
        "the server started with a FIFO as its token file:\n{log}"
    );
    assert!(
        log.contains(file.to_str().unwrap()) && log.contains("not a regular file"),
        "{log}"
    );
}
