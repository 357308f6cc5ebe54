use proptest::prelude::*;

use super::*;
use crate::device::clamp_force;
use crate::serial::Decoder;
use crate::serial::fixtures::{any_info, any_state, decode_all, info, state};

#[test]
fn the_crc_is_ccitt_false() {
    assert_eq!(crc16(b"123456789"), 0x29B1);
    assert_eq!(crc16(b""), 0xFFFF);
    // The crate's algorithm is the one the constants (and the sketch) name.
    let alg = CRC.algorithm;
    assert_eq!((alg.width, alg.poly, alg.init), (16, CRC_POLY, CRC_INIT));
    assert_eq!(
        (alg.refin, alg.refout, alg.xorout, alg.check),
        (false, false, 0, 0x29B1)
    );
}

/// The bitwise definition (shift in each byte MSB first, xor the polynomial on carry), the one
/// the firmware sketch runs: the crate's table must agree with it on every packet length.
fn crc16_bitwise(bytes: &[u8]) -> u16 {
    let mut crc = CRC_INIT;
    for &b in bytes {
        crc ^= u16::from(b) << 8;
        for _ in 0..8 {
            crc = if crc & 0x8000 != 0 {
                (crc << 1) ^ CRC_POLY
            } else {
                crc << 1
            };
        }
    }
    crc
}

proptest! {
    #[test]
    fn the_crc_matches_its_bitwise_definition(bytes in proptest::collection::vec(any::<u8>(), 0..64)) {
        prop_assert_eq!(crc16(&bytes), crc16_bitwise(&bytes));
    }
}

#[test]
fn packets_are_laid_out_as_documented() {
    let f = ForcePacket {
        seq: 0x0102,
        flags: FLAG_ACTIVE,
        force_un: -1_500_000,
    }
    .encode();
    assert_eq!(f[..10], [0xA5, b'F', 1, 1, 0x02, 0x01, 0xA0, 0x1C, 0xE9, 0xFF]);
    assert_eq!(u16::from_le_bytes([f[10], f[11]]), crc16(&f[..10]));

    let s = StatePacket {
        status: STATUS_FORCE_LIMITED,
        echo: 0x0304,
        seq: 0x0506,
        position_um: 0x0A09_0807,
        velocity_um_s: -2,
        buttons: 3,
        force_un: 0x0F0E_0D0C,
    }
    .encode();
    assert_eq!(
        s[..22],
        [
            0xA5, b'S', 1, 2, 0x04, 0x03, 0x06, 0x05, 0x07, 0x08, 0x09, 0x0A, 0xFE, 0xFF, 0xFF, 0xFF, 3, 0, 0x0C, 0x0D,
            0x0E, 0x0F
        ]
    );
    assert_eq!(u16::from_le_bytes([s[22], s[23]]), crc16(&s[..22]));

    let i = InfoPacket {
        echo: 0x0201,
        seq: 0x0403,
        max_force_un: 0x0807_0605,
        travel_um: [-1, 0x100],
        max_stiffness_mn_m: 0x0D0C_0B0A,
        max_damping_mns_m: 0x1110_0F0E,
        rate_hz: 0x1312,
    }
    .encode();
    assert_eq!(
        i[..30],
        [
            0xA5, b'I', 1, 0, 0x01, 0x02, 0x03, 0x04, 0x05, 0x06, 0x07, 0x08, 0xFF, 0xFF, 0xFF, 0xFF, 0x00, 0x01, 0, 0,
            0x0A, 0x0B, 0x0C, 0x0D, 0x0E, 0x0F, 0x10, 0x11, 0x12, 0x13
        ]
    );
    assert_eq!(u16::from_le_bytes([i[30], i[31]]), crc16(&i[..30]));
}

#[test]
fn every_single_bit_flip_is_rejected() {
    type Decodes = fn(&[u8]) -> bool;
    let packets: [(Vec<u8>, Decodes); 3] = [
        (
            ForcePacket {
                seq: 7,
                flags: FLAG_ACTIVE,
                force_un: 123_456,
            }
            .encode()
            .to_vec(),
            |b| ForcePacket::decode(b).is_ok(),
        ),
        (state(9).encode().to_vec(), |b| StatePacket::decode(b).is_ok()),
        (info().encode().to_vec(), |b| InfoPacket::decode(b).is_ok()),
    ];
    for (bytes, decodes) in packets {
        assert!(decodes(&bytes));
        for bit in 0..bytes.len() * 8 {
            let mut b = bytes.clone();
            b[bit / 8] ^= 1 << (bit % 8);
            assert!(!decodes(&b), "a flip of bit {bit} went through");
        }
    }
    let mut b = state(9).encode();
    b[9] ^= 0x10;
    assert!(matches!(StatePacket::decode(&b), Err(PacketError::Checksum { .. })));
    let mut d = Decoder::new();
    d.push(&b);
    assert!(decode_all(&mut d).is_empty());
    assert_eq!(d.bad_packets(), 1);
}

