//! Connections that cannot hold a socket for nothing (slowloris): every HTTP request's headers
//! must arrive within a header time-out, and a plain HTTP connection that neither reads nor
//! writes for the idle time-out is closed. A connection upgraded to a WebSocket is left to the
//! session's own keep-alive (ping/pong with a dead-peer time-out).
//!
//! The guard sits between the listener and hyper ([`GuardedListener`], an axum `Listener`), so
//! it sees the bytes as they arrive: it follows the end of each header block (`\r\n\r\n`) and
//! whether that block asked for `Upgrade: websocket`. The API has no request bodies, so bytes
//! after a header block begin the next request. Asking is not enough: the guard lets go only
//! when the server's answer is `101 Switching Protocols`. A refused upgrade (401, 403, 429, 503)
//! or an upgrade header on a plain route leaves the connection guarded (were the header alone to
//! switch the time-outs off for good, it would be a slowloris bypass).
//!
//! Before the guard, an [`Admission`] decides by the peer's address alone whether a new
//! connection is served at all (the connection caps, `conn_limit.rs`); one refused is reset at
//! once, unread.

use std::io;
use std::net::{IpAddr, SocketAddr};
use std::pin::Pin;
use std::sync::Arc;
use std::task::{Context, Poll};
use std::time::Duration;

use tokio::io::{AsyncRead, AsyncWrite, ReadBuf};
use tokio::net::{TcpListener, TcpStream};
use tokio::time::{Instant, Sleep};

/// Largest header block the guard keeps to look for the upgrade (bytes); hyper refuses larger.
const MAX_HEADER: usize = 16 * 1024;

/// What an admitted connection keeps while it is open (its place among the connections).
pub type Held = Box<dyn Send + Sync>;

/// Whether a new connection from an address is served, decided before anything is read from it:
/// what it keeps while it is open, or None to refuse it.
pub type Admission = Arc<dyn Fn(IpAddr) -> Option<Held> + Send + Sync>;

/// Closes a connection refused by the [`Admission`] with a reset (no FIN handshake, no
/// TIME_WAIT left on the server for a flood's sockets).
pub fn reset(tcp: TcpStream) {
    use std::os::fd::AsRawFd as _;
    let linger = libc::linger {
        l_onoff: 1,
        l_linger: 0,
    };
    // SAFETY: setsockopt on a socket this function owns, with a linger struct of its size. A
    // zero linger makes close() reset the connection; it never blocks.
    unsafe {
        libc::setsockopt(
            tcp.as_raw_fd(),
            libc::SOL_SOCKET,
            libc::SO_LINGER,
            (&linger as *const libc::linger).cast(),
            std::mem::size_of::<libc::linger>() as libc::socklen_t,
        );
    }
    drop(tcp);
}

/// A TCP listener whose connections are admitted, then [`Guarded`].
pub struct GuardedListener {
    inner: TcpListener,
    header_timeout: Duration,
    idle_timeout: Duration,
    admission: Admission,
}

impl GuardedListener {
    /// Guards `inner`'s connections with these time-outs, those `admission` lets in.
    pub fn new(
        inner: TcpListener,
        header_timeout: Duration,
        idle_timeout: Duration,
        admission: Admission,
    ) -> GuardedListener {
        GuardedListener {
            inner,
            header_timeout,
            idle_timeout,
            admission,
        }
    }
}

impl axum::serve::Listener for GuardedListener {
    type Io = Guarded;
    type Addr = SocketAddr;

    async fn accept(&mut self) -> (Guarded, SocketAddr) {
        loop {
            let (io, addr) = axum::serve::Listener::accept(&mut self.inner).await;
            match (self.admission)(addr.ip()) {
                Some(held) => {
                    return (
                        Guarded::new(io, self.header_timeout, self.idle_timeout).holding(held),
                        addr,
                    );
                }
                None => reset(io),
            }
        }
    }

    fn local_addr(&self) -> io::Result<SocketAddr> {
        self.inner.local_addr()
    }
}

/// Where a connection is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum State {
    /// Reading a request's header block (the header deadline runs).
    Headers,
    /// Between requests, or answering one (the idle deadline runs, reset by any traffic).
    Idle,
    /// A request asked for `Upgrade: websocket` and is being answered (the idle deadline runs):
    /// upgraded when the answer is `101`, else idle.
    Asked,
    /// A WebSocket: no deadline here.
    Upgraded,
}

