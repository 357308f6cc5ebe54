//! `nanopush serve` against careless and hostile clients: telemetry not delayed by
//! commands, records served safely, big messages refused with the connection kept, replies never
//! lost, the operator never locked out, slow, dead and stalled connections closed.

use std::io::{Read, Write};
use std::net::TcpStream;
use std::time::{Duration, Instant};

use futures_util::{SinkExt, StreamExt};
use nanopush_e2e::client::{text_frame, upgrade_request};
use serde_json::json;
use tokio_tungstenite::tungstenite::Message;

use crate::util::{TOKEN, Ws, http_get, is, ok, reply, runtime, send, start, start_with, status, until, welcomed};

/// A client that sends commands does not delay its own telemetry (the sockets have
/// TCP_NODELAY; without it each message holds the next frames back 25-45 ms, Nagle against a
/// delayed ACK). With a ping every 100 ms, the frame gap that spans each ping is judged: their
/// median stays within 12 ms of the stream's period. A median over 40 pings, not a percentile of
/// every gap, so that a loaded test machine's stray late frames do not decide it.
#[test]
fn commands_do_not_delay_telemetry() {
    let srv = start("nodelay", &[]);
    runtime().block_on(async {
        let (mut ws, _) = welcomed(&srv.addr, None).await;
        send(&mut ws, json!({"type": "subscribe", "id": 1, "streams": ["tip"]})).await;
        reply(&mut ws, 1).await;
        let mut arrivals = Vec::new();
        let mut pings = Vec::new();
        let mut next_ping = Instant::now();
        let end = Instant::now() + Duration::from_secs(4);
        let mut id = 10;
        while Instant::now() < end {
            if Instant::now() >= next_ping {
                pings.push(Instant::now());
                send(&mut ws, json!({"type": "ping", "id": id})).await;
                id += 1;
                next_ping += Duration::from_millis(100);
            }
            let wait = next_ping.saturating_duration_since(Instant::now());
            if let Ok(Some(Ok(Message::Text(t)))) = tokio::time::timeout(wait, ws.next()).await
                && t.contains("\"telemetry\"")
            {
                arrivals.push(Instant::now());
            }
        }
        assert!(arrivals.len() > 150, "{} frames", arrivals.len());
        // For each ping, the gap between the last frame before it and the first after it.
        let mut spans: Vec<f64> = pings
            .iter()
            .filter_map(|&p| {
                let after = arrivals.iter().position(|&a| a > p)?;
                (after > 0).then(|| (arrivals[after] - arrivals[after - 1]).as_secs_f64())
            })
            .collect();
        assert!(spans.len() >= 30, "{} pings spanned", spans.len());
        spans.sort_by(f64::total_cmp);
        let median = spans[spans.len() / 2];
        let period = 1.0 / 60.0;
        assert!(
            median < period + 12e-3,
            "median gap across a ping {:.1} ms against a {:.1} ms period",
            median * 1e3,
            period * 1e3
        );
    });
}

