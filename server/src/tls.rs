//! HTTPS: the server's own TLS (rustls, with the ring provider), from `--tls-cert`/`--tls-key`
//! (PEM: the chain, leaf first, and its private key) or `--tls-self-signed` (a certificate made
//! once with rcgen, kept in `tls/` of the data directory and used again at the next start, its
//! SHA-256 fingerprint printed so a person can check what their browser shows).
//!
//! [`TlsListener`] accepts TCP connections on a task of its own and shakes hands with each on a
//! task of its own (within the header time-out: a client that stalls its handshake holds only
//! its own socket); the slowloris guard then reads the decrypted bytes ([`Guarded`] over the TLS
//! stream). A client that speaks plain HTTP to the HTTPS port gets an answer in plain HTTP: a
//! redirect to the same address over HTTPS, or, when its request carries a token (which has
//! then crossed the network unencrypted), a refusal that says so.

use std::io;
use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Duration;

use rustls::pki_types::pem::PemObject as _;
use rustls::pki_types::{CertificateDer, PrivateKeyDer};
use sha2::{Digest, Sha256};
use tokio::io::{AsyncReadExt as _, AsyncWriteExt as _};
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::mpsc;
use tokio_rustls::TlsAcceptor;
use tokio_rustls::server::TlsStream;

use crate::guard::{Admission, Guarded, reset};

/// Why TLS could not be set up.
#[derive(Debug, thiserror::Error)]
pub enum TlsError {
    /// A file could not be read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// Cause.
        source: io::Error,
    },
    /// A PEM file holds no certificate or no key, or cannot be parsed.
    #[error("{path}: {why}")]
    Pem {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        why: String,
    },
    /// rustls refused the pair (the key does not match the certificate, an unsupported key).
    #[error("the certificate and key cannot be used: {0}")]
    Config(String),
    /// Making the self-signed certificate failed.
    #[error("making a self-signed certificate: {0}")]
    Generate(String),
}

/// Where the certificate comes from.
#[derive(Debug, Clone)]
pub enum TlsSource {
    /// `--tls-cert` and `--tls-key`.
    Files {
        /// PEM certificate chain, leaf first.
        cert: PathBuf,
        /// PEM private key.
        key: PathBuf,
    },
    /// `--tls-self-signed`: kept in `dir` (made there on the first start), for `names` (DNS
    /// names and addresses the browser will use).
    SelfSigned {
        /// Where the certificate and key are kept.
        dir: PathBuf,
        /// Its subject alternative names.
        names: Vec<String>,
    },
}

/// The server's TLS: its acceptor and its certificate's fingerprint.
#[derive(Clone)]
pub struct Tls {
    /// rustls's acceptor.
    pub acceptor: TlsAcceptor,
    /// SHA-256 of the leaf certificate (DER), as browsers show it: `AB:CD:…`.
    pub fingerprint: String,
    /// The leaf certificate's file.
    pub cert_path: PathBuf,
}

impl std::fmt::Debug for Tls {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Tls")
            .field("fingerprint", &self.fingerprint)
            .field("cert_path", &self.cert_path)
            .finish()
    }
}

/// SHA-256 of `der` as colon-separated upper-case hex.
pub fn fingerprint(der: &[u8]) -> String {
    Sha256::digest(der)
        .iter()
        .map(|b| format!("{b:02X}"))
        .collect::<Vec<_>>()
        .join(":")
}

fn pem_err(path: &Path, e: impl std::fmt::Display) -> TlsError {
    TlsError::Pem {
        path: path.to_path_buf(),
        why: e.to_string(),
    }
}

