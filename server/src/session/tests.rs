//! The session's tests over plain channels (no network), and the clients and commands they share
//! with the tests of the lease, the receive loop and the table of commands.

use std::sync::Arc;
use std::sync::atomic::Ordering::Relaxed;
use std::time::{Duration, Instant};

use axum::extract::ws::Message;
use futures_util::SinkExt;
use nanopush_proto::ws::{ErrorCode, Role};

use super::*;
use crate::app_state::{OPERATOR_PLACES, test_state};
use crate::command_checks::Refusal;

/// A connected client's handling state.
pub(crate) fn client(id: u32, role: Role) -> Client {
    Client {
        id,
        role,
        person: person(role),
        addr: std::net::IpAddr::from([127, 0, 0, 1]),
        streams: HashSet::new(),
        tokens: 50.0,
        last: Instant::now(),
        ack_tokens: 120.0,
        ack_last: Instant::now(),
        acks: Arc::default(),
    }
}

/// Runs the command `json` for client `c` as the session does (its entry in the table: its
/// check, who may send it, its handler).
pub(crate) fn command(st: &Arc<AppState>, c: &mut Client, json: &str) -> Result<super::commands::Accepted, Refusal> {
    let msg = crate::command_checks::parse_command(json).expect("a command");
    super::commands::route(&msg).run(st, c, msg)
}

/// A person of `role` (named after it).
pub(crate) fn person(role: Role) -> Arc<crate::auth::Person> {
    Arc::new(crate::auth::Person {
        name: format!("{role:?}").to_lowercase(),
        role,
        key: "test".into(),
    })
}

/// Runs a session over channels; returns the client's outgoing side and incoming side.
fn connect(
    st: &Arc<AppState>,
    role: Role,
) -> (
    futures_channel::mpsc::UnboundedSender<Result<Message, std::convert::Infallible>>,
    futures_channel::mpsc::UnboundedReceiver<Message>,
    tokio::task::JoinHandle<()>,
) {
    let (to_server, from_client) = futures_channel::mpsc::unbounded();
    let (to_client, from_server) = futures_channel::mpsc::unbounded::<Message>();
    let peer = "127.0.0.1:9".parse().unwrap();
    let task = tokio::spawn(run(st.clone(), to_client, from_client, person(role), peer));
    (to_server, from_server, task)
}

/// The next text message, parsed, skipping pings; panics after 5 s.
async fn next_json(rx: &mut futures_channel::mpsc::UnboundedReceiver<Message>) -> serde_json::Value {
    loop {
        let m = tokio::time::timeout(Duration::from_secs(5), rx.next())
            .await
            .expect("a message within 5 s")
            .expect("the session is open");
        if let Message::Text(t) = m {
            return serde_json::from_str(t.as_str()).unwrap();
        }
    }
}