/// No symlink is served or listed out of the data directory; tokens in a query are
/// decoded; `.partial` files an earlier run left are removed at start; and a record that cannot
/// be written is reported with the reason, not as a silent `null`.
#[test]
fn records_are_served_safely_and_write_failures_say_why() {
    let srv = start_with(
        "files",
        |records| {
            std::fs::write(records.join("push-1-r1-p1.csv.partial"), b"half a trace").unwrap();
            std::os::unix::fs::symlink("/etc/hostname", records.join("push-9-r9-p9.csv")).unwrap();
        },
        &["--viewer-token", "tok+en/1"],
    );
    let records = srv.dir.join("records");
    let deadline = Instant::now() + Duration::from_secs(5);
    while records.join("push-1-r1-p1.csv.partial").exists() {
        assert!(Instant::now() < deadline, "the .partial file was not cleaned at start");
        std::thread::sleep(Duration::from_millis(20));
    }
    // The token, percent-encoded as a browser sends it.
    assert_eq!(http_get(&srv.addr, "/api/status?token=tok%2Ben%2F1").0, 200);
    assert_eq!(
        http_get(&srv.addr, "/api/status?token=tok+en/1").0,
        401,
        "'+' is a space"
    );
    let (code, body) = http_get(&srv.addr, "/api/records?token=tok%2Ben%2F1");
    assert_eq!(code, 200);
    assert!(
        !String::from_utf8_lossy(&body).contains("push-9"),
        "a symlink is listed"
    );
    assert_eq!(
        http_get(&srv.addr, "/api/records/push-9-r9-p9.csv?token=tok%2Ben%2F1").0,
        404
    );
    // The data directory goes away under the server: the scan's record cannot be written.
    std::fs::remove_dir_all(&records).unwrap();
    std::fs::write(&records, b"not a directory").unwrap();
    runtime().block_on(async {
        let (mut op, _) = welcomed(&srv.addr, Some(TOKEN)).await;
        send(&mut op, json!({"type": "subscribe", "id": 1, "streams": ["scan"]})).await;
        reply(&mut op, 1).await;
        send(&mut op, json!({"type": "take_lease", "id": 2})).await;
        reply(&mut op, 2).await;
        ok(&mut op, json!({"type": "scan", "id": 3, "pixels": 8, "size_um": 4.0})).await;
        let done = until(&mut op, 30.0, |m| is(m, "scan_done")).await;
        assert!(done["record"].is_null(), "{done}");
        let why = done["record_error"]
            .as_str()
            .unwrap_or_else(|| panic!("no reason: {done}"));
        assert!(why.contains("records") && why.contains("os error"), "{why}");
    });
}

