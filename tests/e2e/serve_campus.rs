//! `nanopush serve` as a careless or hostile client on a lab network finds it: the slowloris
//! guard without an upgrade bypass, records streamed and listed in pages,
//! a slow reader told `lagged` and kept, a data directory held by one server at a time and
//! checked at start, duplicate and inapplicable fields refused, the stage's edge as stated,
//! messages over 8 MiB closed with 1009, and a late joiner told that a push is being prepared.

use std::io::{Read, Write};
use std::net::TcpStream;
use std::time::{Duration, Instant};

use futures_util::{SinkExt, StreamExt};
use nanopush_e2e::client::upgrade_request;
use serde_json::{Value, json};
use tokio_tungstenite::tungstenite::Message;
use tokio_tungstenite::tungstenite::protocol::frame::coding::CloseCode;

use crate::util::{
    TOKEN, http, http_get, is, ok, operator, reply, runtime, send, start, start_scene, start_with, status, tmp, until,
    wait_exit, welcomed,
};

/// Reads one HTTP answer from `s` (its head, then `Content-Length` bytes of body): the head.
fn read_answer(s: &mut TcpStream) -> String {
    let mut head = Vec::new();
    let mut b = [0u8; 1];
    while !head.ends_with(b"\r\n\r\n") {
        assert_eq!(s.read(&mut b).unwrap(), 1, "closed inside the answer's head");
        head.push(b[0]);
    }
    let head = String::from_utf8_lossy(&head).to_ascii_lowercase();
    let len: usize = head
        .lines()
        .find_map(|l| l.strip_prefix("content-length:"))
        .map_or(0, |v| v.trim().parse().unwrap());
    let mut body = vec![0u8; len];
    s.read_exact(&mut body).unwrap();
    head
}

/// Whether the server closed `s` (EOF or reset) within 10 s, rather than leaving it open.
fn closed_by_server(s: &mut TcpStream) -> bool {
    s.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
    let mut buf = [0u8; 64];
    match s.read(&mut buf) {
        Ok(n) => n == 0,
        Err(e) => !matches!(e.kind(), std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut),
    }
}

/// A request that asks for `Upgrade: websocket` but is not upgraded (a plain route, or a refused
/// token) leaves the connection under the guard: the next request's headers must still arrive
/// within the header time-out (the header alone does not switch the guard off).
#[test]
fn an_upgrade_header_that_is_not_upgraded_leaves_the_slowloris_guard_on() {
    let srv = start("upgrade-bypass", &["--header-timeout-s", "1"]);
    let asks = [
        format!(
            "GET /api/status HTTP/1.1\r\nHost: {}\r\nConnection: Upgrade\r\nUpgrade: websocket\r\n\r\n",
            srv.addr
        ),
        upgrade_request(&srv.addr, "/ws?token=wrong"),
    ];
    for ask in asks {
        let mut s = TcpStream::connect(&srv.addr).unwrap();
        s.write_all(ask.as_bytes()).unwrap();
        let head = read_answer(&mut s);
        assert!(!head.starts_with("http/1.1 101"), "{head}");
        // The next request's headers never finish: the header time-out must close it.
        let _ = s.write_all(b"GET /api/status HTTP/1.1\r\nHost: 127.0.0.1\r\nX-Slow: ");
        assert!(closed_by_server(&mut s), "a socket after {head:?} was left open");
    }
    // A real upgrade is still left to the WebSocket's own keep-alive.
    runtime().block_on(async {
        let (mut ws, _) = welcomed(&srv.addr, None).await;
        tokio::time::sleep(Duration::from_millis(2500)).await;
        ok(&mut ws, json!({"type": "ping", "id": 1})).await;
    });
}

/// The server's resident memory (kB).
fn rss_kb(pid: u32) -> u64 {
    nanopush_e2e::procfs::status_field(&format!("/proc/{pid}/status"), "VmRSS").unwrap()
}