#[tokio::test]
async fn a_session_welcomes_and_frees_the_lease_when_the_peer_goes() {
    let st = test_state();
    let (mut tx, mut rx, task) = connect(&st, Role::Operator);
    let welcome = next_json(&mut rx).await;
    assert_eq!(welcome["type"], "welcome");
    assert_eq!(welcome["role"], "operator");
    let id = welcome["client"].as_u64().unwrap() as u32;
    assert_eq!(next_json(&mut rx).await["type"], "state");
    tx.send(Ok(Message::Text(r#"{"type":"take_lease","id":7}"#.into())))
        .await
        .unwrap();
    // The reply and the broadcast may come in either order.
    let (a, b) = (next_json(&mut rx).await, next_json(&mut rx).await);
    let (ok, lease) = if a["type"] == "ok" { (a, b) } else { (b, a) };
    assert_eq!(ok["id"], 7);
    assert_eq!(lease["type"], "lease");
    assert_eq!(lease["holder"], id);
    assert_eq!(st.lease_holder(), Some(id));
    // A command refused is answered with its id and code; the session goes on.
    tx.send(Ok(Message::Text(r#"{"type":"scan","id":8,"size_um":-1}"#.into())))
        .await
        .unwrap();
    let err = next_json(&mut rx).await;
    assert_eq!(
        (err["type"].as_str(), err["id"].as_u64()),
        (Some("error"), Some(8)),
        "{err}"
    );
    // The peer goes: the session ends and the lease is free.
    drop(tx);
    tokio::time::timeout(Duration::from_secs(5), task)
        .await
        .unwrap()
        .unwrap();
    assert_eq!(st.lease_holder(), None);
}

/// The first message says a push's tolerance as the server checks it: a page's form starts at
/// the default and refuses what the server would.
#[tokio::test]
async fn the_welcome_states_the_push_tolerance_the_server_checks() {
    let st = test_state();
    let (tx, mut rx, task) = connect(&st, Role::Viewer);
    let welcome = next_json(&mut rx).await;
    let said = &welcome["push_tolerance_nm"];
    let (lo, hi) = nanopush_proto::push::TOLERANCE_RANGE_NM;
    assert_eq!(
        *said,
        serde_json::json!({"default": nanopush_proto::push::TOLERANCE_NM, "min": lo, "max": hi})
    );
    let nm = |k: &str| said[k].as_f64().unwrap();
    let tolerance = crate::command_checks::push_tolerance;
    assert_eq!(tolerance(None), Ok(nm("default") * 1e-9));
    assert_eq!(tolerance(Some(nm("min"))), Ok(nm("min") * 1e-9));
    assert_eq!(tolerance(Some(nm("max"))), Ok(nm("max") * 1e-9));
    for past in [nm("min").next_down(), nm("max").next_up()] {
        assert_eq!(tolerance(Some(past)).unwrap_err().code, ErrorCode::OutOfRange, "{past}");
    }
    drop(tx);
    tokio::time::timeout(Duration::from_secs(5), task)
        .await
        .unwrap()
        .unwrap();
}

/// A viewer that subscribes to `scan` while a scan runs gets the lines so far first: it shows
/// the whole scan so far, not the lines after it joined.
#[tokio::test]
async fn subscribing_mid_scan_sends_the_lines_so_far() {
    let st = test_state();
    let frame = |line: u32| {
        let h = nanopush_proto::ws::ScanLineHeader {
            scan: 4,
            line,
            xres: 2,
            yres: 8,
            y: 0.0,
        };
        axum::body::Bytes::from(h.encode(&[line as f32, 0.5]))
    };
    st.activity.scan_lines.lock().unwrap().extend((0..3).map(frame));
    let (mut tx, mut rx, task) = connect(&st, Role::Viewer);
    next_json(&mut rx).await;
    next_json(&mut rx).await;
    tx.send(Ok(Message::Text(
        r#"{"type":"subscribe","id":1,"streams":["scan"]}"#.into(),
    )))
    .await
    .unwrap();
    let mut lines = Vec::new();
    let mut ok = false;
    while lines.len() < 3 || !ok {
        match tokio::time::timeout(Duration::from_secs(5), rx.next())
            .await
            .expect("within 5 s")
            .expect("open")
        {
            Message::Binary(b) => lines.push(b),
            Message::Text(t) => ok |= t.as_str().contains(r#""type":"ok""#),
            _ => {}
        }
    }
    assert_eq!(
        lines,
        (0..3).map(frame).collect::<Vec<_>>(),
        "lines 0, 1 and 2, in order"
    );
    drop(tx);
    tokio::time::timeout(Duration::from_secs(5), task)
        .await
        .unwrap()
        .unwrap();
}

#[tokio::test]
async fn a_viewers_subscription_is_counted_and_given_back() {
    let st = test_state();
    let (mut tx, mut rx, task) = connect(&st, Role::Viewer);
    next_json(&mut rx).await;
    next_json(&mut rx).await;
    tx.send(Ok(Message::Text(
        r#"{"type":"subscribe","id":1,"streams":["tip"]}"#.into(),
    )))
    .await
    .unwrap();
    assert_eq!(next_json(&mut rx).await["type"], "ok");
    assert_eq!(st.clients.tip_subscribers.load(Relaxed), 1);
    tx.send(Ok(Message::Text(r#"{"type":"take_lease","id":2}"#.into())))
        .await
        .unwrap();
    assert_eq!(next_json(&mut rx).await["code"], "forbidden");
    drop(tx);
    tokio::time::timeout(Duration::from_secs(5), task)
        .await
        .unwrap()
        .unwrap();
    assert_eq!(st.clients.tip_subscribers.load(Relaxed), 0);
}

#[tokio::test]
async fn a_shutdown_is_announced_and_the_socket_closed() {
    let st = test_state();
    let (_tx, mut rx, task) = connect(&st, Role::Viewer);
    next_json(&mut rx).await;
    next_json(&mut rx).await;
    st.channels.shutdown.send(true).unwrap();
    assert_eq!(next_json(&mut rx).await["type"], "shutdown");
    let close = tokio::time::timeout(Duration::from_secs(5), rx.next()).await.unwrap();
    assert!(
        matches!(close, Some(Message::Close(Some(ref f))) if f.code == 1001),
        "{close:?}"
    );
    tokio::time::timeout(Duration::from_secs(5), task)
        .await
        .unwrap()
        .unwrap();
}

/// docs/server.md, "The teleoperation server": the operator token's 8 places, idle HTTP connections
/// closed after 60 s, a 5 s send budget per frame, a client that reads no reply for 30 s
/// closed, messages up to 8 MiB refused with `too_large` (above it the connection closes),
/// SCHED_FIFO priority 50 for the loop. (The 8 places are also tested end to end:
/// `tests/e2e/serve_hostile.rs::the_operator_token_has_its_own_places_and_one_more_is_refused`.)
#[test]
fn the_server_limits_are_as_documented() {
    assert_eq!(OPERATOR_PLACES, 8);
    assert_eq!(crate::IDLE_HTTP, Duration::from_secs(60));
    assert_eq!(SEND_BUDGET, Duration::from_secs(5));
    assert_eq!(REPLY_PATIENCE, Duration::from_secs(30));
    assert_eq!(HARD_CAP, 8 * 1024 * 1024);
    assert_eq!(crate::control_loop::realtime::LOOP_PRIORITY, 50);
}