/// A guarded connection: over TCP, or over TLS (`tls.rs`: the guard reads the decrypted bytes).
pub struct Guarded<S = TcpStream> {
    io: S,
    state: State,
    deadline: Pin<Box<Sleep>>,
    header_timeout: Duration,
    idle_timeout: Duration,
    header: Vec<u8>,
    /// Its place among the connections, given back when it closes.
    _held: Option<Held>,
}

impl Guarded {
    /// The TCP stream (for socket options).
    pub fn tcp(&self) -> &TcpStream {
        &self.io
    }
}

impl<S> Guarded<S> {
    /// Guards `io` with these time-outs.
    pub(crate) fn new(io: S, header_timeout: Duration, idle_timeout: Duration) -> Guarded<S> {
        Guarded {
            io,
            state: State::Headers,
            deadline: Box::pin(tokio::time::sleep(header_timeout)),
            header_timeout,
            idle_timeout,
            header: Vec::new(),
            _held: None,
        }
    }

    /// The connection keeping `held` while it is open.
    pub(crate) fn holding(mut self, held: Held) -> Guarded<S> {
        self._held = Some(held);
        self
    }

    /// Follows the header blocks in `bytes`, just read.
    fn saw(&mut self, bytes: &[u8]) {
        for &b in bytes {
            match self.state {
                State::Upgraded => return,
                State::Idle | State::Asked => {
                    // A new request begins.
                    self.state = State::Headers;
                    self.header.clear();
                    let t = self.header_timeout;
                    self.deadline.as_mut().reset(Instant::now() + t);
                    self.header.push(b);
                }
                State::Headers => {
                    if self.header.len() < MAX_HEADER {
                        self.header.push(b);
                    }
                    // The end of the block: an empty line, CRLF or a bare LF (hyper accepts
                    // both, and upgrades either).
                    if self.header.ends_with(b"\n\r\n") || self.header.ends_with(b"\n\n") {
                        let text = String::from_utf8_lossy(&self.header).to_ascii_lowercase();
                        let upgrade = text.lines().any(|l| {
                            l.split_once(':')
                                .is_some_and(|(k, v)| k.trim() == "upgrade" && v.trim().contains("websocket"))
                        });
                        self.state = if upgrade { State::Asked } else { State::Idle };
                        let idle = self.idle_timeout;
                        self.deadline.as_mut().reset(Instant::now() + idle);
                    }
                }
            }
        }
    }

    fn expired(&mut self, cx: &mut Context<'_>) -> bool {
        self.state != State::Upgraded && self.deadline.as_mut().poll(cx).is_ready()
    }
}

impl<S: AsyncRead + Unpin> AsyncRead for Guarded<S> {
    fn poll_read(mut self: Pin<&mut Self>, cx: &mut Context<'_>, buf: &mut ReadBuf<'_>) -> Poll<io::Result<()>> {
        let before = buf.filled().len();
        match Pin::new(&mut self.io).poll_read(cx, buf) {
            Poll::Ready(Ok(())) => {
                let new = &buf.filled()[before..];
                if !new.is_empty() && matches!(self.state, State::Idle | State::Asked) {
                    let idle = self.idle_timeout;
                    self.deadline.as_mut().reset(Instant::now() + idle);
                }
                self.saw(new);
                Poll::Ready(Ok(()))
            }
            Poll::Pending if self.expired(cx) => Poll::Ready(Err(io::Error::new(
                io::ErrorKind::TimedOut,
                match self.state {
                    State::Headers => "request headers did not arrive within the header time-out",
                    _ => "connection idle beyond the idle time-out",
                },
            ))),
            other => other,
        }
    }
}

impl<S: AsyncWrite + Unpin> AsyncWrite for Guarded<S> {
    fn poll_write(mut self: Pin<&mut Self>, cx: &mut Context<'_>, buf: &[u8]) -> Poll<io::Result<usize>> {
        let r = Pin::new(&mut self.io).poll_write(cx, buf);
        if matches!(r, Poll::Ready(Ok(n)) if n > 0) {
            if self.state == State::Asked {
                // The answer to the upgrade request: only a 101 hands the connection over.
                self.state = if buf.starts_with(b"HTTP/1.1 101") {
                    State::Upgraded
                } else {
                    State::Idle
                };
            }
            if self.state == State::Idle {
                let idle = self.idle_timeout;
                self.deadline.as_mut().reset(Instant::now() + idle);
            }
        }
        r
    }

