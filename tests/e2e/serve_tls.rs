//! HTTPS. The server with a certificate from a test CA serves the API and the
//! WebSocket to a client that trusts that CA (and no other), marks its session cookies Secure,
//! and answers plain HTTP with a redirect (or a refusal when a token came in clear); with
//! `--tls-self-signed` it makes its certificate once, keeps it, and prints its fingerprint.

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::Arc;

use futures_util::SinkExt;
use nanopush_e2e::{Proc, bin, workspace};
use rustls::pki_types::pem::PemObject as _;
use rustls::pki_types::{CertificateDer, ServerName};
use serde_json::json;
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio_rustls::TlsConnector;
use tokio_tungstenite::tungstenite::Message;

use crate::util::{TOKEN, http, runtime, start, tmp, until};

/// A test CA, and a leaf for 127.0.0.1 and localhost signed by it, in `dir`: the CA's PEM, the
/// leaf's and its key's.
pub(crate) fn test_ca(dir: &Path) -> (PathBuf, PathBuf, PathBuf) {
    use rcgen::{BasicConstraints, CertificateParams, DnType, IsCa, Issuer, KeyPair, KeyUsagePurpose};
    let mut ca = CertificateParams::new(Vec::<String>::new()).unwrap();
    ca.is_ca = IsCa::Ca(BasicConstraints::Unconstrained);
    ca.distinguished_name.push(DnType::CommonName, "nanopush test CA");
    ca.key_usages = vec![KeyUsagePurpose::KeyCertSign, KeyUsagePurpose::DigitalSignature];
    let ca_key = KeyPair::generate().unwrap();
    let ca_cert = ca.self_signed(&ca_key).unwrap();
    let issuer = Issuer::new(ca, ca_key);
    let mut leaf = CertificateParams::new(vec!["127.0.0.1".to_string(), "localhost".to_string()]).unwrap();
    leaf.distinguished_name.push(DnType::CommonName, "nanopush e2e");
    leaf.extended_key_usages = vec![rcgen::ExtendedKeyUsagePurpose::ServerAuth];
    let leaf_key = KeyPair::generate().unwrap();
    let leaf_cert = leaf.signed_by(&leaf_key, &issuer).unwrap();
    let paths = (dir.join("ca.pem"), dir.join("cert.pem"), dir.join("key.pem"));
    std::fs::write(&paths.0, ca_cert.pem()).unwrap();
    std::fs::write(&paths.1, leaf_cert.pem()).unwrap();
    std::fs::write(&paths.2, leaf_key.serialize_pem()).unwrap();
    paths
}

/// A TLS client that trusts only the certificates in `roots` (PEM).
pub(crate) fn client(roots: &Path) -> TlsConnector {
    let mut store = rustls::RootCertStore::empty();
    for c in CertificateDer::pem_file_iter(roots).unwrap() {
        store.add(c.unwrap()).unwrap();
    }
    let cfg = rustls::ClientConfig::builder_with_provider(Arc::new(rustls::crypto::ring::default_provider()))
        .with_safe_default_protocol_versions()
        .unwrap()
        .with_root_certificates(store)
        .with_no_client_auth();
    TlsConnector::from(Arc::new(cfg))
}

type Tls = tokio_rustls::client::TlsStream<tokio::net::TcpStream>;

/// A TLS connection to `addr` (verified as 127.0.0.1), or the handshake's error.
async fn tls(addr: &str, connector: &TlsConnector) -> std::io::Result<Tls> {
    let tcp = tokio::net::TcpStream::connect(addr).await?;
    let name = ServerName::try_from("127.0.0.1").unwrap();
    connector.connect(name, tcp).await
}

/// One HTTPS request: status, head (lower-case), body.
async fn https(
    addr: &str,
    connector: &TlsConnector,
    method: &str,
    path: &str,
    headers: &[&str],
) -> (u16, String, String) {
    let mut s = tls(addr, connector).await.expect("TLS handshake");
    let mut req = format!("{method} {path} HTTP/1.1\r\nHost: {addr}\r\nConnection: close\r\nContent-Length: 0\r\n");
    for h in headers {
        req.push_str(&format!("{h}\r\n"));
    }
    req.push_str("\r\n");
    s.write_all(req.as_bytes()).await.unwrap();
    let mut buf = Vec::new();
    // rustls reports a peer that closes without close_notify as an error after the data.
    let _ = s.read_to_end(&mut buf).await;
    let end = buf.windows(4).position(|w| w == b"\r\n\r\n").expect("an HTTP head");
    let head = String::from_utf8_lossy(&buf[..end]).to_ascii_lowercase();
    let (status, body) = nanopush_e2e::client::parse_response(&buf).unwrap();
    (status, head, String::from_utf8_lossy(&body).into_owned())
}

