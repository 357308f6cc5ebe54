//! Connections counted before anything is read from them. One address holds at most
//! `--max-connections-per-address` sockets (a trusted proxy excepted), all addresses together at
//! most `--max-connections` (below the open-files limit, so the server never runs out of
//! descriptors), and the lease holder's address has room of its own beyond both: one client with
//! a thousand silent sockets, or many, cannot keep the operator out.

use std::time::{Duration, Instant};

use serde_json::json;
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::TcpStream;

use crate::util::{TOKEN, is, ok, runtime, start, tmp, until};

/// This test process may open as many files as its hard limit allows (a thousand sockets and
/// more).
fn raise_own_open_files() {
    let mut lim = libc::rlimit {
        rlim_cur: 0,
        rlim_max: 0,
    };
    // SAFETY: getrlimit/setrlimit with a valid rlimit struct.
    unsafe {
        libc::getrlimit(libc::RLIMIT_NOFILE, &mut lim);
        lim.rlim_cur = lim.rlim_max;
        libc::setrlimit(libc::RLIMIT_NOFILE, &lim);
    }
}

/// A TCP connection to `addr` from the loopback address `from` (127.0.0.2, …: each its own client).
async fn connect_from(from: &str, addr: &str) -> std::io::Result<TcpStream> {
    let s = tokio::net::TcpSocket::new_v4()?;
    s.bind(format!("{from}:0").parse().unwrap())?;
    s.connect(addr.parse().unwrap()).await
}

/// Whether the server closed `s` within `secs` without a word (a connection refused before its
/// request is read), rather than leaving it open.
/// A socket from `from` that the server refuses: reset while it connects, or closed at once
/// after (which of the two depends on how far the handshake got before the close).
async fn refused_from(from: &'static str, addr: &str) -> bool {
    match connect_from(from, addr).await {
        Ok(mut s) => closed_at_once(&mut s, 2.0).await,
        Err(e) => e.kind() == std::io::ErrorKind::ConnectionReset,
    }
}

async fn closed_at_once(s: &mut TcpStream, secs: f64) -> bool {
    let mut b = [0u8; 1];
    matches!(
        tokio::time::timeout(Duration::from_secs_f64(secs), s.read(&mut b)).await,
        Ok(Ok(0)) | Ok(Err(_))
    )
}

/// Silent sockets from `from`, `n` of them kept open until `until`, each re-opened 100 ms after
/// the server closes it: how many times the server closed one.
async fn silent_sockets(from: &'static str, addr: String, n: usize, until: tokio::time::Instant) -> u64 {
    let slots = (0..n).map(|_| {
        let addr = addr.clone();
        async move {
            let mut closed = 0;
            while tokio::time::Instant::now() < until {
                let Ok(mut s) = connect_from(from, &addr).await else {
                    tokio::time::sleep(Duration::from_millis(100)).await;
                    continue;
                };
                let mut b = [0u8; 1];
                let _ = tokio::time::timeout_at(until, s.read(&mut b)).await;
                closed += 1;
                tokio::time::sleep(Duration::from_millis(100)).await;
            }
            closed
        }
    });
    futures_util::future::join_all(slots).await.into_iter().sum()
}