    fn poll_flush(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        Pin::new(&mut self.io).poll_flush(cx)
    }

    fn poll_shutdown(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        Pin::new(&mut self.io).poll_shutdown(cx)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use tokio::io::{AsyncReadExt, AsyncWriteExt};

    async fn pair(header: Duration, idle: Duration) -> (Guarded, TcpStream) {
        let l = TcpListener::bind("127.0.0.1:0").await.unwrap();
        let addr = l.local_addr().unwrap();
        let client = TcpStream::connect(addr).await.unwrap();
        let (server, _) = l.accept().await.unwrap();
        (Guarded::new(server, header, idle), client)
    }

    #[tokio::test]
    async fn headers_that_dribble_in_past_the_time_out_close_the_connection() {
        let (mut g, mut c) = pair(Duration::from_millis(200), Duration::from_secs(60)).await;
        c.write_all(b"GET / HTTP/1.1\r\nHost: x\r\n").await.unwrap();
        let mut buf = [0u8; 64];
        let n = g.read(&mut buf).await.unwrap();
        assert!(n > 0);
        let e = g.read(&mut buf).await.unwrap_err();
        assert_eq!(e.kind(), io::ErrorKind::TimedOut);
    }

    /// The client asks for a WebSocket upgrade; the guard reads the whole request.
    async fn ask_upgrade(g: &mut Guarded, c: &mut TcpStream) {
        c.write_all(b"GET /ws HTTP/1.1\r\nHost: x\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n\r\n")
            .await
            .unwrap();
        let mut buf = [0u8; 256];
        let mut got = 0;
        while got < 60 {
            got += g.read(&mut buf).await.unwrap();
        }
    }

    #[tokio::test]
    async fn a_websocket_upgrade_is_left_alone_and_plain_idle_connections_close() {
        let (mut g, mut c) = pair(Duration::from_millis(100), Duration::from_millis(200)).await;
        let mut buf = [0u8; 256];
        ask_upgrade(&mut g, &mut c).await;
        assert_eq!(g.state, State::Asked);
        g.write_all(b"HTTP/1.1 101 Switching Protocols\r\n\r\n").await.unwrap();
        assert_eq!(g.state, State::Upgraded);
        // Quiet for longer than both time-outs: still open.
        let quiet = tokio::time::timeout(Duration::from_millis(500), g.read(&mut buf)).await;
        assert!(quiet.is_err(), "an upgraded connection was closed");

        let (mut g, mut c) = pair(Duration::from_millis(100), Duration::from_millis(200)).await;
        c.write_all(b"GET / HTTP/1.1\r\nHost: x\r\n\r\n").await.unwrap();
        let mut got = 0;
        while got < 27 {
            got += g.read(&mut buf).await.unwrap();
        }
        assert_eq!(g.state, State::Idle);
        let e = g.read(&mut buf).await.unwrap_err();
        assert_eq!(e.kind(), io::ErrorKind::TimedOut);
    }

    /// An upgrade asked for and refused (here 401) leaves the connection guarded:
    /// the next request's headers are timed again.
    #[tokio::test]
    async fn an_upgrade_refused_leaves_the_guard_on() {
        let (mut g, mut c) = pair(Duration::from_millis(100), Duration::from_secs(60)).await;
        let mut buf = [0u8; 256];
        ask_upgrade(&mut g, &mut c).await;
        g.write_all(b"HTTP/1.1 401 Unauthorized\r\ncontent-length: 0\r\n\r\n")
            .await
            .unwrap();
        assert_eq!(g.state, State::Idle);
        c.write_all(b"GET / HTTP/1.1\r\nX-Slow: ").await.unwrap();
        let _ = g.read(&mut buf).await.unwrap();
        let e = g.read(&mut buf).await.unwrap_err();
        assert_eq!(e.kind(), io::ErrorKind::TimedOut);
    }
}