/// The self-signed pair in `dir`, made (and written, the key with mode 0600) if missing.
fn self_signed(dir: &Path, names: &[String]) -> Result<(PathBuf, PathBuf), TlsError> {
    use std::os::unix::fs::OpenOptionsExt as _;
    let cert = dir.join("self-signed-cert.pem");
    let key = dir.join("self-signed-key.pem");
    if cert.is_file() && key.is_file() {
        return Ok((cert, key));
    }
    let io = |path: &Path| {
        let path = path.to_path_buf();
        move |source| TlsError::Io { path, source }
    };
    std::fs::create_dir_all(dir).map_err(io(dir))?;
    let mut params = rcgen::CertificateParams::new(names.to_vec()).map_err(|e| TlsError::Generate(e.to_string()))?;
    params
        .distinguished_name
        .push(rcgen::DnType::CommonName, "nanopush serve (self-signed)");
    let pair = rcgen::KeyPair::generate().map_err(|e| TlsError::Generate(e.to_string()))?;
    let made = params
        .self_signed(&pair)
        .map_err(|e| TlsError::Generate(e.to_string()))?;
    let mut f = std::fs::OpenOptions::new()
        .write(true)
        .create(true)
        .truncate(true)
        .mode(0o600)
        .open(&key)
        .map_err(io(&key))?;
    std::io::Write::write_all(&mut f, pair.serialize_pem().as_bytes()).map_err(io(&key))?;
    std::fs::write(&cert, made.pem()).map_err(io(&cert))?;
    Ok((cert, key))
}

/// Loads (or makes) the certificate and key: the acceptor, for HTTP/1.1.
pub fn load(source: &TlsSource) -> Result<Tls, TlsError> {
    let (cert_path, key_path) = match source {
        TlsSource::Files { cert, key } => (cert.clone(), key.clone()),
        TlsSource::SelfSigned { dir, names } => self_signed(dir, names)?,
    };
    let chain: Vec<CertificateDer<'static>> = CertificateDer::pem_file_iter(&cert_path)
        .map_err(|e| pem_err(&cert_path, e))?
        .collect::<Result<_, _>>()
        .map_err(|e| pem_err(&cert_path, e))?;
    let Some(leaf) = chain.first() else {
        return Err(pem_err(
            &cert_path,
            "no certificate in it (expected PEM `BEGIN CERTIFICATE`)",
        ));
    };
    let fingerprint = fingerprint(leaf.as_ref());
    let key = PrivateKeyDer::from_pem_file(&key_path).map_err(|e| pem_err(&key_path, e))?;
    let provider = Arc::new(rustls::crypto::ring::default_provider());
    let mut config = rustls::ServerConfig::builder_with_provider(provider)
        .with_safe_default_protocol_versions()
        .map_err(|e| TlsError::Config(e.to_string()))?
        .with_no_client_auth()
        .with_single_cert(chain, key)
        .map_err(|e| TlsError::Config(e.to_string()))?;
    config.alpn_protocols = vec![b"http/1.1".to_vec()];
    Ok(Tls {
        acceptor: TlsAcceptor::from(Arc::new(config)),
        fingerprint,
        cert_path,
    })
}

/// A TLS connection, guarded against slowloris.
pub type TlsIo = Guarded<TlsStream<TcpStream>>;

/// Accepts HTTPS connections: handshakes run concurrently, each within the header time-out.
pub struct TlsListener {
    ready: mpsc::Receiver<(TlsIo, SocketAddr)>,
    local: SocketAddr,
}

