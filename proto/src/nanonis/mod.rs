//! The SPECS Nanonis "TCP Programming Interface": the framing of its requests and responses, the
//! types of their bodies, and the frames of its TCP Logger stream. All big-endian.
//!
//! - A **request** is a 40-byte header — the command name (32 bytes, NUL-padded), the body size
//!   (`i32`), a send-response flag (`u16`, 1 to ask for a reply) and two zero bytes — then the body.
//! - A **response** repeats the name and the body size, then four zero bytes, then the body.
//! - A response body ends with an **error block**: a status (`u32`, 0 for none), the description's
//!   size (`i32`) and the description. A failed call may send the error block alone.
//! - Commands run one after another on a connection.
//!
//! This module only turns bytes into values and back; the client that sends them over TCP is the
//! `nanopush-nanonis` crate, which also holds the fake controller the tests run against.

mod body;
mod logger;

pub use body::{BodyReader, BodyWriter};
pub use logger::{LOGGER_HEADER_LEN, LoggerFrame};

/// Bytes of a request's or a response's header.
pub const HEADER_LEN: usize = 40;
/// Bytes of the command name in a header.
pub const NAME_LEN: usize = 32;
/// The largest body either side accepts (bytes): a 4096 × 4096 f32 frame and its prefixes fit.
pub const MAX_BODY_BYTES: usize = 80 << 20;

/// What a frame or a body that does not follow the protocol is.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FrameError {
    /// A command name longer than the header holds, or with a NUL or a non-ASCII byte.
    #[error("command name {name:?} is not 1-{NAME_LEN} ASCII characters without NUL")]
    BadName {
        /// The name as given.
        name: String,
    },
    /// A header whose padding or body size is not the protocol's.
    #[error("malformed header for {name:?}: {what}")]
    BadHeader {
        /// The name in the header (lossy).
        name: String,
        /// What is wrong.
        what: String,
    },
    /// A body shorter than its fields.
    #[error("body too short: {field} needs {need} bytes at offset {at}, the body has {len}")]
    Short {
        /// The field being read.
        field: &'static str,
        /// Bytes it needs.
        need: usize,
        /// Where it starts.
        at: usize,
        /// The body's length.
        len: usize,
    },
    /// A size or count field out of range.
    #[error("{field} = {value} is out of range; allowed: [0, {max}]")]
    BadSize {
        /// The field.
        field: &'static str,
        /// Its value.
        value: i64,
        /// The largest allowed.
        max: usize,
    },
    /// Bytes left over after the last field and the error block.
    #[error("{extra} bytes left over after the error block")]
    Trailing {
        /// How many.
        extra: usize,
    },
}

/// A request's header, decoded.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RequestHeader {
    /// The command, e.g. `FolMe.XYPosSet`.
    pub name: String,
    /// Bytes of body that follow.
    pub body_size: usize,
    /// Whether the sender waits for a response.
    pub send_response: bool,
}

/// A response's header, decoded.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ResponseHeader {
    /// The command it answers.
    pub name: String,
    /// Bytes of body that follow.
    pub body_size: usize,
}

/// The error block that ends every response body.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct ErrorBlock {
    /// 0 when the command succeeded.
    pub status: u32,
    /// The controller's own words.
    pub description: String,
}

impl ErrorBlock {
    /// The block a successful command ends with.
    pub fn ok() -> ErrorBlock {
        ErrorBlock::default()
    }

    /// Whether it reports a failure (a status, or a description without one).
    pub fn is_error(&self) -> bool {
        self.status != 0 || !self.description.is_empty()
    }

    /// Appends the block to a body.
    pub fn write(&self, w: &mut BodyWriter) {
        w.u32(self.status);
        w.string(&self.description);
    }

    /// Reads the block from where `r` stands; it must be the end of the body.
    pub fn read(r: &mut BodyReader<'_>) -> Result<ErrorBlock, FrameError> {
        let status = r.u32("error status")?;
        let description = r.string("error description")?;
        r.finish()?;
        Ok(ErrorBlock { status, description })
    }

    /// The block, when `body` is an error block alone (a failed call's whole reply).
    pub fn alone(body: &[u8]) -> Option<ErrorBlock> {
        ErrorBlock::read(&mut BodyReader::new(body)).ok()
    }
}

