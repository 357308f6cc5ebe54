//! The host's stream decoder: bytes in, device packets out, resyncing after garbage.

use super::protocol::{
    DevicePacket, INFO_LEN, InfoPacket, KIND_INFO, KIND_STATE, PacketError, STATE_LEN, SYNC, StatePacket, crc16, u16_at,
};

/// The host's stream decoder: bytes in, device packets out, resyncing on [`SYNC`].
#[derive(Debug, Default)]
pub struct Decoder {
    buf: Vec<u8>,
    bad_packets: u64,
    skipped_bytes: u64,
}

impl Decoder {
    /// An empty decoder.
    pub fn new() -> Decoder {
        Decoder::default()
    }

    /// Appends received bytes.
    pub fn push(&mut self, bytes: &[u8]) {
        self.buf.extend_from_slice(bytes);
    }

    /// The next complete packet, `None` until more bytes are needed. Bytes before a sync byte, a
    /// sync byte not followed by a known kind, and packets with a bad checksum are skipped (the
    /// latter counted in [`Decoder::bad_packets`]); a checksum failure skips only its sync byte,
    /// so a packet hidden behind a truncated one is found. A packet of another protocol version
    /// is an error.
    pub fn next_packet(&mut self) -> Option<Result<DevicePacket, PacketError>> {
        let mut start = 0;
        let out = loop {
            let Some(off) = self.buf[start..].iter().position(|&b| b == SYNC) else {
                self.skipped_bytes += (self.buf.len() - start) as u64;
                start = self.buf.len();
                break None;
            };
            self.skipped_bytes += off as u64;
            start += off;
            let Some(&kind) = self.buf.get(start + 1) else {
                break None;
            };
            let len = match kind {
                KIND_STATE => STATE_LEN,
                KIND_INFO => INFO_LEN,
                _ => {
                    self.skipped_bytes += 1;
                    start += 1;
                    continue;
                }
            };
            let Some(frame) = self.buf.get(start..start + len) else {
                break None;
            };
            if crc16(&frame[..len - 2]) != u16_at(frame, len - 2) {
                self.bad_packets += 1;
                self.skipped_bytes += 1;
                start += 1;
                continue;
            }
            let packet = if kind == KIND_STATE {
                StatePacket::decode(frame).map(DevicePacket::State)
            } else {
                InfoPacket::decode(frame).map(DevicePacket::Info)
            };
            start += len;
            break Some(packet);
        };
        self.buf.drain(..start);
        out
    }

    /// Packets skipped for a bad checksum (or cut short).
    pub fn bad_packets(&self) -> u64 {
        self.bad_packets
    }

    /// Bytes skipped while looking for a packet.
    pub fn skipped_bytes(&self) -> u64 {
        self.skipped_bytes
    }
}

#[cfg(test)]
mod tests {
    use proptest::prelude::*;

    use super::*;
    use crate::serial::fixtures::{any_info, any_state, decode_all, info, state};
    use crate::serial::protocol::{PROTOCOL_VERSION, seal};

    #[test]
    fn the_decoder_resyncs_after_garbage() {
        let mut d = Decoder::new();
        // A lone sync, then a sync + state kind whose 24 bytes run into the real packet.
        d.push(&[0x00, SYNC, 0x00, SYNC, KIND_STATE, 1, 2, 3]);
        d.push(&state(1).encode());
        d.push(&[SYNC]);
        d.push(&info().encode());
        d.push(&state(2).encode());
        let got = decode_all(&mut d);
        assert_eq!(
            got,
            [
                Ok(DevicePacket::State(state(1))),
                Ok(DevicePacket::Info(info())),
                Ok(DevicePacket::State(state(2)))
            ]
        );
        assert_eq!(d.bad_packets(), 1);
        assert_eq!(d.skipped_bytes(), 9);
    }

    #[test]
    fn a_truncated_packet_is_counted_and_the_next_one_found() {
        let mut d = Decoder::new();
        d.push(&state(1).encode()[..10]);
        assert_eq!(d.next_packet(), None, "waits for the rest");
        d.push(&state(2).encode());
        assert_eq!(decode_all(&mut d), [Ok(DevicePacket::State(state(2)))]);
        assert_eq!(d.bad_packets(), 1);
    }