/// Downloads are streamed. Twelve clients that ask for a 32 MB record and do not read it cost
/// the server a few buffers each, not the file each (12 × 32 MB resident); and a client that
/// reads gets every byte.
#[test]
fn record_downloads_are_streamed_not_read_whole() {
    const MB: usize = 1 << 20;
    let name = "push-1-r1-p1.csv";
    let content: Vec<u8> = (0..32 * MB).map(|i| b"0123456789,\n"[i % 12]).collect();
    let srv = start_with("download", |dir| std::fs::write(dir.join(name), &content).unwrap(), &[]);
    let pid = srv.child.id();
    let before = rss_kb(pid);
    let mut idle: Vec<TcpStream> = (0..12)
        .map(|_| {
            let mut s = TcpStream::connect(&srv.addr).unwrap();
            s.write_all(format!("GET /api/records/{name} HTTP/1.1\r\nHost: {}\r\n\r\n", srv.addr).as_bytes())
                .unwrap();
            s
        })
        .collect();
    // Each has its answer's head: the server has opened the file for each.
    for s in &mut idle {
        let mut head = Vec::new();
        let mut b = [0u8; 1];
        while !head.ends_with(b"\r\n\r\n") {
            s.read_exact(&mut b).unwrap();
            head.push(b[0]);
        }
        assert!(String::from_utf8_lossy(&head).starts_with("HTTP/1.1 200"));
    }
    let grown_mb = rss_kb(pid).saturating_sub(before) / 1024;
    eprintln!("12 unread 32 MB downloads: the server grew by {grown_mb} MB");
    assert!(
        grown_mb < 100,
        "12 unread 32 MB downloads grew the server by {grown_mb} MB"
    );
    let (code, body) = http_get(&srv.addr, &format!("/api/records/{name}"));
    assert_eq!(code, 200);
    assert!(body == content, "the download differs ({} bytes)", body.len());
    drop(idle);
}

/// `/api/records` comes in pages (newest first; `limit`, `offset`, the total in
/// `X-Total-Count`), so 20,000 records are not one answer of megabytes; every record is reached
/// page by page, and bad paging values name the allowed range.
#[test]
fn the_record_listing_comes_in_pages() {
    let n = 20_000;
    let srv = start_with(
        "listing",
        |dir| {
            for i in 0..n {
                std::fs::write(dir.join(format!("scan-1-{i}.json")), b"{}").unwrap();
            }
        },
        &[],
    );
    let page = |query: &str| http(&srv.addr, "GET", &format!("/api/records{query}"), &[]);
    let (code, head, body) = page("");
    assert_eq!(code, 200, "{body}");
    let first: Value = serde_json::from_str(&body).unwrap();
    let first = first.as_array().unwrap();
    assert!(
        first.len() <= 1000 && !first.is_empty(),
        "{} entries in one answer",
        first.len()
    );
    assert!(head.contains(&format!("x-total-count: {n}")), "{head}");
    let mut seen = std::collections::HashSet::new();
    let mut offset = 0;
    loop {
        let (code, _, body) = page(&format!("?limit=1000&offset={offset}"));
        assert_eq!(code, 200);
        let v: Value = serde_json::from_str(&body).unwrap();
        let v = v.as_array().unwrap();
        if v.is_empty() {
            break;
        }
        assert!(v.len() <= 1000);
        for e in v {
            assert!(seen.insert(e["name"].as_str().unwrap().to_string()), "{e} twice");
        }
        offset += v.len();
    }
    assert_eq!(seen.len(), n);
    let (code, _, why) = page("?limit=0");
    assert_eq!(code, 400);
    assert!(why.contains("limit") && why.contains("[1, 1000]"), "{why}");
}