/// Messages of 65 KiB, 200 KiB and 5 MB each get `too_large` and the
/// connection stays (a ping sent before gets its `ok`, one sent after too); and a client that
/// sends 300 commands before reading any reply loses none of them (its queue holds 64: it is
/// slowed down, not answered with silence).
#[test]
fn big_messages_are_refused_and_no_reply_is_lost() {
    let srv = start("big", &["--max-rate", "10000"]);
    runtime().block_on(async {
        let (mut ws, _) = welcomed(&srv.addr, None).await;
        send(&mut ws, json!({"type": "ping", "id": 1})).await;
        for kib in [65usize, 200, 5 * 1024] {
            let text = format!(r#"{{"type":"ping","id":9,"pad":"{}"}}"#, "x".repeat(kib * 1024));
            ws.send(Message::Text(text.into())).await.unwrap();
        }
        send(&mut ws, json!({"type": "ping", "id": 2})).await;
        assert_eq!(reply(&mut ws, 1).await["type"], "ok");
        for _ in 0..3 {
            let e = until(&mut ws, 10.0, |m| is(m, "error")).await;
            assert_eq!(e["code"], "too_large", "{e}");
        }
        assert_eq!(reply(&mut ws, 2).await["type"], "ok");
        // 300 pings, not a reply read in between.
        for id in 100..400 {
            send(&mut ws, json!({"type": "ping", "id": id})).await;
        }
        every_ping_answered(&mut ws, 100..400).await;
    });
}

/// Viewers filling `--max-clients` never lock the operator out (the operator token
/// has places of its own), and one address cannot take every viewer place.
#[test]
fn viewers_never_lock_the_operator_out_and_one_address_has_a_limit() {
    let srv = start("reserve", &["--max-clients", "2", "--max-clients-per-address", "3"]);
    runtime().block_on(async {
        let (_a, _) = welcomed(&srv.addr, None).await;
        let (_b, _) = welcomed(&srv.addr, None).await;
        let e = tokio_tungstenite::connect_async(format!("ws://{}/ws", srv.addr))
            .await
            .unwrap_err();
        assert!(e.to_string().contains("503"), "{e}");
        // The operator still gets in, takes the lease and is answered.
        let (mut op, welcome) = welcomed(&srv.addr, Some(TOKEN)).await;
        assert_eq!(welcome["role"], "operator");
        ok(&mut op, json!({"type": "take_lease", "id": 1})).await;
    });
    // Per address: a third viewer place is the address's limit here (3), a fourth is refused.
    let srv = start("peraddr", &["--max-clients", "100", "--max-clients-per-address", "3"]);
    runtime().block_on(async {
        let mut held = Vec::new();
        for _ in 0..3 {
            let (c, _) = welcomed(&srv.addr, None).await;
            held.push(c);
        }
        let e = tokio_tungstenite::connect_async(format!("ws://{}/ws", srv.addr))
            .await
            .unwrap_err();
        assert!(e.to_string().contains("429"), "{e}");
    });
}

/// docs/server.md, "The teleoperation server" (Roles): "the operator token has 8 places of its own". With the viewer cap full,
/// eight operator connections get in and a ninth is refused with 503; a viewer place is not an
/// operator place (`--max-clients 1`, taken by a viewer, leaves all eight).
#[test]
fn the_operator_token_has_its_own_places_and_one_more_is_refused() {
    let srv = start("operators", &["--max-clients", "1"]);
    runtime().block_on(async {
        let (_viewer, _) = welcomed(&srv.addr, None).await;
        let mut held = Vec::new();
        for _ in 0..8 {
            let (op, welcome) = welcomed(&srv.addr, Some(TOKEN)).await;
            assert_eq!(welcome["role"], "operator");
            held.push(op);
        }
        let url = format!("ws://{}/ws?token={TOKEN}", srv.addr);
        let e = tokio_tungstenite::connect_async(url).await.unwrap_err();
        assert!(e.to_string().contains("503"), "{e}");
    });
}

/// A slowloris client (headers that never finish) is closed after the header
/// time-out, fifty of them do not keep anyone else out, and a WebSocket peer that stops
/// answering pings is closed after the dead-peer time-out while a live one stays.
#[test]
fn slow_and_dead_connections_are_closed() {
    let srv = start(
        "slow",
        &["--header-timeout-s", "1", "--ws-ping-s", "0.5", "--ws-timeout-s", "1.5"],
    );
    let mut lorises: Vec<TcpStream> = (0..50)
        .map(|_| {
            let mut s = TcpStream::connect(&srv.addr).unwrap();
            s.write_all(b"GET /api/status HTTP/1.1\r\nHost: 127.0.0.1\r\nX-Slow: ")
                .unwrap();
            s
        })
        .collect();
    // Meanwhile a normal request is answered at once.
    assert_eq!(http_get(&srv.addr, "/api/status").0, 200);
    let t0 = Instant::now();
    for s in &mut lorises {
        s.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
        let mut buf = [0u8; 64];
        // Closed by the server (EOF or reset), not left hanging (a read time-out).
        let closed = match s.read(&mut buf) {
            Ok(n) => n == 0,
            Err(e) => !matches!(e.kind(), std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut),
        };
        assert!(closed, "a slowloris socket was answered or left open");
    }
    assert!(t0.elapsed() < Duration::from_secs(8), "closed after {:?}", t0.elapsed());
    runtime().block_on(async {
        let (mut live, _) = welcomed(&srv.addr, None).await;
        let (mut dead, _) = welcomed(&srv.addr, None).await;
        // The live peer keeps reading (tungstenite answers each ping); the dead one does not.
        let end = Instant::now() + Duration::from_secs(3);
        while Instant::now() < end {
            let _ = tokio::time::timeout(Duration::from_millis(100), live.next()).await;
        }
        ok(&mut live, json!({"type": "ping", "id": 5})).await;
        let mut ended = false;
        let deadline = Instant::now() + Duration::from_secs(5);
        while Instant::now() < deadline {
            match tokio::time::timeout(Duration::from_secs(1), dead.next()).await {
                Ok(None) | Ok(Some(Err(_))) | Ok(Some(Ok(Message::Close(_)))) => {
                    ended = true;
                    break;
                }
                _ => {}
            }
        }
        assert!(ended, "a peer that answered no ping was not closed");
    });
}

/// A TCP connection to `addr` whose receive buffer is as small as the kernel allows: the
/// server's socket toward it fills after a few kB.
fn small_buffer_socket(addr: &str) -> TcpStream {
    use std::os::fd::FromRawFd;
    let sa: std::net::SocketAddrV4 = addr.parse().unwrap();
    // SAFETY: a fresh socket, options set on it, connected, then owned by the TcpStream.
    unsafe {
        let fd = libc::socket(libc::AF_INET, libc::SOCK_STREAM, 0);
        assert!(fd >= 0);
        let small: libc::c_int = 2048;
        libc::setsockopt(
            fd,
            libc::SOL_SOCKET,
            libc::SO_RCVBUF,
            &small as *const _ as *const libc::c_void,
            std::mem::size_of::<libc::c_int>() as libc::socklen_t,
        );
        let sin = libc::sockaddr_in {
            sin_family: libc::AF_INET as libc::sa_family_t,
            sin_port: sa.port().to_be(),
            sin_addr: libc::in_addr {
                s_addr: u32::from(*sa.ip()).to_be(),
            },
            sin_zero: [0; 8],
        };
        let r = libc::connect(
            fd,
            &sin as *const _ as *const libc::sockaddr,
            std::mem::size_of::<libc::sockaddr_in>() as libc::socklen_t,
        );
        assert_eq!(r, 0, "connect");
        TcpStream::from_raw_fd(fd)
    }
}

/// A client socket with a tiny receive buffer (so a server that sends to it and is not read
/// fills it at once), upgraded to a WebSocket by hand, subscribed to telemetry.
fn stalled_subscriber(addr: &str) -> TcpStream {
    let mut s = small_buffer_socket(addr);
    s.write_all(upgrade_request(addr, "/ws").as_bytes()).unwrap();
    let mut head = Vec::new();
    let mut b = [0u8; 1];
    while !head.ends_with(b"\r\n\r\n") {
        s.read_exact(&mut b).unwrap();
        head.push(b[0]);
    }
    assert!(
        String::from_utf8_lossy(&head).contains("101"),
        "{}",
        String::from_utf8_lossy(&head)
    );
    let subscribe = br#"{"type":"subscribe","streams":["tip"]}"#;
    s.write_all(&text_frame(subscribe, [7, 1, 3, 9])).unwrap();
    s
}

/// A reader that stops reading is dropped once one frame has waited 5 s to be sent
/// (its socket full), and the others go on meanwhile.
#[test]
fn a_reader_that_stops_reading_is_dropped_without_slowing_the_others() {
    let srv = start("stalled", &["--telemetry-hz", "1000"]);
    let clients = |addr: &str| status(addr)["clients"].as_u64().unwrap();
    runtime().block_on(async {
        let (mut other, _) = welcomed(&srv.addr, None).await;
        send(&mut other, json!({"type": "subscribe", "id": 1, "streams": ["tip"]})).await;
        reply(&mut other, 1).await;
        let stalled = stalled_subscriber(&srv.addr);
        let deadline = Instant::now() + Duration::from_secs(30);
        let mut frames = 0;
        // The other client reads on; the stalled one is let go of within the budget.
        while clients(&srv.addr) > 1 {
            assert!(Instant::now() < deadline, "the stalled reader was never dropped");
            let end = Instant::now() + Duration::from_millis(200);
            while Instant::now() < end {
                if let Ok(Some(Ok(Message::Text(_)))) =
                    tokio::time::timeout(Duration::from_millis(50), other.next()).await
                {
                    frames += 1;
                }
            }
        }
        assert!(frames > 500, "the others waited: {frames} frames");
        drop(stalled);
        ok(&mut other, json!({"type": "ping", "id": 2})).await;
    });
}

/// The bytes the server's socket for the connection from local port `peer` holds unsent or
/// unacknowledged (`tx_queue` in `/proc/net/tcp`), or None before it is listed.
fn server_send_queue(server_port: u16, peer: u16) -> Option<u64> {
    let table = std::fs::read_to_string("/proc/net/tcp").unwrap();
    table.lines().skip(1).find_map(|l| {
        let f: Vec<&str> = l.split_whitespace().collect();
        let port = |a: &str| u16::from_str_radix(a.rsplit(':').next()?, 16).ok();
        (port(f[1])? == server_port && port(f[2])? == peer)
            .then(|| u64::from_str_radix(f[4].split(':').next()?, 16).ok())
            .flatten()
    })
}

/// A client whose socket is full (it reads slowly) and who sends 300 commands gets 300 replies:
/// the replies wait for room behind the blocked frame, none is dropped without a word.
#[test]
fn a_slow_readers_replies_wait_for_room_and_none_is_lost() {
    let srv = start(
        "backpressure",
        &[
            "--max-rate",
            "10000",
            "--telemetry-hz",
            "1000",
            "--scan-line-hz",
            "1000",
        ],
    );
    let server_port: u16 = srv.addr.rsplit(':').next().unwrap().parse().unwrap();
    runtime().block_on(async {
        let tcp = small_buffer_socket(&srv.addr);
        let peer = tcp.local_addr().unwrap().port();
        tcp.set_nonblocking(true).unwrap();
        let tcp = tokio_tungstenite::MaybeTlsStream::Plain(tokio::net::TcpStream::from_std(tcp).unwrap());
        let url = format!("ws://{}/ws?token={TOKEN}", srv.addr);
        let (mut ws, _) = tokio_tungstenite::client_async(url, tcp).await.unwrap();
        until(&mut ws, 5.0, |m| is(m, "welcome")).await;
        ok(
            &mut ws,
            json!({"type": "subscribe", "id": 1, "streams": ["tip", "scan"]}),
        )
        .await;
        ok(&mut ws, json!({"type": "take_lease", "id": 2})).await;
        ok(&mut ws, json!({"type": "scan", "id": 3, "pixels": 512})).await;
        // Read nothing until the server's socket toward us is full (2 MB here): its send queue
        // holds bytes and has stopped growing (the scan's 2 kB lines at 1 kHz and telemetry at
        // 1 kHz fill it in a few seconds).
        let deadline = Instant::now() + Duration::from_secs(30);
        let mut last = (0, Instant::now());
        loop {
            assert!(Instant::now() < deadline, "the server's socket never filled: {last:?}");
            tokio::time::sleep(Duration::from_millis(20)).await;
            let q = server_send_queue(server_port, peer).unwrap_or(0);
            if q != last.0 {
                last = (q, Instant::now());
            } else if q > 0 && last.1.elapsed() > Duration::from_millis(250) {
                break;
            }
        }
        for id in 100..400 {
            send(&mut ws, json!({"type": "ping", "id": id})).await;
        }
        // Now read (well within the 5 s a frame may wait): every ping is answered.
        every_ping_answered(&mut ws, 100..400).await;
    });
}

/// Reads until every ping of `ids` has its `ok` (an `error` reply fails), within 20 s.
async fn every_ping_answered(ws: &mut Ws, ids: std::ops::Range<u64>) {
    let mut seen = std::collections::HashSet::new();
    let deadline = Instant::now() + Duration::from_secs(20);
    let n = ids.clone().count();
    while seen.len() < n {
        let left = deadline.saturating_duration_since(Instant::now());
        let Ok(Some(Ok(msg))) = tokio::time::timeout(left, ws.next()).await else {
            panic!("{} of the {n} pings answered within 20 s", seen.len());
        };
        if let Message::Text(t) = msg {
            let m: serde_json::Value = serde_json::from_str(&t).unwrap();
            if is(&m, "ok") || is(&m, "error") {
                assert_eq!(m["type"], "ok", "{m}");
                seen.insert(m["id"].as_u64().unwrap());
            }
        }
    }
    assert!(ids.into_iter().all(|id| seen.contains(&id)));
}