#[test]
fn a_short_or_foreign_buffer_is_an_error_not_a_panic() {
    let b = state(1).encode();
    assert_eq!(
        StatePacket::decode(&b[..STATE_LEN - 1]),
        Err(PacketError::Truncated { len: 23, need: 24 })
    );
    assert_eq!(
        StatePacket::decode(&[]),
        Err(PacketError::Truncated { len: 0, need: 24 })
    );
    assert_eq!(
        InfoPacket::decode(&b),
        Err(PacketError::Truncated { len: 24, need: 32 })
    );
    assert_eq!(
        ForcePacket::decode(&b),
        Err(PacketError::Kind {
            found: b'S',
            want: b'F'
        })
    );
    assert_eq!(
        StatePacket::decode(&b[1..]),
        Err(PacketError::Truncated { len: 23, need: 24 })
    );
    let mut shifted = b.to_vec();
    shifted.insert(0, 0);
    assert_eq!(StatePacket::decode(&shifted), Err(PacketError::NoSync(0)));
}

#[test]
fn forces_saturate_on_the_wire_and_never_wrap() {
    assert_eq!(newtons_to_micronewtons(2.5), 2_500_000);
    assert_eq!(newtons_to_micronewtons(-1.2345674), -1_234_567);
    assert_eq!(newtons_to_micronewtons(1e12), i32::MAX);
    assert_eq!(newtons_to_micronewtons(-1e12), i32::MIN);
    assert_eq!(newtons_to_micronewtons(f64::INFINITY), i32::MAX);
    assert_eq!(newtons_to_micronewtons(f64::NEG_INFINITY), i32::MIN);
    assert_eq!(newtons_to_micronewtons(f64::NAN), 0);
    // 2147.4836475 N rounds up to i32::MAX + 1 µN.
    assert_eq!(newtons_to_micronewtons(2147.4836475), i32::MAX);
    // The device's limit in and out of the fixed point is the same number of µN.
    let max = info().spec().unwrap().max_force;
    assert_eq!(newtons_to_micronewtons(clamp_force(7.0, max)), 2_500_000);
    assert_eq!(newtons_to_micronewtons(clamp_force(-7.0, max)), -2_500_000);
}

#[test]
fn a_state_is_converted_to_si_and_checked_against_the_device() {
    let spec = info().spec().unwrap();
    assert_eq!(spec.name, "serial");
    assert_eq!(spec.max_force, 2.5);
    assert_eq!(spec.travel, [-0.04, 0.045]);
    assert_eq!(spec.max_stiffness, 400.0);
    assert_eq!(spec.max_damping, 1.5);

    let s = StatePacket {
        buttons: 0xFF,
        ..state(1)
    };
    let (sample, force) = state_in_si(&spec, &s).unwrap();
    assert!((sample.position + 0.012345).abs() < 1e-15);
    assert!((sample.velocity - 0.06789).abs() < 1e-15);
    assert_eq!(
        sample.buttons,
        BUTTON_ENGAGE | BUTTON_CLUTCH,
        "unknown button bits are dropped"
    );
    assert_eq!(force, 0.25);

    // The travel is 85 mm: 8.5 mm of give at each end.
    let at = |position_um| state_in_si(&spec, &StatePacket { position_um, ..s });
    assert!(at(53_499).is_ok() && at(-48_499).is_ok());
    let e = at(53_501).unwrap_err();
    assert!(
        e.contains("53.501 mm is outside the travel [-40.000, 45.000] mm"),
        "{e}"
    );
    assert!(at(-48_501).is_err() && at(i32::MIN).is_err() && at(i32::MAX).is_err());

    let fast = state_in_si(
        &spec,
        &StatePacket {
            velocity_um_s: -10_000_001,
            ..s
        },
    );
    assert!(fast.unwrap_err().contains("faster than a hand"));
    assert!(
        state_in_si(
            &spec,
            &StatePacket {
                velocity_um_s: 10_000_000,
                ..s
            }
        )
        .is_ok()
    );

    let strong = state_in_si(
        &spec,
        &StatePacket {
            force_un: 2_500_002,
            ..s
        },
    );
    assert!(strong.unwrap_err().contains("more than its own maximum"));
    assert!(
        state_in_si(
            &spec,
            &StatePacket {
                force_un: -2_500_000,
                ..s
            }
        )
        .is_ok()
    );
}