/// A viewer that reads 15 messages a second (telemetry at 60 Hz) is told what it missed
/// with `lagged` and gets recent frames, and stays connected: it answers every ping, late only
/// by what it has not read yet. Checked by the frames' numbers: the slow reader's newest frame
/// is within 5 s (300 frames) of a fast reader's, and every number it passed over was announced.
#[test]
fn a_slow_reader_is_told_it_lagged_and_is_not_closed() {
    let srv = start(
        "slow-reader",
        &["--telemetry-hz", "60", "--ws-ping-s", "0.5", "--ws-timeout-s", "10"],
    );
    runtime().block_on(async {
        let (mut fast, _) = welcomed(&srv.addr, None).await;
        ok(&mut fast, json!({"type": "subscribe", "id": 1, "streams": ["tip"]})).await;
        let (mut slow, _) = welcomed(&srv.addr, None).await;
        ok(&mut slow, json!({"type": "subscribe", "id": 1, "streams": ["tip"]})).await;
        let fast_task = tokio::spawn(async move {
            let mut newest = 0u64;
            let end = Instant::now() + Duration::from_secs(20);
            while Instant::now() < end {
                if let Ok(Some(Ok(Message::Text(t)))) =
                    tokio::time::timeout(Duration::from_millis(100), fast.next()).await
                {
                    let v: Value = serde_json::from_str(&t).unwrap();
                    if is(&v, "telemetry") {
                        newest = newest.max(v["seq"].as_u64().unwrap());
                    }
                }
            }
            (newest, fast)
        });
        let (mut last_seq, mut skipped_total, mut received, mut first_seq) = (0u64, 0u64, 0u64, 0u64);
        let mut announced_gaps = 0u64;
        let mut pending_skip = 0u64;
        let end = Instant::now() + Duration::from_secs(20);
        while Instant::now() < end {
            tokio::time::sleep(Duration::from_millis(66)).await;
            match tokio::time::timeout(Duration::from_secs(5), slow.next()).await {
                Ok(Some(Ok(Message::Text(t)))) => {
                    let v: Value = serde_json::from_str(&t).unwrap();
                    if is(&v, "lagged") {
                        let k = v["skipped"].as_u64().unwrap();
                        skipped_total += k;
                        pending_skip += k;
                    } else if is(&v, "telemetry") {
                        let seq = v["seq"].as_u64().unwrap();
                        if first_seq == 0 {
                            first_seq = seq;
                        } else if seq != last_seq + 1 {
                            // A gap: announced by the `lagged` just before, exactly.
                            assert_eq!(
                                seq - last_seq - 1,
                                pending_skip,
                                "a gap of {} after {last_seq} not announced",
                                seq - last_seq - 1
                            );
                            announced_gaps += 1;
                        }
                        pending_skip = 0;
                        last_seq = seq;
                        received += 1;
                    }
                }
                Ok(Some(Ok(Message::Close(c)))) => panic!("the slow reader was closed: {c:?}"),
                Ok(Some(Ok(_))) => {}
                other => panic!("the slow reader's socket ended: {other:?}"),
            }
        }
        let (fast_newest, _fast) = fast_task.await.unwrap();
        eprintln!(
            "slow reader: {received} frames read, {skipped_total} skipped in {announced_gaps} gaps, newest {} frames behind",
            fast_newest.saturating_sub(last_seq)
        );
        assert!(
            skipped_total > 0 && announced_gaps > 0,
            "never told it lagged ({received} frames)"
        );
        assert!(
            fast_newest.saturating_sub(last_seq) < 300,
            "the slow reader's newest frame is {} frames ({:.0} s) behind",
            fast_newest - last_seq,
            (fast_newest - last_seq) as f64 / 60.0
        );
        // Still connected, and answered.
        send(&mut slow, json!({"type": "ping", "id": 9})).await;
        let r = until(&mut slow, 30.0, |m| is(m, "ok") && m["id"] == 9).await;
        assert_eq!(r["type"], "ok");
    });
}

