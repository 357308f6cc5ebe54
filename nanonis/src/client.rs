//! One connection to the controller: a request, then its response, with a time-out on every read
//! and write. A response must answer the request by name and carry a body of the size its header
//! announces; anything else ends the call with the command named and nothing assumed.

use std::io::{Read, Write};
use std::net::{SocketAddr, TcpStream, ToSocketAddrs};
use std::time::{Duration, Instant};

use nanopush_instrument::afm::MicroscopeError;
use nanopush_proto::nanonis::{BodyReader, ErrorBlock, FrameError, HEADER_LEN, decode_response_header, encode_request};

/// A connection that speaks the TCP Programming Interface.
#[derive(Debug)]
pub struct Connection {
    stream: TcpStream,
    addr: SocketAddr,
    timeout: Duration,
}

/// Resolves `host:port` to its first address.
pub fn resolve(addr: &str) -> Result<SocketAddr, MicroscopeError> {
    addr.to_socket_addrs()
        .ok()
        .and_then(|mut a| a.next())
        .ok_or_else(|| MicroscopeError::Link {
            command: "connect".into(),
            message: format!("{addr} does not resolve to an address"),
        })
}

fn link(command: &str, message: impl std::fmt::Display) -> MicroscopeError {
    MicroscopeError::Link {
        command: command.into(),
        message: message.to_string(),
    }
}

fn reply(command: &str, message: impl std::fmt::Display) -> MicroscopeError {
    MicroscopeError::Controller {
        command: command.into(),
        message: message.to_string(),
    }
}

impl Connection {
    /// Connects within `timeout`; every later read and write has the same time-out.
    pub fn open(addr: SocketAddr, timeout: Duration) -> Result<Connection, MicroscopeError> {
        let stream = TcpStream::connect_timeout(&addr, timeout).map_err(|e| link("connect", format!("{addr}: {e}")))?;
        stream.set_nodelay(true).map_err(|e| link("connect", e))?;
        stream.set_read_timeout(Some(timeout)).map_err(|e| link("connect", e))?;
        stream
            .set_write_timeout(Some(timeout))
            .map_err(|e| link("connect", e))?;
        Ok(Connection { stream, addr, timeout })
    }

    /// The controller's address.
    pub fn addr(&self) -> SocketAddr {
        self.addr
    }

    /// Sends `name` with `body` and returns the response's body (its error block included).
    /// The whole reply, header and body, must arrive within the time-out (or `patience`, which
    /// replaces it for this one call: a scan's wait): a controller that trickles its bytes is as
    /// late as one that says nothing.
    pub fn call_raw(
        &mut self,
        name: &str,
        body: &[u8],
        patience: Option<Duration>,
    ) -> Result<Vec<u8>, MicroscopeError> {
        let request = encode_request(name, body, true).map_err(|e| reply(name, e))?;
        self.stream
            .write_all(&request)
            .map_err(|e| link(name, io_words(&e, self.timeout)))?;
        let waited = patience.unwrap_or(self.timeout);
        let deadline = Instant::now() + waited;
        let mut header = [0u8; HEADER_LEN];
        self.read_by(&mut header, deadline)
            .map_err(|e| link(name, io_words(&e, waited)))?;
        let h = decode_response_header(&header)
            .map_err(|e| reply(name, format!("the reply is not the protocol's: {e}")))?;
        if h.name != name {
            return Err(reply(name, format!("the controller answered {:?} instead", h.name)));
        }
        // Filled as it arrives, so a size that lies costs no more memory than the bytes sent.
        let mut body = Vec::with_capacity(h.body_size.min(1 << 20));
        let mut chunk = [0u8; 64 * 1024];
        while body.len() < h.body_size {
            let want = (h.body_size - body.len()).min(chunk.len());
            self.read_by(&mut chunk[..want], deadline).map_err(|e| {
                link(
                    name,
                    format!("the reply's body of {} bytes: {}", h.body_size, io_words(&e, waited)),
                )
            })?;
            body.extend_from_slice(&chunk[..want]);
        }
        Ok(body)
    }

    /// Fills `buf` before `deadline`.
    fn read_by(&mut self, buf: &mut [u8], deadline: Instant) -> std::io::Result<()> {
        let mut got = 0;
        while got < buf.len() {
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                return Err(std::io::ErrorKind::TimedOut.into());
            }
            self.stream.set_read_timeout(Some(left))?;
            match self.stream.read(&mut buf[got..]) {
                Ok(0) => return Err(std::io::ErrorKind::UnexpectedEof.into()),
                Ok(n) => got += n,
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                Err(e) => return Err(e),
            }
        }
        Ok(())
    }

    /// Sends `name` with `body` and reads the response with `parse`, then its error block. An
    /// error block that reports a failure ends the call with the controller's own words, whether
    /// it follows the fields or comes alone.
    pub fn call<T>(
        &mut self,
        name: &str,
        body: &[u8],
        patience: Option<Duration>,
        parse: impl FnOnce(&mut BodyReader<'_>) -> Result<T, FrameError>,
    ) -> Result<T, MicroscopeError> {
        let bytes = self.call_raw(name, body, patience)?;
        let mut r = BodyReader::new(&bytes);
        let parsed = parse(&mut r).and_then(|v| ErrorBlock::read(&mut r).map(|e| (v, e)));
        match parsed {
            Ok((_, e)) if e.is_error() => Err(controller_error(name, &e)),
            Ok((v, _)) => Ok(v),
            Err(frame) => match ErrorBlock::alone(&bytes) {
                Some(e) if e.is_error() => Err(controller_error(name, &e)),
                _ => Err(reply(name, format!("the reply does not fit the command: {frame}"))),
            },
        }
    }
}

fn controller_error(name: &str, e: &ErrorBlock) -> MicroscopeError {
    let text = if e.description.is_empty() {
        "(no description)".to_string()
    } else {
        e.description.trim().to_string()
    };
    reply(name, format!("the controller reports error {}: {text}", e.status))
}

fn io_words(e: &std::io::Error, waited: Duration) -> String {
    use std::io::ErrorKind::*;
    match e.kind() {
        WouldBlock | TimedOut => format!("no answer within {:.1} s", waited.as_secs_f64()),
        UnexpectedEof => "the controller closed the connection".into(),
        ConnectionReset | ConnectionAborted | BrokenPipe => format!("the connection was lost ({e})"),
        _ => e.to_string(),
    }
}
