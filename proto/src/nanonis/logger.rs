//! The TCP Logger's data stream, on a port of its own: frame after frame, each a header — the
//! channel count (`u32`), the oversampling (`f32`), a counter (`u64`) and the logger's state
//! (`u16`) — then one `f32` per channel. Big-endian, no framing beyond that.

use super::{BodyReader, BodyWriter, FrameError};

/// Bytes of a logger frame's header.
pub const LOGGER_HEADER_LEN: usize = 4 + 4 + 8 + 2;
/// The most channels a frame may carry (the controller has 128 signals; more means the stream is
/// out of step).
pub const MAX_LOGGER_CHANNELS: usize = 128;

/// One frame of the logger stream.
#[derive(Debug, Clone, PartialEq)]
pub struct LoggerFrame {
    /// Samples averaged into each value.
    pub oversampling: f32,
    /// The frame's number since the logger started.
    pub counter: u64,
    /// The logger's state (0 idle, 1 running, as `TCPLog.StatusGet` reports it).
    pub state: u16,
    /// One value per recorded channel, in `TCPLog.ChsSet`'s order.
    pub values: Vec<f32>,
}

impl LoggerFrame {
    /// The frame's bytes.
    pub fn encode(&self) -> Vec<u8> {
        let mut w = BodyWriter::new();
        w.u32(self.values.len() as u32)
            .f32(self.oversampling)
            .u64(self.counter)
            .u16(self.state)
            .f32s(&self.values);
        w.into_bytes()
    }

    /// The channel count a frame's header announces, checked: the rest of the frame is
    /// `4 × count` bytes.
    pub fn channels_in_header(header: &[u8; LOGGER_HEADER_LEN]) -> Result<usize, FrameError> {
        let n = u32::from_be_bytes([header[0], header[1], header[2], header[3]]) as usize;
        if n > MAX_LOGGER_CHANNELS {
            return Err(FrameError::BadSize {
                field: "logger channel count",
                value: n as i64,
                max: MAX_LOGGER_CHANNELS,
            });
        }
        Ok(n)
    }

    /// Decodes a whole frame (header and values).
    pub fn decode(bytes: &[u8]) -> Result<LoggerFrame, FrameError> {
        let mut r = BodyReader::new(bytes);
        let n = r.u32("logger channel count")? as usize;
        if n > MAX_LOGGER_CHANNELS {
            return Err(FrameError::BadSize {
                field: "logger channel count",
                value: n as i64,
                max: MAX_LOGGER_CHANNELS,
            });
        }
        let oversampling = r.f32("logger oversampling")?;
        let counter = r.u64("logger counter")?;
        let state = r.u16("logger state")?;
        let values = r.f32s("logger values", n)?;
        r.finish()?;
        Ok(LoggerFrame {
            oversampling,
            counter,
            state,
            values,
        })
    }
}