fn name_bytes(name: &str) -> Result<[u8; NAME_LEN], FrameError> {
    if name.is_empty() || name.len() > NAME_LEN || !name.bytes().all(|b| b.is_ascii() && b != 0) {
        return Err(FrameError::BadName { name: name.into() });
    }
    let mut out = [0u8; NAME_LEN];
    out[..name.len()].copy_from_slice(name.as_bytes());
    Ok(out)
}

fn body_size(name: &str, len: usize) -> Result<i32, FrameError> {
    if len > MAX_BODY_BYTES {
        return Err(FrameError::BadHeader {
            name: name.into(),
            what: format!("body of {len} bytes; allowed: [0, {MAX_BODY_BYTES}]"),
        });
    }
    Ok(len as i32)
}

/// The request for `name` with `body`: header then body, ready to write.
pub fn encode_request(name: &str, body: &[u8], send_response: bool) -> Result<Vec<u8>, FrameError> {
    let mut out = Vec::with_capacity(HEADER_LEN + body.len());
    out.extend_from_slice(&name_bytes(name)?);
    out.extend_from_slice(&body_size(name, body.len())?.to_be_bytes());
    out.extend_from_slice(&u16::from(send_response).to_be_bytes());
    out.extend_from_slice(&[0, 0]);
    out.extend_from_slice(body);
    Ok(out)
}

/// The response to `name` with `body` (which ends with its error block): header then body.
pub fn encode_response(name: &str, body: &[u8]) -> Result<Vec<u8>, FrameError> {
    let mut out = Vec::with_capacity(HEADER_LEN + body.len());
    out.extend_from_slice(&name_bytes(name)?);
    out.extend_from_slice(&body_size(name, body.len())?.to_be_bytes());
    out.extend_from_slice(&[0, 0, 0, 0]);
    out.extend_from_slice(body);
    Ok(out)
}

fn header_name(h: &[u8; HEADER_LEN]) -> Result<String, FrameError> {
    let raw = &h[..NAME_LEN];
    let end = raw.iter().position(|&b| b == 0).unwrap_or(NAME_LEN);
    let lossy = String::from_utf8_lossy(&raw[..end]).into_owned();
    if end == 0 || !raw[..end].iter().all(|b| b.is_ascii_graphic()) || raw[end..].iter().any(|&b| b != 0) {
        return Err(FrameError::BadHeader {
            name: lossy,
            what: "the name is not printable ASCII padded with NUL".into(),
        });
    }
    Ok(lossy)
}

fn header_size(name: &str, h: &[u8; HEADER_LEN]) -> Result<usize, FrameError> {
    let size = i32::from_be_bytes([h[32], h[33], h[34], h[35]]);
    if size < 0 || size as usize > MAX_BODY_BYTES {
        return Err(FrameError::BadHeader {
            name: name.into(),
            what: format!("body size {size}; allowed: [0, {MAX_BODY_BYTES}]"),
        });
    }
    Ok(size as usize)
}

/// Decodes a request's header.
pub fn decode_request_header(h: &[u8; HEADER_LEN]) -> Result<RequestHeader, FrameError> {
    let name = header_name(h)?;
    let body_size = header_size(&name, h)?;
    let flag = u16::from_be_bytes([h[36], h[37]]);
    if flag > 1 || h[38] != 0 || h[39] != 0 {
        return Err(FrameError::BadHeader {
            name,
            what: format!(
                "send-response flag {flag} and padding {:?}; expected 0 or 1 and [0, 0]",
                &h[38..]
            ),
        });
    }
    Ok(RequestHeader {
        name,
        body_size,
        send_response: flag == 1,
    })
}

/// Decodes a response's header.
pub fn decode_response_header(h: &[u8; HEADER_LEN]) -> Result<ResponseHeader, FrameError> {
    let name = header_name(h)?;
    let body_size = header_size(&name, h)?;
    if h[36..].iter().any(|&b| b != 0) {
        return Err(FrameError::BadHeader {
            name,
            what: format!("padding {:?}; expected four zero bytes", &h[36..]),
        });
    }
    Ok(ResponseHeader { name, body_size })
}

#[cfg(test)]
mod tests;
