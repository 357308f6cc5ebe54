//! A real nginx in front of the server, as docs/deployment.md configures it.
//! The server trusts `X-Forwarded-For` from the proxy (`--trusted-proxy 127.0.0.1`) and from no
//! one else, so the per-address limit and the audit log see the real clients (here 127.0.0.2
//! and 127.0.0.3, which connect to nginx), not the proxy, and a client cannot forge its address.
//! Without nginx the test is skipped with a message, except under CI (`CI=true`), where it fails.

use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use nanopush_e2e::Proc;
use serde_json::Value;
use tokio_tungstenite::tungstenite::client::IntoClientRequest;

use crate::serve_access::named_server;
use crate::util::{Ws, free_port, is, ok, runtime, until};

/// nginx's binary, or None (then the test says why it is skipped; under CI it fails).
fn nginx() -> Option<String> {
    let found = ["/usr/sbin/nginx", "/usr/bin/nginx"]
        .iter()
        .find(|p| Path::new(p).exists())
        .map(|p| p.to_string());
    if found.is_none() {
        assert!(
            std::env::var("CI").as_deref() != Ok("true"),
            "nginx is missing under CI: .ci/setup installs it (apt-get install nginx)"
        );
        eprintln!("SKIPPED: nginx is not installed (apt-get install nginx, or make setup); the proxy test did not run");
    }
    found
}

/// The server block of docs/deployment.md (plain HTTP here: TLS is the server's own test),
/// proxying to `upstream`, in a configuration of its own for an unprivileged nginx in `dir`.
pub(crate) fn nginx_conf(dir: &Path, port: u16, upstream: &str) -> String {
    let d = dir.display();
    format!(
        r#"daemon off;
worker_processes 1;
pid {d}/nginx.pid;
error_log {d}/error.log;
events {{ worker_connections 256; }}
http {{
    access_log {d}/access.log;
    client_body_temp_path {d}/body;
    proxy_temp_path {d}/proxy;
    fastcgi_temp_path {d}/fastcgi;
    uwsgi_temp_path {d}/uwsgi;
    scgi_temp_path {d}/scgi;
    map $http_upgrade $connection_upgrade {{
        default upgrade;
        ''      close;
    }}
    server {{
        listen 127.0.0.1:{port};
        location / {{
            proxy_pass http://{upstream};
            proxy_http_version 1.1;
            proxy_set_header Upgrade $http_upgrade;
            proxy_set_header Connection $connection_upgrade;
            proxy_set_header X-Forwarded-For $proxy_add_x_forwarded_for;
            proxy_set_header X-Forwarded-Proto $scheme;
            proxy_read_timeout 1h;
            proxy_buffering off;
        }}
    }}
}}
"#
    )
}

/// Starts nginx with `conf` and waits until it accepts on `port`.
fn start_nginx(bin: &str, dir: &Path, conf: &str, port: u16) -> Proc {
    let path = dir.join("nginx.conf");
    std::fs::write(&path, conf).unwrap();
    let child = Command::new(bin)
        .arg("-c")
        .arg(&path)
        .arg("-p")
        .arg(dir)
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .expect("starting nginx");
    let proc = Proc(child);
    let deadline = Instant::now() + Duration::from_secs(20);
    while std::net::TcpStream::connect(("127.0.0.1", port)).is_err() {
        let log = std::fs::read_to_string(dir.join("error.log")).unwrap_or_default();
        assert!(Instant::now() < deadline, "nginx did not start within 20 s: {log}");
        std::thread::sleep(Duration::from_millis(20));
    }
    proc
}