/// One data directory, one server. A second server given a data directory a live server holds
/// refuses to start and names it (else it would delete the first one's unfinished trace and
/// write records of the same names); the first one's records go on. Record names carry
/// the server run (`welcome`'s `instance`), so two runs never write the same name.
#[test]
fn a_data_directory_is_held_by_one_server_and_record_names_name_the_run() {
    let srv = start("held-dir", &[]);
    let records = srv.dir.join("records");
    let unfinished = records.join("push-1-r1-p1.csv.partial");
    std::fs::write(&unfinished, b"leg,t_s\n").unwrap();
    let log = srv.dir.join("second.log");
    let mut second = std::process::Command::new(nanopush_e2e::bin("nanopush"));
    second
        .current_dir(nanopush_e2e::workspace())
        .args(["serve", "--port", "0", "--haptic", "none", "--data-dir"])
        .arg(&records)
        .stdout(std::process::Stdio::null())
        .stderr(std::fs::File::create(&log).unwrap());
    let mut child = second.spawn().unwrap();
    let st = wait_exit(&mut child, 30.0);
    assert!(!st.success(), "a second server started on a held data directory");
    let err = std::fs::read_to_string(&log).unwrap();
    assert!(
        err.contains(&records.display().to_string()) && err.contains("another nanopush serve"),
        "{err}"
    );
    assert!(
        unfinished.exists(),
        "the second server removed the first one's .partial trace"
    );
    runtime().block_on(async {
        let (mut op, welcome) = welcomed(&srv.addr, Some(TOKEN)).await;
        let instance = welcome["instance"].as_str().unwrap().to_string();
        send(&mut op, json!({"type": "subscribe", "id": 1, "streams": ["scan"]})).await;
        reply(&mut op, 1).await;
        ok(&mut op, json!({"type": "take_lease", "id": 2})).await;
        ok(&mut op, json!({"type": "scan", "id": 3, "pixels": 8, "size_um": 4.0})).await;
        let done = until(&mut op, 60.0, |m| is(m, "scan_done")).await;
        let record = done["record"].as_str().unwrap_or_else(|| panic!("{done}"));
        assert!(record.contains(&instance), "{record} does not name the run {instance}");
    });
}

