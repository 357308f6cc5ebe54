//! The binary frames of the `scan` stream: one scan line each, a 32-byte header and the heights.

/// The header of a binary scan-line frame, little-endian, 32 bytes, followed by `xres` f32
/// heights (m), left to right:
///
/// | offset | type | field |
/// |---|---|---|
/// | 0 | `[u8; 4]` | magic `NPSL` |
/// | 4 | u16 | version (1) |
/// | 6 | u16 | reserved (0) |
/// | 8 | u32 | scan id |
/// | 12 | u32 | line index (0 = first, bottom) |
/// | 16 | u32 | xres |
/// | 20 | u32 | yres |
/// | 24 | f64 | line y (m) |
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ScanLineHeader {
    /// Scan id.
    pub scan: u32,
    /// Line index.
    pub line: u32,
    /// Pixels per line.
    pub xres: u32,
    /// Lines.
    pub yres: u32,
    /// Line y (m).
    pub y: f64,
}

/// Magic of a scan-line frame.
pub const SCAN_LINE_MAGIC: [u8; 4] = *b"NPSL";
/// Header length (bytes).
pub const SCAN_LINE_HEADER_LEN: usize = 32;

/// Why a binary frame could not be decoded.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum FrameError {
    /// Shorter than its header or its declared data.
    Short(usize),
    /// Not a scan line.
    BadMagic,
    /// A version this decoder does not know.
    Version(u16),
}

impl ScanLineHeader {
    /// Encodes the header and `heights` into one frame.
    pub fn encode(&self, heights: &[f32]) -> Vec<u8> {
        let mut b = Vec::with_capacity(SCAN_LINE_HEADER_LEN + 4 * heights.len());
        b.extend_from_slice(&SCAN_LINE_MAGIC);
        b.extend_from_slice(&1u16.to_le_bytes());
        b.extend_from_slice(&0u16.to_le_bytes());
        for v in [self.scan, self.line, self.xres, self.yres] {
            b.extend_from_slice(&v.to_le_bytes());
        }
        b.extend_from_slice(&self.y.to_le_bytes());
        for h in heights {
            b.extend_from_slice(&h.to_le_bytes());
        }
        b
    }

    /// Decodes a frame into its header and heights.
    pub fn decode(b: &[u8]) -> Result<(ScanLineHeader, Vec<f32>), FrameError> {
        if b.len() < SCAN_LINE_HEADER_LEN {
            return Err(FrameError::Short(b.len()));
        }
        if b[..4] != SCAN_LINE_MAGIC {
            return Err(FrameError::BadMagic);
        }
        let version = u16::from_le_bytes([b[4], b[5]]);
        if version != 1 {
            return Err(FrameError::Version(version));
        }
        let u = |k: usize| u32::from_le_bytes([b[k], b[k + 1], b[k + 2], b[k + 3]]);
        let h = ScanLineHeader {
            scan: u(8),
            line: u(12),
            xres: u(16),
            yres: u(20),
            y: f64::from_le_bytes(b[24..32].try_into().expect("8 bytes")),
        };
        let need = SCAN_LINE_HEADER_LEN + 4 * h.xres as usize;
        if b.len() != need {
            return Err(FrameError::Short(b.len()));
        }
        let heights = b[SCAN_LINE_HEADER_LEN..]
            .chunks_exact(4)
            .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
            .collect();
        Ok((h, heights))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scan_line_frames_round_trip_and_reject_bad_input() {
        let h = ScanLineHeader {
            scan: 2,
            line: 5,
            xres: 3,
            yres: 8,
            y: 1.5e-6,
        };
        let f = h.encode(&[1.0, 2.0, 3.0]);
        assert_eq!(f.len(), SCAN_LINE_HEADER_LEN + 12);
        assert_eq!(&f[..4], b"NPSL");
        assert_eq!(ScanLineHeader::decode(&f).unwrap(), (h, vec![1.0, 2.0, 3.0]));
        assert_eq!(ScanLineHeader::decode(&f[..20]), Err(FrameError::Short(20)));
        assert_eq!(ScanLineHeader::decode(&f[..40]), Err(FrameError::Short(40)));
        let mut bad = f.clone();
        bad[0] = b'X';
        assert_eq!(ScanLineHeader::decode(&bad), Err(FrameError::BadMagic));
        let mut v2 = f;
        v2[4] = 2;
        assert_eq!(ScanLineHeader::decode(&v2), Err(FrameError::Version(2)));
    }

    /// Every byte of every header field is read from its own place: fields whose four bytes all
    /// differ survive the round trip (values with only a low byte would not tell byte `k - 1`
    /// from `k + 1`); a line of no pixels is a 32-byte frame, not a short one.
    #[test]
    fn a_scan_line_header_round_trips_with_every_byte_set() {
        let h = ScanLineHeader {
            scan: 0x0403_0201,
            line: 0x0807_0605,
            xres: 2,
            yres: 0x0c0b_0a09,
            y: -1.234_567_890_123e-5,
        };
        let f = h.encode(&[-0.5, 7.25]);
        assert_eq!(ScanLineHeader::decode(&f).unwrap(), (h, vec![-0.5, 7.25]));
        let empty = ScanLineHeader { xres: 0, ..h };
        let f = empty.encode(&[]);
        assert_eq!(f.len(), SCAN_LINE_HEADER_LEN);
        assert_eq!(ScanLineHeader::decode(&f).unwrap(), (empty, vec![]));
    }
}