/// A server with a test CA's certificate: a client that trusts the CA gets the API and a `wss:`
/// WebSocket (the operator's token, the lease taken over TLS); a client that trusts another CA
/// is refused in the handshake; the session cookie is `Secure`; plain HTTP to the port is
/// redirected to https (or refused when it carries a token).
#[test]
fn https_serves_the_api_and_the_websocket_and_redirects_plain_http() {
    let certs = tmp("tls-ca");
    let (ca, cert, key) = test_ca(&certs);
    let other = tmp("tls-other-ca");
    let (other_ca, _, _) = test_ca(&other);
    let srv = start(
        "tls",
        &["--tls-cert", cert.to_str().unwrap(), "--tls-key", key.to_str().unwrap()],
    );
    let trusted = client(&ca);
    runtime().block_on(async {
        let (code, _, body) = https(&srv.addr, &trusted, "GET", "/api/status", &[]).await;
        assert_eq!(code, 200, "{body}");
        assert!(body.contains("\"scene\""), "{body}");
        let Err(e) = tls(&srv.addr, &client(&other_ca)).await else {
            panic!("a client that trusts another CA connected");
        };
        assert!(e.to_string().to_lowercase().contains("certificate"), "{e}");

        let stream = tls(&srv.addr, &trusted).await.unwrap();
        let url = format!("wss://{}/ws?token={TOKEN}", srv.addr);
        let (mut ws, _) = tokio_tungstenite::client_async(url, stream).await.expect("wss upgrade");
        let w = until(&mut ws, 10.0, |m| m["type"] == "welcome").await;
        assert_eq!(w["role"], "operator");
        ws.send(Message::Text(json!({"type": "take_lease", "id": 1}).to_string().into()))
            .await
            .unwrap();
        let ok = until(&mut ws, 10.0, |m| m["id"] == 1).await;
        assert_eq!(ok["type"], "ok", "{ok}");

        let bearer = format!("Authorization: Bearer {TOKEN}");
        let (code, head, _) = https(&srv.addr, &trusted, "POST", "/api/session", &[&bearer]).await;
        assert_eq!(code, 200);
        let set = head
            .lines()
            .find(|l| l.starts_with("set-cookie:"))
            .expect("a cookie")
            .to_string();
        assert!(
            set.contains("; secure") && set.contains("httponly") && set.contains("samesite=strict"),
            "{set}"
        );
    });
    let (code, head, body) = http(&srv.addr, "GET", "/api/status?x=1", &[]);
    assert_eq!(code, 301, "{body}");
    assert!(
        head.contains(&format!("location: https://{}/api/status?x=1", srv.addr)),
        "{head}"
    );
    let (code, _, body) = http(&srv.addr, "GET", &format!("/?token={TOKEN}"), &[]);
    assert_eq!(code, 400, "{body}");
    assert!(
        body.contains("HTTPS only") && body.contains("have it replaced"),
        "{body}"
    );
    let _ = std::fs::remove_dir_all(&certs);
    let _ = std::fs::remove_dir_all(&other);
}

/// `--tls-self-signed`: the server prints its certificate's SHA-256 fingerprint, which is the
/// certificate it serves (a client trusting exactly that certificate connects) and the one it
/// kept; started again on the same data directory, it serves the same one.
#[test]
fn a_self_signed_certificate_is_made_once_and_its_fingerprint_printed() {
    let dir = tmp("tls-self");
    let records = dir.join("records");
    let serve = || {
        let mut child = Command::new(bin("nanopush"))
            .current_dir(workspace())
            .args([
                "serve",
                "--port",
                "0",
                "--no-realtime",
                "--allow-cpu-halt",
                "--tls-self-signed",
            ])
            .arg("--data-dir")
            .arg(&records)
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .unwrap();
        let mut lines = BufReader::new(child.stdout.take().unwrap()).lines();
        let mut next = || lines.next().unwrap().unwrap();
        let addr = next()
            .strip_prefix("nanopush serve: listening on ")
            .unwrap()
            .to_string();
        let open = next();
        assert!(open.starts_with(&format!("open https://{addr}/?token=")), "{open}");
        let fp = next();
        let fp = fp.rsplit(' ').next().unwrap().to_string();
        (Proc(child), addr, fp)
    };
    let (first, addr, fp) = serve();
    let pem = records.join("tls/self-signed-cert.pem");
    let der = CertificateDer::from_pem_file(&pem).unwrap();
    assert_eq!(
        fp,
        openssl_fingerprint(der.as_ref()),
        "the printed fingerprint is the kept certificate's"
    );
    runtime().block_on(async {
        let mut s = tls(&addr, &client(&pem))
            .await
            .expect("the certificate the server serves");
        s.write_all(format!("GET /api/status HTTP/1.1\r\nHost: {addr}\r\nConnection: close\r\n\r\n").as_bytes())
            .await
            .unwrap();
        let mut buf = Vec::new();
        let _ = s.read_to_end(&mut buf).await;
        assert!(buf.starts_with(b"HTTP/1.1 200"), "{}", String::from_utf8_lossy(&buf));
    });
    drop(first);
    let (_second, _, again) = serve();
    assert_eq!(again, fp, "the same certificate at the next start");
    let _ = std::fs::remove_dir_all(&dir);
}

/// `openssl x509 -fingerprint -sha256` of a DER certificate (`AB:CD:…`): the server's printed
/// fingerprint compared with openssl's, as a person would compare it.
fn openssl_fingerprint(der: &[u8]) -> String {
    let dir = std::env::temp_dir().join(format!("nanopush-fp-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let f = dir.join("c.der");
    std::fs::write(&f, der).unwrap();
    let o = std::process::Command::new("openssl")
        .args(["x509", "-inform", "DER", "-noout", "-fingerprint", "-sha256", "-in"])
        .arg(&f)
        .output()
        .expect("openssl (Debian's openssl package)");
    let _ = std::fs::remove_dir_all(&dir);
    let out = String::from_utf8_lossy(&o.stdout);
    out.trim().rsplit('=').next().unwrap().to_string()
}