/// A WebSocket through the proxy at `proxy`, from the local address `from` (127.0.0.x), with
/// `token` and extra headers: the socket and its welcome, or the HTTP status it was refused with.
async fn ws_from(from: &str, proxy: &str, token: &str, headers: &[(&str, &str)]) -> Result<(Ws, Value), u16> {
    let sock = tokio::net::TcpSocket::new_v4().unwrap();
    sock.bind(format!("{from}:0").parse().unwrap()).unwrap();
    let tcp = sock.connect(proxy.parse().unwrap()).await.unwrap();
    let mut req = format!("ws://{proxy}/ws?token={token}").into_client_request().unwrap();
    for (k, v) in headers {
        let k: tokio_tungstenite::tungstenite::http::HeaderName = k.parse().unwrap();
        req.headers_mut().insert(k, v.parse().unwrap());
    }
    let stream = tokio_tungstenite::MaybeTlsStream::Plain(tcp);
    match tokio_tungstenite::client_async(req, stream).await {
        Ok((mut ws, _)) => {
            let w = until(&mut ws, 10.0, |m| is(m, "welcome")).await;
            Ok((ws, w))
        }
        Err(tokio_tungstenite::tungstenite::Error::Http(r)) => Err(r.status().as_u16()),
        Err(e) => panic!("upgrade through nginx failed without an HTTP answer: {e}"),
    }
}

/// Behind nginx: the WebSocket works through the proxy; the lease holder's address in the audit
/// log is the real client's (127.0.0.2), also when it forged an `X-Forwarded-For`; the
/// per-address limit (2 here) counts each real client apart: a third viewer from 127.0.0.2 is
/// refused while 127.0.0.3 still gets in (all of them reach the server from the proxy's
/// 127.0.0.1).
#[test]
fn behind_nginx_the_limits_and_the_audit_log_see_the_real_clients() {
    let Some(bin) = nginx() else { return };
    let (srv, tokens) = named_server(
        "proxy",
        &[("alice", "operator"), ("bob", "viewer")],
        &["--trusted-proxy", "127.0.0.1", "--max-clients-per-address", "2"],
    );
    let dir = srv.dir.join("nginx");
    std::fs::create_dir_all(&dir).unwrap();
    let port = free_port();
    let _nginx = start_nginx(&bin, &dir, &nginx_conf(&dir, port, &srv.addr), port);
    let proxy = format!("127.0.0.1:{port}");
    runtime().block_on(async {
        let (mut a, w) = ws_from("127.0.0.2", &proxy, &tokens[0], &[("x-forwarded-for", "203.0.113.9")])
            .await
            .expect("alice through nginx");
        assert_eq!(w["name"], "alice");
        ok(&mut a, serde_json::json!({"type": "take_lease", "id": 1})).await;
        // Bob, twice from 127.0.0.2 (alice's operator place does not count), then a third time.
        let (_b1, _) = ws_from("127.0.0.2", &proxy, &tokens[1], &[]).await.expect("bob 1");
        let (_b2, _) = ws_from("127.0.0.2", &proxy, &tokens[1], &[]).await.expect("bob 2");
        assert_eq!(
            ws_from("127.0.0.2", &proxy, &tokens[1], &[]).await.err(),
            Some(429),
            "a third viewer from the same real client"
        );
        let (_b3, _) = ws_from("127.0.0.3", &proxy, &tokens[1], &[])
            .await
            .expect("another real client behind the same proxy");
    });
    let records = srv.dir.join("records");
    let deadline = Instant::now() + Duration::from_secs(20);
    let line = loop {
        let text = std::fs::read_to_string(records.join("audit/audit.jsonl")).unwrap_or_default();
        if let Some(l) = text.lines().find(|l| l.contains("take_lease")) {
            break serde_json::from_str::<Value>(l).unwrap();
        }
        assert!(Instant::now() < deadline, "no take_lease in the audit log: {text}");
        std::thread::sleep(Duration::from_millis(20));
    };
    assert_eq!(line["person"], "alice");
    assert_eq!(
        line["address"], "127.0.0.2",
        "the real client, not the proxy (127.0.0.1) nor the forged 203.0.113.9: {line}"
    );
    let access = std::fs::read_to_string(dir.join("access.log")).unwrap_or_default();
    assert!(
        access.contains("127.0.0.2") && access.contains("/ws"),
        "nginx carried the requests: {access}"
    );
}
