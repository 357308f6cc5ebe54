//! What the end-to-end tests share: scratch directories, the `nanopush` CLI's JSON, a `nanopush
//! serve` on a free port (and the quick scene most of them run), its HTTP API and its WebSocket.
//! The crate's library (`nanopush_e2e`) has what the benchmarks share with them: the binaries,
//! stopping processes, the raw HTTP client.

use std::io::{Read, Write};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use futures_util::{SinkExt, StreamExt};
use nanopush_e2e::{bin, run, text, workspace};
use serde_json::{Value, json};
use tokio_tungstenite::tungstenite::Message;
use tokio_tungstenite::tungstenite::client::IntoClientRequest;

pub(crate) use nanopush_e2e::client::Ws;

/// The operator token the tests' servers are started with.
pub(crate) const TOKEN: &str = "e2e-operator-token";

// ---------------------------------------------------------------------------------------------
// Files and the command line.

/// A fresh, empty scratch directory `nanopush-e2e-{tag}-{pid}` in the system's temporary
/// directory (what an earlier run left there is removed first).
pub(crate) fn tmp(tag: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("nanopush-e2e-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// `nanopush ARGS`, which must succeed and print one JSON object: that object.
pub(crate) fn nanopush_json(args: &[&str]) -> Value {
    let o = run("nanopush", args, None);
    let (out, err) = text(&o);
    assert!(o.status.success(), "nanopush {args:?} failed: {err}");
    serde_json::from_str(&out).unwrap_or_else(|e| panic!("not one JSON object ({e}): {out}"))
}

// ---------------------------------------------------------------------------------------------
// The server.

/// Starts `nanopush serve --port 0` from the workspace root, with the arguments (and environment)
/// `configure` adds, its stderr to `log`: the child and the address it listens on.
pub(crate) fn spawn_serve(log: &Path, configure: impl FnOnce(&mut Command)) -> (Child, String) {
    let mut cmd = Command::new(bin("nanopush"));
    cmd.current_dir(workspace()).args(["serve", "--port", "0"]);
    configure(&mut cmd);
    let mut child = cmd
        .stdout(Stdio::piped())
        .stderr(std::fs::File::create(log).unwrap())
        .spawn()
        .expect("starting nanopush serve");
    let addr =
        nanopush_e2e::listening_addr(&mut child).unwrap_or_else(|first| panic!("unexpected first line {first:?}"));
    (child, addr)
}

/// A server on a free port, stopped on drop (its log shown if the test failed) and its
/// directory removed.
pub(crate) struct Server {
    pub(crate) child: Child,
    pub(crate) addr: String,
    pub(crate) dir: PathBuf,
}

impl Drop for Server {
    fn drop(&mut self) {
        nanopush_e2e::stop(&mut self.child);
        if std::thread::panicking() {
            // Show the server's log with the failure.
            let log = std::fs::read_to_string(self.dir.join("server.log")).unwrap_or_default();
            eprintln!("--- server log ---\n{log}");
        }
        let _ = std::fs::remove_dir_all(&self.dir);
    }
}

/// The gold-latex scene made quick for a test: a low start height, fast approaches and travel, a
/// short run-up and a level substrate (the push itself at the paper's 2 µm/s), so a whole push
/// takes a few seconds of real time; then each of `edits` `(from, to)` replaced once in its text.
fn fast_scene_with(dir: &Path, edits: &[(&str, &str)]) -> PathBuf {
    let text = std::fs::read_to_string(workspace().join("scenes/gold-latex-500nm.toml")).unwrap();
    let text = text.replacen("tilt_x_mrad = 6.0", "tilt_x_mrad = 0.0", 1).replacen(
        "roughness_rms_nm = 0.5",
        "roughness_rms_nm = 0.0",
        1,
    );
    let text = nanopush_e2e::with_strategy(
        &text,
        &[
            ("start_height_um", "1.2"),
            ("approach_speed_um_per_s", "5.0"),
            ("travel_speed_um_per_s", "40.0"),
            ("approach_distance_um", "0.3"),
            ("dwell_ms", "2.0"),
        ],
    );
    let text = format!("{text}\n[scan]\ncentre_x_um = 40.0\ncentre_y_um = 32.0\nsize_um = 16.0\npixels = 32\n");
    let mut text = text;
    for (from, to) in edits {
        assert!(text.contains(from), "the scene has {from:?}");
        text = text.replacen(from, to, 1);
    }
    let path = dir.join("fast.toml");
    std::fs::write(&path, text).unwrap();
    path
}

/// `nanopush serve` on the fast scene ([`fast_scene_with`]), without a haptic link, with the
/// operator token [`TOKEN`], its records in `records/` of its directory, and `extra` arguments.
pub(crate) fn start(tag: &str, extra: &[&str]) -> Server {
    start_with(tag, |_| {}, extra)
}

/// [`start`], with `prepare` run on the records directory (created) before the server starts.
pub(crate) fn start_with(tag: &str, prepare: impl FnOnce(&Path), extra: &[&str]) -> Server {
    start_edited(tag, &[], prepare, extra)
}

/// [`start`] on the fast scene with `edits` (see [`fast_scene_with`]).
pub(crate) fn start_scene(tag: &str, edits: &[(&str, &str)]) -> Server {
    start_edited(tag, edits, |_| {}, &[])
}

fn start_edited(tag: &str, edits: &[(&str, &str)], prepare: impl FnOnce(&Path), extra: &[&str]) -> Server {
    launch(tag, edits, prepare, |_| {
        let mut a: Vec<String> = vec!["--operator-token".into(), TOKEN.into()];
        a.extend(extra.iter().map(|s| s.to_string()));
        a
    })
}

/// [`start`] without the operator token [`TOKEN`], with the arguments `args` makes from the
/// server's directory (e.g. `--token-file DIR/tokens`, written there first).
pub(crate) fn start_args(tag: &str, args: impl FnOnce(&Path) -> Vec<String>) -> Server {
    launch(tag, &[], |_| {}, args)
}

fn launch(
    tag: &str,
    edits: &[(&str, &str)],
    prepare: impl FnOnce(&Path),
    args: impl FnOnce(&Path) -> Vec<String>,
) -> Server {
    let dir = tmp(&format!("serve-{tag}"));
    let scene = fast_scene_with(&dir, edits);
    let records = dir.join("records");
    std::fs::create_dir_all(&records).unwrap();
    prepare(&records);
    let extra = args(&dir);
    let (child, addr) = spawn_serve(&dir.join("server.log"), |c| {
        c.args(["--haptic", "none", "--scene"])
            .arg(&scene)
            .arg("--data-dir")
            .arg(&records)
            .args(&extra);
    });
    Server { child, addr, dir }
}

/// Waits (reaping it) until `child` has exited, within `secs`: its exit status.
pub(crate) fn wait_exit(child: &mut Child, secs: f64) -> std::process::ExitStatus {
    let deadline = Instant::now() + Duration::from_secs_f64(secs);
    loop {
        if let Some(st) = child.try_wait().unwrap() {
            return st;
        }
        assert!(Instant::now() < deadline, "the process did not exit within {secs} s");
        std::thread::sleep(Duration::from_millis(5));
    }
}

// ---------------------------------------------------------------------------------------------
// Its HTTP API.

/// A free TCP port on 127.0.0.1: nothing listens on it now.
pub(crate) fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

/// One HTTP/1.1 request with `headers` (each `Name: value`): the status, the head (lower-case)
/// and the body (de-chunked) as text.
pub(crate) fn http(addr: &str, method: &str, path: &str, headers: &[String]) -> (u16, String, String) {
    let mut s = std::net::TcpStream::connect(addr).unwrap();
    let mut req = format!("{method} {path} HTTP/1.1\r\nHost: {addr}\r\nConnection: close\r\nContent-Length: 0\r\n");
    for h in headers {
        req.push_str(h);
        req.push_str("\r\n");
    }
    req.push_str("\r\n");
    s.write_all(req.as_bytes()).unwrap();
    let mut buf = Vec::new();
    s.read_to_end(&mut buf).unwrap();
    let end = buf.windows(4).position(|w| w == b"\r\n\r\n").expect("an HTTP head");
    let head = String::from_utf8_lossy(&buf[..end]).to_ascii_lowercase();
    let (status, body) = nanopush_e2e::client::parse_response(&buf).unwrap();
    (status, head, String::from_utf8_lossy(&body).into_owned())
}

/// One HTTP/1.1 GET of `path` with `headers` (each `Name: value`), given `secs` to connect and
/// answer in all: the status and the body, or None when the server did not answer in time (a
/// server that froze fails the test instead of hanging it).
pub(crate) fn http_within(addr: &str, path: &str, headers: &[String], secs: f64) -> Option<(u16, String)> {
    let deadline = Instant::now() + Duration::from_secs_f64(secs);
    let left = || {
        deadline
            .saturating_duration_since(Instant::now())
            .max(Duration::from_millis(1))
    };
    let mut s = std::net::TcpStream::connect_timeout(&addr.parse().unwrap(), left()).ok()?;
    let mut req = format!("GET {path} HTTP/1.1\r\nHost: {addr}\r\nConnection: close\r\n");
    for h in headers {
        req.push_str(h);
        req.push_str("\r\n");
    }
    req.push_str("\r\n");
    s.set_write_timeout(Some(left())).ok()?;
    s.write_all(req.as_bytes()).ok()?;
    let mut buf = Vec::new();
    let mut chunk = [0u8; 16 * 1024];
    loop {
        s.set_read_timeout(Some(left())).ok()?;
        match s.read(&mut chunk) {
            Ok(0) => break,
            Ok(n) => buf.extend_from_slice(&chunk[..n]),
            Err(_) => return None,
        }
        if Instant::now() >= deadline {
            return None;
        }
    }
    let (status, body) = nanopush_e2e::client::parse_response(&buf).ok()?;
    Some((status, String::from_utf8_lossy(&body).into_owned()))
}

/// A plain HTTP/1.1 GET: status and body.
pub(crate) fn http_get(addr: &str, path: &str) -> (u16, Vec<u8>) {
    nanopush_e2e::client::get(addr, path).unwrap_or_else(|e| panic!("GET {path} from {addr}: {e}"))
}

/// `/api/status` (no viewer token set).
pub(crate) fn status(addr: &str) -> Value {
    let (code, body) = http_get(addr, "/api/status");
    assert_eq!(code, 200, "{}", String::from_utf8_lossy(&body));
    serde_json::from_slice(&body).unwrap()
}

/// Waits until `pred` holds for the status (read every 20 ms), within `secs`: that status.
pub(crate) fn wait_status(addr: &str, secs: f64, what: &str, pred: impl Fn(&Value) -> bool) -> Value {
    let deadline = Instant::now() + Duration::from_secs_f64(secs);
    loop {
        let s = status(addr);
        if pred(&s) {
            return s;
        }
        assert!(Instant::now() < deadline, "{what} not within {secs} s: {s}");
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// Waits (10 s at most) until the server's loop has made `n` ticks.
pub(crate) fn wait_ticks(addr: &str, n: u64) {
    wait_status(addr, 10.0, &format!("{n} ticks"), |s| {
        s["loop"]["ticks"].as_u64().unwrap() >= n
    });
}

// ---------------------------------------------------------------------------------------------
// Its WebSocket.

/// A current-thread tokio runtime, for a test's WebSocket clients.
pub(crate) fn runtime() -> tokio::runtime::Runtime {
    tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .unwrap()
}

/// A WebSocket to the server, with `token` (the operator's or a viewer's) when given.
pub(crate) async fn connect(addr: &str, token: Option<&str>) -> Ws {
    let url = nanopush_e2e::client::ws_url(addr, token);
    let (ws, _) = tokio_tungstenite::connect_async(url.into_client_request().unwrap())
        .await
        .expect("upgrade");
    ws
}

/// [`connect`], then the `welcome` (within 5 s): the socket and the welcome.
pub(crate) async fn welcomed(addr: &str, token: Option<&str>) -> (Ws, Value) {
    let mut ws = connect(addr, token).await;
    let welcome = until(&mut ws, 5.0, |m| is(m, "welcome")).await;
    (ws, welcome)
}

/// Sends one JSON message.
pub(crate) async fn send(ws: &mut Ws, v: Value) {
    ws.send(Message::Text(v.to_string().into())).await.unwrap();
}

/// The next JSON message that satisfies `pred`, within `secs` (on a WebSocket over TCP, or over
/// TLS: `serve_tls.rs`).
pub(crate) async fn until<S>(
    ws: &mut tokio_tungstenite::WebSocketStream<S>,
    secs: f64,
    pred: impl Fn(&Value) -> bool,
) -> Value
where
    S: tokio::io::AsyncRead + tokio::io::AsyncWrite + Unpin,
{
    let deadline = Instant::now() + Duration::from_secs_f64(secs);
    loop {
        let left = deadline.saturating_duration_since(Instant::now());
        let msg = tokio::time::timeout(left, ws.next())
            .await
            .unwrap_or_else(|_| panic!("no matching message within {secs} s"))
            .expect("socket open")
            .expect("a frame");
        if let Message::Text(t) = msg {
            let v: Value = serde_json::from_str(&t).unwrap();
            if pred(&v) {
                return v;
            }
        }
    }
}

/// Whether message `v` is of type `ty`.
pub(crate) fn is(v: &Value, ty: &str) -> bool {
    v["type"] == ty
}

/// Whether `v` is the reply (ok or error) to command `id`.
pub(crate) fn is_reply(v: &Value, id: u32) -> bool {
    (is(v, "ok") || is(v, "error")) && v["id"] == id
}

/// The reply (ok or error) to command `id`.
pub(crate) async fn reply(ws: &mut Ws, id: u32) -> Value {
    until(ws, 10.0, |v| is_reply(v, id)).await
}

/// Sends command `v` and waits for its reply, which must be `ok` (the reply is matched by the
/// command's `id`).
pub(crate) async fn ok(ws: &mut Ws, v: Value) {
    let id = v["id"].as_u64().expect("a command with an id") as u32;
    send(ws, v).await;
    let r = reply(ws, id).await;
    assert_eq!(r["type"], "ok", "{r}");
}

/// Sends command `v`, whose reply must be `ok`, and returns the first message satisfying `pred`
/// that comes before or after that reply. An event the command causes (the `lease` of a
/// `take_lease`) travels on the broadcast channel, the reply on the client's own queue: either
/// may reach the socket first, so waiting for the reply and then for the event could drop it.
pub(crate) async fn ok_and(ws: &mut Ws, v: Value, secs: f64, pred: impl Fn(&Value) -> bool) -> Value {
    let id = v["id"].as_u64().expect("a command with an id") as u32;
    send(ws, v).await;
    let (mut replied, mut seen) = (false, None);
    while !replied || seen.is_none() {
        let m = until(ws, secs, |m| is_reply(m, id) || pred(m)).await;
        if is_reply(&m, id) {
            assert_eq!(m["type"], "ok", "{m}");
            replied = true;
        } else if seen.is_none() {
            seen = Some(m);
        }
    }
    seen.unwrap()
}

/// The operator's usual start: connected with the token, welcomed as `operator`, subscribed to
/// `stream` (command 1), holding the lease (command 2).
pub(crate) async fn operator(addr: &str, stream: &str) -> Ws {
    let (mut op, welcome) = welcomed(addr, Some(TOKEN)).await;
    assert_eq!(welcome["role"], "operator");
    send(&mut op, json!({"type": "subscribe", "id": 1, "streams": [stream]})).await;
    ok(&mut op, json!({"type": "take_lease", "id": 2})).await;
    op
}