/// An implausible device is refused, naming the value and the allowed range: 2100 N, a ±1 µm or
/// ±2 km travel, an absurd stiffness, damping or rate.
#[test]
fn implausible_limits_are_refused_naming_the_allowed_range() {
    let refused = |p: InfoPacket| p.spec().unwrap_err();
    assert!(
        refused(InfoPacket {
            max_force_un: 0,
            ..info()
        })
        .contains("maximum force of 0 N; allowed: (0, 50] N")
    );
    assert!(
        refused(InfoPacket {
            max_force_un: -5,
            ..info()
        })
        .contains("allowed: (0, 50] N")
    );
    assert!(
        refused(InfoPacket {
            max_force_un: 2_100_000_000,
            ..info()
        })
        .contains("2100 N")
    );
    for travel in [
        [0, 10],
        [-10, -1],
        [-1, 1],
        [-2_000_000_000, 2_000_000_000],
        [-30_000, 600_000],
    ] {
        let why = refused(InfoPacket {
            travel_um: travel,
            ..info()
        });
        assert!(
            why.contains("must lie 1 to 500 mm from the centre"),
            "{travel:?}: {why}"
        );
    }
    assert!(
        refused(InfoPacket {
            max_stiffness_mn_m: 0,
            ..info()
        })
        .contains("allowed: (0, 100000] N/m")
    );
    assert!(
        refused(InfoPacket {
            max_stiffness_mn_m: u32::MAX,
            ..info()
        })
        .contains("N/m")
    );
    assert!(
        refused(InfoPacket {
            max_damping_mns_m: 0,
            ..info()
        })
        .contains("allowed: (0, 1000] N·s/m")
    );
    assert!(
        refused(InfoPacket {
            max_damping_mns_m: 2_000_000,
            ..info()
        })
        .contains("2000 N·s/m")
    );
    assert!(refused(InfoPacket { rate_hz: 0, ..info() }).contains("allowed: (0, 20000] Hz"));
    assert!(
        refused(InfoPacket {
            rate_hz: 30_000,
            ..info()
        })
        .contains("30000 Hz")
    );
    // The edges are in.
    assert!(
        InfoPacket {
            max_force_un: 50_000_000,
            travel_um: [-1_000, 500_000],
            rate_hz: 20_000,
            ..info()
        }
        .spec()
        .is_ok()
    );
}

/// One range rule for every device: the travel extended by 10 % of its span, at least 5 mm.
#[test]
fn the_travel_margin_is_a_share_of_the_span_with_a_floor() {
    assert!((travel_margin([-0.03, 0.03]) - 0.006).abs() < 1e-15);
    assert_eq!(travel_margin([-0.01, 0.01]), 0.005);
}

/// The link's rate limit is 80 % of baud / (36 bytes × 10 bits): 2222 Hz at the default 1 Mbaud,
/// 256 Hz at 115 200, which cannot carry 1 kHz.
#[test]
fn the_links_rate_limit_follows_its_baud_rate() {
    assert_eq!(DEFAULT_BAUD, 1_000_000);
    assert!((exchange_wire_time(1_000_000).as_secs_f64() - 360e-6).abs() < 1e-12);
    assert!((exchange_wire_time(115_200).as_secs_f64() - 3.125e-3).abs() < 1e-9);
    assert_eq!(link_rate_limit_hz(1_000_000).round(), 2222.0);
    assert_eq!(link_rate_limit_hz(115_200).round(), 256.0);
    assert!(link_rate_limit_hz(115_200) < MIN_RATE_HZ && link_rate_limit_hz(DEFAULT_BAUD) >= 1000.0);
}

