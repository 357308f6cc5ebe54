//! The typed fields of a Nanonis body: integers and floats big-endian, a string as its size
//! (`i32`) then its bytes, an array as its values after a count the command sends as a field of
//! its own, a 2-D array row by row.

use super::{FrameError, MAX_BODY_BYTES};

/// Builds a body field by field.
#[derive(Debug, Default, Clone)]
pub struct BodyWriter {
    buf: Vec<u8>,
}

impl BodyWriter {
    /// An empty body.
    pub fn new() -> BodyWriter {
        BodyWriter::default()
    }

    /// The bytes written.
    pub fn into_bytes(self) -> Vec<u8> {
        self.buf
    }

    /// An `i32`.
    pub fn i32(&mut self, v: i32) -> &mut Self {
        self.buf.extend_from_slice(&v.to_be_bytes());
        self
    }

    /// A `u32` (the protocol's booleans and enumerations in most commands).
    pub fn u32(&mut self, v: u32) -> &mut Self {
        self.buf.extend_from_slice(&v.to_be_bytes());
        self
    }

    /// A `u16`.
    pub fn u16(&mut self, v: u16) -> &mut Self {
        self.buf.extend_from_slice(&v.to_be_bytes());
        self
    }

    /// A `u64`.
    pub fn u64(&mut self, v: u64) -> &mut Self {
        self.buf.extend_from_slice(&v.to_be_bytes());
        self
    }

    /// An `f32`.
    pub fn f32(&mut self, v: f32) -> &mut Self {
        self.buf.extend_from_slice(&v.to_be_bytes());
        self
    }

    /// An `f64`.
    pub fn f64(&mut self, v: f64) -> &mut Self {
        self.buf.extend_from_slice(&v.to_be_bytes());
        self
    }

    /// A string: its size (`i32`), then its bytes.
    pub fn string(&mut self, s: &str) -> &mut Self {
        self.i32(s.len() as i32);
        self.buf.extend_from_slice(s.as_bytes());
        self
    }

    /// `f32` values one after another (the count is a field of its own).
    pub fn f32s(&mut self, vs: &[f32]) -> &mut Self {
        for v in vs {
            self.f32(*v);
        }
        self
    }

    /// `i32` values one after another.
    pub fn i32s(&mut self, vs: &[i32]) -> &mut Self {
        for v in vs {
            self.i32(*v);
        }
        self
    }
}

/// Reads a body field by field; every read names its field when the body is too short.
#[derive(Debug, Clone)]
pub struct BodyReader<'a> {
    buf: &'a [u8],
    at: usize,
}

impl<'a> BodyReader<'a> {
    /// A reader at the start of `buf`.
    pub fn new(buf: &'a [u8]) -> BodyReader<'a> {
        BodyReader { buf, at: 0 }
    }

    /// Bytes not read yet.
    pub fn remaining(&self) -> usize {
        self.buf.len() - self.at
    }

    fn take<const N: usize>(&mut self, field: &'static str) -> Result<[u8; N], FrameError> {
        let bytes = self.bytes(field, N)?;
        Ok(bytes.try_into().expect("took N bytes"))
    }

    /// `n` raw bytes.
    pub fn bytes(&mut self, field: &'static str, n: usize) -> Result<&'a [u8], FrameError> {
        if self.remaining() < n {
            return Err(FrameError::Short {
                field,
                need: n,
                at: self.at,
                len: self.buf.len(),
            });
        }
        let out = &self.buf[self.at..self.at + n];
        self.at += n;
        Ok(out)
    }

    /// An `i32`.
    pub fn i32(&mut self, field: &'static str) -> Result<i32, FrameError> {
        Ok(i32::from_be_bytes(self.take(field)?))
    }

    /// A `u32`.
    pub fn u32(&mut self, field: &'static str) -> Result<u32, FrameError> {
        Ok(u32::from_be_bytes(self.take(field)?))
    }

    /// A `u16`.
    pub fn u16(&mut self, field: &'static str) -> Result<u16, FrameError> {
        Ok(u16::from_be_bytes(self.take(field)?))
    }

    /// A `u64`.
    pub fn u64(&mut self, field: &'static str) -> Result<u64, FrameError> {
        Ok(u64::from_be_bytes(self.take(field)?))
    }

    /// An `f32`.
    pub fn f32(&mut self, field: &'static str) -> Result<f32, FrameError> {
        Ok(f32::from_be_bytes(self.take(field)?))
    }

    /// An `f64`.
    pub fn f64(&mut self, field: &'static str) -> Result<f64, FrameError> {
        Ok(f64::from_be_bytes(self.take(field)?))
    }

    /// A count or size field: an `i32` in `[0, max]`.
    pub fn count(&mut self, field: &'static str, max: usize) -> Result<usize, FrameError> {
        let v = self.i32(field)?;
        if v < 0 || v as usize > max {
            return Err(FrameError::BadSize {
                field,
                value: i64::from(v),
                max,
            });
        }
        Ok(v as usize)
    }

    /// A string: its size (`i32`), then its bytes (invalid UTF-8 is replaced, not refused: it is
    /// the controller's text).
    pub fn string(&mut self, field: &'static str) -> Result<String, FrameError> {
        let n = self.count(field, self.remaining())?;
        Ok(String::from_utf8_lossy(self.bytes(field, n)?).into_owned())
    }

    /// `n` strings, each with its size.
    pub fn strings(&mut self, field: &'static str, n: usize) -> Result<Vec<String>, FrameError> {
        // Each string takes at least its 4-byte size: a count beyond that is a lie.
        if n > self.remaining() / 4 {
            return Err(FrameError::BadSize {
                field,
                value: n as i64,
                max: self.remaining() / 4,
            });
        }
        (0..n).map(|_| self.string(field)).collect()
    }

    /// `n` `f32` values.
    pub fn f32s(&mut self, field: &'static str, n: usize) -> Result<Vec<f32>, FrameError> {
        self.words(field, n, f32::from_be_bytes)
    }

    /// `n` `i32` values.
    pub fn i32s(&mut self, field: &'static str, n: usize) -> Result<Vec<i32>, FrameError> {
        self.words(field, n, i32::from_be_bytes)
    }

    /// `n` four-byte values, each read with `from`; a count whose bytes could not fit a body is
    /// refused before anything is allocated.
    fn words<T>(&mut self, field: &'static str, n: usize, from: fn([u8; 4]) -> T) -> Result<Vec<T>, FrameError> {
        let need = n
            .checked_mul(4)
            .filter(|&b| b <= MAX_BODY_BYTES)
            .ok_or(FrameError::BadSize {
                field,
                value: n as i64,
                max: MAX_BODY_BYTES / 4,
            })?;
        let bytes = self.bytes(field, need)?;
        Ok(bytes.chunks_exact(4).map(|c| from([c[0], c[1], c[2], c[3]])).collect())
    }

    /// Fails when bytes are left.
    pub fn finish(&self) -> Result<(), FrameError> {
        match self.remaining() {
            0 => Ok(()),
            extra => Err(FrameError::Trailing { extra }),
        }
    }
}