/// The operator's attempts against a flood: 2,100 silent TCP sockets from 127.0.0.1, re-opened
/// as the server closes them, at a server over TLS whose open-files limit is 1,024 (soft and
/// hard) and whose header time-out is 30 s. Each of the operator's 6 attempts from 127.0.0.2, a second apart (a TLS handshake and
/// `/api/status`), is answered within 5 s (3 of 6 timed out over 30 s, before).
#[test]
fn silent_sockets_from_one_address_do_not_keep_the_operator_out() {
    use std::os::unix::process::CommandExt as _;
    raise_own_open_files();
    let dir = tmp("conn-flood");
    let (_ca, cert, key) = crate::serve_tls::test_ca(&dir);
    let connector = crate::serve_tls::client(&dir.join("ca.pem"));
    let (mut child, addr) = crate::util::spawn_serve(&dir.join("server.log"), |c| {
        // Silent sockets live 30 s: longer than the test, as a slow network's would.
        c.args([
            "--haptic",
            "none",
            "--operator-token",
            TOKEN,
            "--header-timeout-s",
            "30",
            "--data-dir",
        ])
        .arg(dir.join("records"))
        .arg("--tls-cert")
        .arg(&cert)
        .arg("--tls-key")
        .arg(&key);
        // SAFETY: only setrlimit, async-signal-safe, between fork and exec.
        unsafe {
            c.pre_exec(|| {
                let lim = libc::rlimit {
                    rlim_cur: 1024,
                    rlim_max: 1024,
                };
                libc::setrlimit(libc::RLIMIT_NOFILE, &lim);
                Ok(())
            });
        }
    });
    let outcome = runtime().block_on(async {
        let end = tokio::time::Instant::now() + Duration::from_secs(9);
        let flood = tokio::spawn(silent_sockets("127.0.0.1", addr.clone(), 2100, end));
        // The flood has filled what it can.
        tokio::time::sleep(Duration::from_secs(2)).await;
        let mut took = Vec::new();
        for _ in 0..6 {
            let t0 = Instant::now();
            let attempt = async {
                let tcp = connect_from("127.0.0.2", &addr).await?;
                let name = rustls::pki_types::ServerName::try_from("127.0.0.1").unwrap();
                let mut s = connector.connect(name, tcp).await?;
                let req =
                    format!("GET /api/status?token={TOKEN} HTTP/1.1\r\nHost: {addr}\r\nConnection: close\r\n\r\n");
                s.write_all(req.as_bytes()).await?;
                let mut buf = Vec::new();
                let _ = s.read_to_end(&mut buf).await;
                std::io::Result::Ok(buf.starts_with(b"HTTP/1.1 200"))
            };
            let answered = matches!(
                tokio::time::timeout(Duration::from_secs(5), attempt).await,
                Ok(Ok(true))
            );
            took.push(answered.then(|| t0.elapsed().as_secs_f64()));
            tokio::time::sleep(Duration::from_secs(1).saturating_sub(t0.elapsed())).await;
        }
        let closed = flood.await.unwrap();
        (took, closed)
    });
    let log = std::fs::read_to_string(dir.join("server.log")).unwrap_or_default();
    nanopush_e2e::stop(&mut child);
    let _ = std::fs::remove_dir_all(&dir);
    let (took, closed) = outcome;
    eprintln!("the operator's attempts: {took:?} s; the flood's sockets closed by the server {closed} times");
    let failed = took.iter().filter(|t| t.is_none()).count();
    assert_eq!(
        failed,
        0,
        "{failed} of the operator's 6 attempts were not answered within 5 s ({took:?}):\n{}",
        log.lines().rev().take(20).collect::<Vec<_>>().join("\n")
    );
}

/// Room for the lease holder: with `--max-connections 300`, three addresses holding 128 silent
/// sockets each fill every place but the holder's; a new client from a fourth address is closed
/// before its request is read, while the lease holder's address still opens `/api/status` and a
/// second WebSocket, and, once its connection is gone, reconnects and takes the lease again.
#[test]
fn the_lease_holders_address_has_room_when_every_place_is_taken() {
    raise_own_open_files();
    let srv = start(
        "conn-reserve",
        &["--max-connections", "300", "--max-connections-per-address", "128"],
    );
    let addr = srv.addr.clone();
    runtime().block_on(async move {
        let ws_from = |from: &'static str| {
            let addr = addr.clone();
            async move {
                let tcp = connect_from(from, &addr).await.unwrap();
                let url = format!("ws://{addr}/ws?token={TOKEN}");
                let tcp = tokio_tungstenite::MaybeTlsStream::Plain(tcp);
                let (mut ws, _) = tokio_tungstenite::client_async(url, tcp).await.expect("upgrade");
                until(&mut ws, 5.0, |m| is(m, "welcome")).await;
                ws
            }
        };
        let mut op = ws_from("127.0.0.2").await;
        ok(&mut op, json!({"type": "take_lease", "id": 1})).await;
        let mut held = Vec::new();
        for from in ["127.0.0.3", "127.0.0.4", "127.0.0.5"] {
            for _ in 0..128 {
                if let Ok(s) = connect_from(from, &addr).await {
                    held.push(s);
                }
            }
        }
        // Each address's 129th, and a fourth address, are closed without a word.
        assert!(
            refused_from("127.0.0.3", &addr).await,
            "a 129th socket from 127.0.0.3 was kept"
        );
        assert!(
            refused_from("127.0.0.6", &addr).await,
            "a new address got a place with 3 × 128 + 1 of 300 taken"
        );
        // The lease holder's address is served.
        let mut s = connect_from("127.0.0.2", &addr).await.unwrap();
        s.write_all(format!("GET /api/status HTTP/1.1\r\nHost: {addr}\r\nConnection: close\r\n\r\n").as_bytes())
            .await
            .unwrap();
        let mut buf = Vec::new();
        tokio::time::timeout(Duration::from_secs(5), s.read_to_end(&mut buf))
            .await
            .expect("the holder's address answered within 5 s")
            .unwrap();
        assert!(buf.starts_with(b"HTTP/1.1 200"), "{}", String::from_utf8_lossy(&buf));
        let _second = ws_from("127.0.0.2").await;
        // Its connection gone (the lease freed), it comes back and takes the lease again.
        drop(op);
        tokio::time::sleep(Duration::from_millis(300)).await;
        let mut back = ws_from("127.0.0.2").await;
        ok(&mut back, json!({"type": "take_lease", "id": 2})).await;
        drop(held);
    });
    let refused = crate::serve_access::metric(&srv.addr, "nanopush_connections_refused_total");
    assert!(refused >= 2.0, "{refused} refusals counted");
}