/// The data directory stays held when its lock file is deleted (`rm DATA/.nanopush.lock`): a
/// second server given it still refuses to start, and the first one's unfinished `.partial` trace
/// is still there (the lock is on the directory, which a removed path cannot release).
#[test]
fn a_deleted_lock_file_does_not_let_a_second_server_in() {
    let srv = start("held-unlinked", &[]);
    let records = srv.dir.join("records");
    let unfinished = records.join("push-1-r1-p1.csv.partial");
    std::fs::write(&unfinished, b"leg,t_s\n").unwrap();
    std::fs::remove_file(records.join(".nanopush.lock")).unwrap();
    let log = srv.dir.join("second.log");
    let mut child = std::process::Command::new(nanopush_e2e::bin("nanopush"))
        .current_dir(nanopush_e2e::workspace())
        .args(["serve", "--port", "0", "--haptic", "none", "--data-dir"])
        .arg(&records)
        .stdout(std::process::Stdio::null())
        .stderr(std::fs::File::create(&log).unwrap())
        .spawn()
        .unwrap();
    // It refuses within seconds; one that starts removes the `.partial` at once, or runs on.
    let deadline = Instant::now() + Duration::from_secs(15);
    let st = loop {
        if let Some(st) = child.try_wait().unwrap() {
            break Some(st);
        }
        if Instant::now() > deadline || !unfinished.exists() {
            break None;
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    let err = std::fs::read_to_string(&log).unwrap();
    if st.is_none() {
        nanopush_e2e::stop(&mut child);
    }
    assert!(
        unfinished.exists(),
        "the second server removed the first one's .partial trace:\n{err}"
    );
    let st =
        st.unwrap_or_else(|| panic!("a second server runs on a data directory whose lock file was deleted:\n{err}"));
    assert!(!st.success());
    assert!(err.contains("another nanopush serve"), "{err}");
}

/// A data directory the server cannot write is found at start, with a clear error that names it
/// (not at the first record). As root (who writes
/// through permissions) the directory is one of `/proc`, which nobody can write.
#[test]
fn a_data_directory_that_cannot_be_written_stops_the_start() {
    let dir = tmp("readonly");
    let records = if unsafe { libc::geteuid() } == 0 {
        std::path::PathBuf::from("/proc/self/fdinfo")
    } else {
        let r = dir.join("records");
        std::fs::create_dir_all(&r).unwrap();
        let mut p = std::fs::metadata(&r).unwrap().permissions();
        std::os::unix::fs::PermissionsExt::set_mode(&mut p, 0o555);
        std::fs::set_permissions(&r, p).unwrap();
        r
    };
    let log = dir.join("server.log");
    let mut child = std::process::Command::new(nanopush_e2e::bin("nanopush"))
        .current_dir(nanopush_e2e::workspace())
        .args(["serve", "--port", "0", "--haptic", "none", "--data-dir"])
        .arg(&records)
        .stdout(std::process::Stdio::null())
        .stderr(std::fs::File::create(&log).unwrap())
        .spawn()
        .unwrap();
    let st = wait_exit(&mut child, 30.0);
    let err = std::fs::read_to_string(&log).unwrap();
    assert!(
        !st.success(),
        "the server started on a data directory it cannot write: {err}"
    );
    assert!(
        err.contains(&records.display().to_string()) && err.contains("cannot be written"),
        "{err}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// A key given twice is refused as `malformed`, naming the key, and nothing happens (were the
/// last one to win, `{"type":"ping","type":"stop"}` would stop a push).
#[test]
fn duplicate_keys_are_refused_naming_the_key() {
    let srv = start("dupkeys", &[]);
    runtime().block_on(async {
        let mut op = operator(&srv.addr, "tip").await;
        for (text, key) in [
            (r#"{"type":"ping","type":"stop","id":5}"#, "type"),
            (
                r#"{"type":"push","id":5,"particle":1,"distance_um":1,"direction_deg":0,"direction_deg":90}"#,
                "direction_deg",
            ),
            (r#"{"type":"subscribe","id":5,"streams":["tip"],"id":6}"#, "id"),
        ] {
            op.send(Message::Text(text.into())).await.unwrap();
            let e = until(&mut op, 10.0, |m| {
                is(m, "error") || is(m, "ok") || is(m, "push_started")
            })
            .await;
            assert_eq!(e["code"], "malformed", "{text}: {e}");
            let why = e["message"].as_str().unwrap();
            assert!(
                why.contains(&format!("\"{key}\"")) && why.contains("more than once"),
                "{why}"
            );
        }
        assert_eq!(status(&srv.addr)["busy"], false, "a refused push ran");
    });
}

/// A field that does not belong to the command is refused, naming it (not dropped without a
/// word); a stream is a name, not an object.
#[test]
fn inapplicable_fields_are_refused_naming_the_field() {
    let srv = start("inapplicable", &[]);
    runtime().block_on(async {
        let mut op = operator(&srv.addr, "tip").await;
        for (cmd, field) in [
            (
                json!({"type": "haptic", "id": 3, "action": "recenter", "nm_per_mm": -5}),
                "nm_per_mm",
            ),
            (
                json!({"type": "haptic", "id": 4, "action": "engage", "pull_off_at_hand_n": 1e300}),
                "pull_off_at_hand_n",
            ),
            (
                json!({"type": "haptic", "id": 5, "action": "release", "nm_per_mm": 1.0}),
                "nm_per_mm",
            ),
        ] {
            send(&mut op, cmd.clone()).await;
            let r = reply(&mut op, cmd["id"].as_u64().unwrap() as u32).await;
            assert_eq!(r["type"], "error", "{cmd}: {r}");
            assert_eq!(r["code"], "invalid", "{cmd}: {r}");
            assert!(r["message"].as_str().unwrap().contains(field), "{r}");
        }
        send(
            &mut op,
            json!({"type": "subscribe", "id": 6, "streams": [{"tip": null}]}),
        )
        .await;
        let r = reply(&mut op, 6).await;
        assert_eq!(r["code"], "malformed", "{r}");
        let why = r["message"].as_str().unwrap();
        assert!(why.contains("tip") && why.contains("scan"), "{why}");
    });
}

/// A message over 8 MiB closes the connection with 1009 (message too big), as the
/// protocol says, not a bare end of stream.
#[test]
fn a_message_over_the_hard_cap_is_closed_as_too_big() {
    let srv = start("huge", &[]);
    runtime().block_on(async {
        let (ws, _) = welcomed(&srv.addr, None).await;
        let (mut tx, mut rx) = ws.split();
        let huge = format!(r#"{{"type":"ping","pad":"{}"}}"#, "x".repeat(9 << 20));
        let sending = tokio::spawn(async move {
            let _ = tx.send(Message::Text(huge.into())).await;
            tx
        });
        let deadline = Instant::now() + Duration::from_secs(30);
        let code = loop {
            let left = deadline.saturating_duration_since(Instant::now());
            match tokio::time::timeout(left, rx.next()).await {
                Ok(Some(Ok(Message::Close(c)))) => break c.map(|c| c.code),
                Ok(Some(Ok(_))) => {}
                other => panic!("the connection ended without a close frame: {other:?}"),
            }
        };
        assert_eq!(code, Some(CloseCode::Size));
        sending.abort();
    });
}

/// The fast scene with `extra` particles on a 5 µm grid away from the three it has.
fn crowded(extra: usize) -> String {
    let mut s = String::new();
    let mut id = 4;
    'grid: for i in 0..19 {
        for j in 0..19 {
            let (x, y) = (5.0 + 5.0 * i as f64, 5.0 + 5.0 * j as f64);
            if [(40.0, 30.0), (55.0, 62.0), (70.0, 45.0)]
                .iter()
                .any(|(px, py): &(f64, f64)| (px - x).hypot(py - y) < 4.0)
            {
                continue;
            }
            s.push_str(&format!(
                "\n[[particles]]\nid = {id}\nmaterial = \"gold-coated polystyrene latex\"\nradius_nm = 500.0\nx_um = {x}\ny_um = {y}\nyoungs_modulus_gpa = 3.4\npoisson_ratio = 0.34\ndensity_kg_per_m3 = 1050.0\nhamaker_zj = 400.0\n"
            ));
            id += 1;
            if id > extra + 3 {
                break 'grid;
            }
        }
    }
    s
}

/// While a push is being prepared (a crowded sample takes seconds), a client
/// that joins is told so: its `state` says `preparing`, not `idle`.
#[test]
fn a_late_joiner_is_told_a_push_is_being_prepared() {
    let particles = crowded(340);
    let srv = start_scene(
        "preparing",
        &[("[environment]", &format!("{particles}\n[environment]"))],
    );
    runtime().block_on(async {
        let mut op = operator(&srv.addr, "tip").await;
        ok(
            &mut op,
            json!({"type": "push", "id": 3, "particle": 1, "distance_um": 2.0, "direction_deg": 0}),
        )
        .await;
        let (mut late, _) = welcomed(&srv.addr, None).await;
        let state = until(&mut late, 10.0, |m| is(m, "state")).await;
        // Either still being prepared, or (on a fast machine) already running with its path.
        let phase = state["phase"].as_str().unwrap();
        assert!(
            phase == "preparing" || !state["push"].is_null(),
            "a late joiner sees {phase} while a push is prepared (push: {})",
            state["push"]
        );
        assert_ne!(phase, "idle");
        ok(&mut op, json!({"type": "stop", "id": 4})).await;
        until(&mut op, 60.0, |m| is(m, "run_done")).await;
    });
}

/// The slowloris guard bounds how long a socket that sends no headers lives, not how many there
/// are; at the soft limit of 1024 open files, one client holding ~1100 half-open TLS handshakes
/// would make `/api/status` time out for everyone. Started with a soft limit
/// of 1024, the server raises it to the hard limit.
#[test]
fn the_server_raises_its_open_files_limit_to_the_hard_limit() {
    use std::os::unix::process::CommandExt as _;
    let dir = crate::util::tmp("nofile");
    let (mut child, _addr) = crate::util::spawn_serve(&dir.join("server.log"), |c| {
        c.args(["--haptic", "none", "--operator-token", "nofile-token", "--data-dir"])
            .arg(dir.join("records"));
        // SAFETY: only setrlimit, async-signal-safe, between fork and exec.
        unsafe {
            c.pre_exec(|| {
                let mut lim = libc::rlimit {
                    rlim_cur: 0,
                    rlim_max: 0,
                };
                libc::getrlimit(libc::RLIMIT_NOFILE, &mut lim);
                lim.rlim_cur = lim.rlim_max.min(1024);
                libc::setrlimit(libc::RLIMIT_NOFILE, &lim);
                Ok(())
            });
        }
    });
    let limits = std::fs::read_to_string(format!("/proc/{}/limits", child.id())).unwrap();
    nanopush_e2e::stop(&mut child);
    let line = limits
        .lines()
        .find(|l| l.starts_with("Max open files"))
        .expect("a Max open files line");
    // "Max open files SOFT HARD files": the hard limit here is above 1024 (else nothing to raise).
    let v: Vec<&str> = line.split_whitespace().collect();
    assert_eq!(v[3], v[4], "{line}");
}

/// hyper accepts a request whose lines end in a bare LF, and upgrades it; the slowloris guard
/// only recognises the end of a header block as CRLF CRLF, so the upgraded WebSocket stays
/// under the header time-out and is cut after it, although the client is alive.
#[test]
fn a_websocket_upgraded_from_bare_lf_headers_outlives_the_header_timeout() {
    let srv = start("campus-lf", &["--header-timeout-s", "1"]);
    let mut s = TcpStream::connect(&srv.addr).unwrap();
    let req = format!(
        "GET /ws HTTP/1.1\nHost: {}\nUpgrade: websocket\nConnection: Upgrade\nSec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\nSec-WebSocket-Version: 13\n\n",
        srv.addr
    );
    s.write_all(req.as_bytes()).unwrap();
    s.set_read_timeout(Some(Duration::from_millis(200))).unwrap();
    let mut buf = [0u8; 4096];
    let n = s.read(&mut buf).unwrap();
    let head = String::from_utf8_lossy(&buf[..n]).to_string();
    assert!(head.starts_with("HTTP/1.1 101"), "{head}");
    // Alive for 3 header time-outs: a masked ping every 0.2 s, reading what comes.
    let t0 = Instant::now();
    while t0.elapsed() < Duration::from_secs(3) {
        s.write_all(&[0x89, 0x80, 0, 0, 0, 0]).unwrap();
        match s.read(&mut buf) {
            Ok(0) => panic!(
                "the server closed an upgraded WebSocket after {:.1} s (header time-out 1 s)",
                t0.elapsed().as_secs_f64()
            ),
            Ok(_) => {}
            Err(e) if matches!(e.kind(), std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut) => {}
            Err(e) => panic!("after {:.1} s: {e}", t0.elapsed().as_secs_f64()),
        }
    }
}

/// A target exactly on the edge the refusal states is answered `ok`, and not refused when the
/// push is planned with other bounds (the located radius's would be a fraction of a nanometre
/// off: `to_x_um: 1` on the paper scene, ok, then a `plan` run_done allowing [1.001, 98.999]).
#[test]
fn a_push_target_on_the_stated_edge_is_not_refused_when_planned() {
    use crate::util::{is, operator, reply, runtime, send, until};
    use serde_json::json;
    let srv = start("campus-edge", &[]);
    runtime().block_on(async {
        let mut op = operator(&srv.addr, "tip").await;
        send(
            &mut op,
            json!({"type": "push", "id": 3, "particle": 1, "to_x_um": 0.4, "to_y_um": 30.0}),
        )
        .await;
        let why = reply(&mut op, 3).await["message"].as_str().unwrap().to_string();
        let edges = why.split("allowed: [").nth(1).expect("the stated bounds").to_string();
        let (lo, hi) = edges.split_once(']').unwrap().0.split_once(", ").unwrap();
        let mut refused = Vec::new();
        for (id, x) in [(4, lo.parse::<f64>().unwrap()), (6, hi.parse::<f64>().unwrap())] {
            send(
                &mut op,
                json!({"type": "push", "id": id, "particle": 1, "to_x_um": x, "to_y_um": 30.0}),
            )
            .await;
            let r = reply(&mut op, id).await;
            assert_eq!(r["type"], "ok", "to_x_um {x}: {r}");
            let m = until(&mut op, 60.0, |m| is(m, "push_started") || is(m, "run_done")).await;
            if is(&m, "push_started") {
                send(&mut op, json!({"type": "stop", "id": id + 1})).await;
                until(&mut op, 60.0, |m| is(m, "run_done")).await;
            } else if m["outcome"] == "plan" {
                refused.push(format!("to_x_um {x}: {}", m["failure"]));
            }
        }
        assert!(
            refused.is_empty(),
            "stated: [{lo}, {hi}]; refused when planned: {refused:?}"
        );
    });
}