impl TlsListener {
    /// Starts accepting on `inner` (on a task of its own, ended when this listener is dropped)
    /// the connections `admission` lets in, before their handshake.
    pub fn new(
        inner: TcpListener,
        tls: &Tls,
        header_timeout: Duration,
        idle_timeout: Duration,
        admission: Admission,
    ) -> io::Result<TlsListener> {
        let local = inner.local_addr()?;
        let (tx, ready) = mpsc::channel(64);
        let acceptor = tls.acceptor.clone();
        tokio::spawn(async move {
            loop {
                let (tcp, addr) = tokio::select! {
                    r = inner.accept() => match r {
                        Ok(c) => c,
                        Err(e) => {
                            // Out of descriptors, mostly: wait a little, as axum's listener does.
                            tracing::debug!("accepting a connection: {e}");
                            tokio::time::sleep(Duration::from_millis(50)).await;
                            continue;
                        }
                    },
                    _ = tx.closed() => break,
                };
                let Some(held) = admission(addr.ip()) else {
                    reset(tcp);
                    continue;
                };
                let (tx, acceptor) = (tx.clone(), acceptor.clone());
                tokio::spawn(async move {
                    if let Err(e) = tcp.set_nodelay(true) {
                        tracing::debug!("TCP_NODELAY refused on a connection: {e}");
                    }
                    let handshake = async {
                        let mut first = [0u8; 1];
                        let n = tcp.peek(&mut first).await?;
                        // A TLS record of type handshake begins with 0x16; anything else is not TLS.
                        if n == 1 && first[0] != 0x16 {
                            let port = local_port(&tcp);
                            plain_http_answer(tcp, port).await;
                            return Ok(None);
                        }
                        acceptor.accept(tcp).await.map(Some)
                    };
                    match tokio::time::timeout(header_timeout, handshake).await {
                        Ok(Ok(Some(stream))) => {
                            let io = Guarded::new(stream, header_timeout, idle_timeout).holding(held);
                            let _ = tx.send((io, addr)).await;
                        }
                        Ok(Ok(None)) => {}
                        Ok(Err(e)) => tracing::debug!("TLS handshake with {addr}: {e}"),
                        Err(_) => tracing::debug!("TLS handshake with {addr}: not finished within the header time-out"),
                    }
                });
            }
        });
        Ok(TlsListener { ready, local })
    }
}

fn local_port(tcp: &TcpStream) -> u16 {
    tcp.local_addr().map_or(0, |a| a.port())
}

/// The answer to plain HTTP on the HTTPS port: a 301 to `https://HOST/PATH`, or a 400 saying
/// the token just crossed the network unencrypted when the request carried one.
async fn plain_http_answer(mut tcp: TcpStream, port: u16) {
    let mut head = Vec::with_capacity(1024);
    let mut buf = [0u8; 1024];
    while head.len() < 8192 && !head.windows(4).any(|w| w == b"\r\n\r\n") {
        match tcp.read(&mut buf).await {
            Ok(0) | Err(_) => break,
            Ok(n) => head.extend_from_slice(&buf[..n]),
        }
    }
    let answer = plain_http_reply(&String::from_utf8_lossy(&head), port);
    let _ = tcp.write_all(answer.as_bytes()).await;
    let _ = tcp.shutdown().await;
}

/// The reply to a plain-HTTP request `text` (its head) on the HTTPS port `port`.
fn plain_http_reply(text: &str, port: u16) -> String {
    let path = text
        .lines()
        .next()
        .and_then(|l| l.split_whitespace().nth(1))
        .filter(|p| p.starts_with('/'))
        .unwrap_or("/");
    let host = text
        .lines()
        .find_map(|l| l.split_once(':').filter(|(k, _)| k.trim().eq_ignore_ascii_case("host")))
        .map(|(_, v)| v.trim().to_string())
        .filter(|h| !h.is_empty() && h.chars().all(|c| c.is_ascii_alphanumeric() || ".-:[]".contains(c)))
        .unwrap_or_else(|| format!("localhost:{port}"));
    // A query that holds a token in any spelling (`%74oken=` too) is never repeated: it gets the
    // 400 below.
    let (path, query) = path.split_once('?').unwrap_or((path, ""));
    let decoded = percent_decoded(query).to_ascii_lowercase();
    let carries_token = decoded.contains("token") || text.to_ascii_lowercase().contains("\nauthorization:");
    if carries_token {
        let body = format!(
            "This nanopush server speaks HTTPS only: open https://{host}/ . Your request carried a token over plain HTTP, where anyone on the network can read it: have it replaced (nanopush token revoke NAME, then add).\n"
        );
        format!(
            "HTTP/1.1 400 Bad Request\r\nContent-Type: text/plain; charset=utf-8\r\nContent-Length: {}\r\nConnection: close\r\n\r\n{body}",
            body.len()
        )
    } else {
        // No token in it (checked decoded above): the query is kept.
        let to = if query.is_empty() {
            format!("https://{host}{path}")
        } else {
            format!("https://{host}{path}?{query}")
        };
        let body = format!("This nanopush server speaks HTTPS only: {to}\n");
        format!(
            "HTTP/1.1 301 Moved Permanently\r\nLocation: {to}\r\nContent-Type: text/plain; charset=utf-8\r\nContent-Length: {}\r\nConnection: close\r\n\r\n{body}",
            body.len()
        )
    }
}

