//! A client of a running `nanopush serve`: plain HTTP GETs (a blocking one, and the parsing of
//! an answer for the benchmarks' own asynchronous requests) and its WebSocket's address.

use std::io::{Read, Write};
use std::net::TcpStream;

/// A WebSocket to the server, as tokio-tungstenite connects it.
pub type Ws = tokio_tungstenite::WebSocketStream<tokio_tungstenite::MaybeTlsStream<tokio::net::TcpStream>>;

/// The server's WebSocket URL, with `token` (the operator's or a viewer's) when given.
pub fn ws_url(addr: &str, token: Option<&str>) -> String {
    match token {
        Some(t) => format!("ws://{addr}/ws?token={t}"),
        None => format!("ws://{addr}/ws"),
    }
}

/// A WebSocket upgrade request for `path` (`/ws`, `/ws?token=…`), for a client that speaks the
/// protocol by hand over a socket of its own making.
pub fn upgrade_request(addr: &str, path: &str) -> String {
    format!(
        "GET {path} HTTP/1.1\r\nHost: {addr}\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n\
         Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n\r\n"
    )
}

/// One WebSocket text frame from a client (masked with `key`, as a client must), for a payload
/// of at most 125 bytes.
pub fn text_frame(payload: &[u8], key: [u8; 4]) -> Vec<u8> {
    assert!(payload.len() <= 125, "a one-byte length: {} bytes", payload.len());
    let mut frame = vec![0x81, 0x80 | payload.len() as u8];
    frame.extend_from_slice(&key);
    frame.extend(payload.iter().enumerate().map(|(i, c)| c ^ key[i % 4]));
    frame
}

/// The request [`get`] sends for `path` (HTTP/1.1, `Connection: close`).
pub fn request(addr: &str, path: &str) -> String {
    format!("GET {path} HTTP/1.1\r\nHost: {addr}\r\nConnection: close\r\n\r\n")
}

/// A plain HTTP/1.1 GET of `path` from `addr`, read to the end of the connection: the status and
/// the body (de-chunked). An Err for a connection refused or broken, or an answer that is not HTTP.
pub fn get(addr: &str, path: &str) -> std::io::Result<(u16, Vec<u8>)> {
    let mut s = TcpStream::connect(addr)?;
    s.write_all(request(addr, path).as_bytes())?;
    let mut buf = Vec::new();
    s.read_to_end(&mut buf)?;
    parse_response(&buf).map_err(|e| std::io::Error::new(std::io::ErrorKind::InvalidData, format!("GET {path}: {e}")))
}

/// An HTTP answer's status and body (de-chunked when its head says `Transfer-Encoding: chunked`).
pub fn parse_response(buf: &[u8]) -> Result<(u16, Vec<u8>), String> {
    let head_end = buf.windows(4).position(|w| w == b"\r\n\r\n").ok_or("no HTTP header")?;
    let head = String::from_utf8_lossy(&buf[..head_end]).to_ascii_lowercase();
    let status = head.split_whitespace().nth(1).unwrap_or("");
    let status = status.parse().map_err(|_| format!("no HTTP status in {status:?}"))?;
    let body = &buf[head_end + 4..];
    let body = if head.contains("transfer-encoding: chunked") {
        dechunk(body)
    } else {
        body.to_vec()
    };
    Ok((status, body))
}

/// The data of a chunked body, up to its last chunk (or as far as it is whole).
fn dechunk(mut b: &[u8]) -> Vec<u8> {
    let mut out = Vec::new();
    while let Some(eol) = b.windows(2).position(|w| w == b"\r\n") {
        let n = std::str::from_utf8(&b[..eol])
            .ok()
            .and_then(|s| usize::from_str_radix(s.trim(), 16).ok())
            .unwrap_or(0);
        if n == 0 || b.len() < eol + 2 + n {
            break;
        }
        out.extend_from_slice(&b[eol + 2..eol + 2 + n]);
        b = &b[(eol + 4 + n).min(b.len())..];
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_chunked_answer_is_dechunked_and_a_plain_one_kept() {
        let chunked = b"HTTP/1.1 200 OK\r\nTransfer-Encoding: chunked\r\n\r\n4\r\nnano\r\n4\r\npush\r\n0\r\n\r\n";
        assert_eq!(parse_response(chunked), Ok((200, b"nanopush".to_vec())));
        let plain = b"HTTP/1.0 404 Not Found\r\nContent-Length: 2\r\n\r\n4\r\n";
        assert_eq!(parse_response(plain), Ok((404, b"4\r\n".to_vec())));
        assert!(parse_response(b"HTTP/1.1 200 OK\r\n").is_err());
    }

    /// RFC 6455, 5.7: a masked "Hello" from a client.
    #[test]
    fn a_text_frame_is_masked_as_the_rfc_example() {
        let frame = text_frame(b"Hello", [0x37, 0xfa, 0x21, 0x3d]);
        assert_eq!(
            frame,
            [0x81, 0x85, 0x37, 0xfa, 0x21, 0x3d, 0x7f, 0x9f, 0x4d, 0x51, 0x58]
        );
    }
}