#[test]
fn the_sketch_speaks_the_same_protocol() {
    let ino = include_str!("../../../firmware/hapkit_nanopush/hapkit_nanopush.ino");
    let lines = [
        format!("const uint8_t SYNC = 0x{SYNC:02X};"),
        format!("const uint8_t KIND_FORCE = '{}';", KIND_FORCE as char),
        format!("const uint8_t KIND_STATE = '{}';", KIND_STATE as char),
        format!("const uint8_t KIND_INFO = '{}';", KIND_INFO as char),
        format!("const uint8_t PROTOCOL_VERSION = {PROTOCOL_VERSION};"),
        format!("const uint8_t FORCE_LEN = {FORCE_LEN};"),
        format!("const uint8_t STATE_LEN = {STATE_LEN};"),
        format!("const uint8_t INFO_LEN = {INFO_LEN};"),
        format!("const uint16_t CRC_POLY = 0x{CRC_POLY:04X};"),
        format!("const uint16_t CRC_INIT = 0x{CRC_INIT:04X};"),
        format!("const uint8_t FLAG_ACTIVE = 0x{FLAG_ACTIVE:02X};"),
        format!("const uint8_t FLAG_HELLO = 0x{FLAG_HELLO:02X};"),
        format!("const uint8_t STATUS_HOST_SILENT = 0x{STATUS_HOST_SILENT:02X};"),
        format!("const uint8_t STATUS_FORCE_LIMITED = 0x{STATUS_FORCE_LIMITED:02X};"),
        format!("const uint32_t HOST_SILENCE_MS = {DEVICE_SILENCE_MS};"),
        format!("const uint32_t BAUD = {DEFAULT_BAUD};"),
    ];
    for line in lines {
        assert!(ino.contains(&line), "the sketch lacks `{line}`");
    }
}

proptest! {
    #[test]
    fn packets_round_trip(
        f in any::<(u16, u8, i32)>(),
        s in any_state(),
        i in any_info(),
    ) {
        let f = ForcePacket { seq: f.0, flags: f.1, force_un: f.2 };
        prop_assert_eq!(ForcePacket::decode(&f.encode()), Ok(f));
        prop_assert_eq!(StatePacket::decode(&s.encode()), Ok(s));
        prop_assert_eq!(InfoPacket::decode(&i.encode()), Ok(i));
    }
}

/// A serial device gets its renderable region from its info packet as the simulated
/// device does from its spec. The fixture's board declares 400 N/m at 1 kHz (a port damping of
/// 0.6 N·s/m): with the loop's 1 ms round trip its edge is 400 N/m at 1 kHz and 4 kHz, 240 N/m
/// with 2 ms (its 1.5 N·s/m carry the coupling's damper there); the same board declaring its limit
/// at 500 Hz keeps it at 500 Hz, where with 2 ms its damping limits the edge to 250 N/m.
#[test]
fn the_info_packet_gives_the_renderable_region() {
    use nanopush_proto::haptic::region::{edge, port_damping};
    let spec = info().spec().unwrap();
    assert_eq!((spec.max_stiffness, spec.spec_rate_hz), (400.0, 1000.0));
    assert!((port_damping(spec.max_stiffness, spec.spec_rate_hz) - 0.6).abs() < 1e-12);
    assert!((edge(spec.max_stiffness, spec.spec_rate_hz, 1000.0, 1e-3, spec.max_damping) - 400.0).abs() < 1e-9);
    assert_eq!(
        edge(spec.max_stiffness, spec.spec_rate_hz, 4000.0, 1e-3, spec.max_damping),
        400.0
    );
    assert!((edge(spec.max_stiffness, spec.spec_rate_hz, 1000.0, 2e-3, spec.max_damping) - 240.0).abs() < 1e-9);
    let slow = InfoPacket { rate_hz: 500, ..info() }.spec().unwrap();
    assert_eq!(slow.spec_rate_hz, 500.0);
    // At 500 Hz with 2 ms the Z-width keeps 400 N/m, but its coupling damper, 2K (T/2 + T_d) =
    // 2.4 N·s/m, is more than the board's 1.5: the edge is where the damper fits, 250 N/m.
    assert!((edge(slow.max_stiffness, slow.spec_rate_hz, 500.0, 2e-3, 0.0) - 400.0).abs() < 1e-9);
    assert!((edge(slow.max_stiffness, slow.spec_rate_hz, 500.0, 2e-3, slow.max_damping) - 250.0).abs() < 1e-9);
}