impl axum::serve::Listener for TlsListener {
    type Io = TlsIo;
    type Addr = SocketAddr;

    async fn accept(&mut self) -> (TlsIo, SocketAddr) {
        match self.ready.recv().await {
            Some(c) => c,
            // The accepting task ended (it does not, while this listener lives): wait forever,
            // as a listener with no more connections.
            None => std::future::pending().await,
        }
    }

    fn local_addr(&self) -> io::Result<SocketAddr> {
        Ok(self.local)
    }
}

/// `%XX` escapes decoded (and `+` as a space), byte by byte; invalid escapes are kept as they are.
fn percent_decoded(s: &str) -> String {
    let b = s.as_bytes();
    let hex = |c: u8| (c as char).to_digit(16);
    let mut out = Vec::with_capacity(b.len());
    let mut i = 0;
    while i < b.len() {
        if b[i] == b'%'
            && i + 2 < b.len()
            && let (Some(h), Some(l)) = (hex(b[i + 1]), hex(b[i + 2]))
        {
            out.push((h * 16 + l) as u8);
            i += 3;
            continue;
        }
        out.push(if b[i] == b'+' { b' ' } else { b[i] });
        i += 1;
    }
    String::from_utf8_lossy(&out).into_owned()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A token in the query in any spelling (percent-encoded: `%74ok%65n=`) gets the 400 that
    /// says it crossed the network in clear, and is not repeated in a redirect's `Location` or
    /// body; another query is kept.
    #[test]
    fn plain_http_echoes_no_query_and_refuses_a_token_in_any_spelling() {
        assert_eq!(percent_decoded("%74ok%65n=abc+d%2"), "token=abc d%2");
        for q in ["token=npt_x_y", "%74ok%65n=npt_x_y", "a=1&TOKEN=npt_x_y"] {
            let r = plain_http_reply(&format!("GET /?{q} HTTP/1.1\r\nHost: lab:8443\r\n\r\n"), 8443);
            assert!(r.starts_with("HTTP/1.1 400"), "{q}: {r}");
            assert!(!r.contains("npt_x_y"), "{q}: {r}");
        }
        let r = plain_http_reply("GET /monitor?view=monitor HTTP/1.1\r\nHost: lab:8443\r\n\r\n", 8443);
        assert!(
            r.starts_with("HTTP/1.1 301") && r.contains("Location: https://lab:8443/monitor?view=monitor\r\n"),
            "{r}"
        );
    }

    #[test]
    fn a_self_signed_certificate_is_made_once_and_kept_with_its_fingerprint() {
        let dir = std::env::temp_dir().join(format!("nanopush-tls-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let source = TlsSource::SelfSigned {
            dir: dir.clone(),
            names: vec!["localhost".into(), "127.0.0.1".into()],
        };
        let a = load(&source).unwrap();
        assert_eq!(a.fingerprint.len(), 32 * 3 - 1, "{}", a.fingerprint);
        let b = load(&source).unwrap();
        assert_eq!(a.fingerprint, b.fingerprint, "the same certificate at the next start");
        use std::os::unix::fs::PermissionsExt as _;
        let mode = std::fs::metadata(dir.join("self-signed-key.pem"))
            .unwrap()
            .permissions()
            .mode();
        assert_eq!(mode & 0o077, 0, "the key is readable by its owner only");
        let bad = TlsSource::Files {
            cert: dir.join("self-signed-key.pem"),
            key: dir.join("self-signed-key.pem"),
        };
        assert!(load(&bad).unwrap_err().to_string().contains("no certificate"));
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