    #[test]
    fn packets_arriving_a_byte_at_a_time_decode() {
        let mut d = Decoder::new();
        let mut got = Vec::new();
        for b in state(3).encode().iter().chain(info().encode().iter()) {
            d.push(&[*b]);
            got.extend(decode_all(&mut d));
        }
        assert_eq!(got, [Ok(DevicePacket::State(state(3))), Ok(DevicePacket::Info(info()))]);
        assert_eq!((d.bad_packets(), d.skipped_bytes()), (0, 0));
    }

    #[test]
    fn another_protocol_version_is_an_error_not_a_skip() {
        let mut b = state(1).encode();
        b[2] = 2;
        seal(&mut b);
        let mut d = Decoder::new();
        d.push(&b);
        d.push(&state(2).encode());
        let got = decode_all(&mut d);
        assert_eq!(got, [Err(PacketError::Version(2)), Ok(DevicePacket::State(state(2)))]);
        assert!(
            got[0]
                .as_ref()
                .unwrap_err()
                .to_string()
                .contains("version 2, this host version 1")
        );
    }

    fn any_packet() -> impl Strategy<Value = DevicePacket> {
        prop_oneof![
            any_state().prop_map(DevicePacket::State),
            any_info().prop_map(DevicePacket::Info)
        ]
    }

    fn bytes_of(p: &DevicePacket) -> Vec<u8> {
        match p {
            DevicePacket::State(s) => s.encode().to_vec(),
            DevicePacket::Info(i) => i.encode().to_vec(),
        }
    }

    /// Bytes rich in sync and kind bytes, to exercise the resync paths.
    fn noisy_bytes(max: usize) -> impl Strategy<Value = Vec<u8>> {
        proptest::collection::vec(
            prop_oneof![
                any::<u8>(),
                Just(SYNC),
                Just(KIND_STATE),
                Just(KIND_INFO),
                Just(PROTOCOL_VERSION)
            ],
            0..max,
        )
    }

    /// Feeds `bytes` to a decoder in chunks of the given sizes.
    fn feed(bytes: &[u8], chunks: &[usize]) -> (Decoder, Vec<Result<DevicePacket, PacketError>>) {
        let mut d = Decoder::new();
        let mut got = Vec::new();
        let mut rest = bytes;
        for &n in chunks.iter().cycle().take(bytes.len() + 1) {
            let n = n.min(rest.len());
            d.push(&rest[..n]);
            rest = &rest[n..];
            got.extend(decode_all(&mut d));
            if rest.is_empty() {
                break;
            }
        }
        (d, got)
    }

    proptest! {
        #[test]
        fn any_bytes_in_any_chunks_never_panic_and_only_give_what_was_sent(
            bytes in noisy_bytes(1000),
            chunks in proptest::collection::vec(1usize..64, 1..8),
        ) {
            let (d, got) = feed(&bytes, &chunks);
            for p in got {
                match p {
                    // Random bytes pass the checksum now and then; what comes out must still be
                    // a packet that is in the input (reserved bytes aside).
                    Ok(p) => {
                        let len = bytes_of(&p).len();
                        let decodes_to_p = |w: &[u8]| match p {
                            DevicePacket::State(s) => StatePacket::decode(w) == Ok(s),
                            DevicePacket::Info(i) => InfoPacket::decode(w) == Ok(i),
                        };
                        prop_assert!(bytes.windows(len).any(decodes_to_p));
                    }
                    Err(e) => prop_assert!(matches!(e, PacketError::Version(v) if v != PROTOCOL_VERSION)),
                }
            }
            prop_assert!(d.skipped_bytes() <= bytes.len() as u64);
        }

        #[test]
        fn packets_between_garbage_all_arrive_in_order(
            items in proptest::collection::vec((noisy_bytes(40), any_packet()), 1..20),
            chunks in proptest::collection::vec(1usize..64, 1..8),
        ) {
            let mut bytes = Vec::new();
            for (garbage, p) in &items {
                // Garbage without a sync byte cannot hide a packet (a sync byte in it may: a
                // checksum of 1 in 65 536 passes by chance).
                bytes.extend(garbage.iter().map(|&b| if b == SYNC { 0 } else { b }));
                bytes.extend(bytes_of(p));
            }
            let (d, got) = feed(&bytes, &chunks);
            let want: Vec<_> = items.iter().map(|(_, p)| Ok(*p)).collect();
            prop_assert_eq!(got, want);
            prop_assert_eq!(d.bad_packets(), 0);
        }
    }
}
