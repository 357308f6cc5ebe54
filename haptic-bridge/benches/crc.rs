//! CRC-16/CCITT-FALSE over the serial protocol's packets: a hand-written bitwise loop against
//! the `crc` crate (`CRC_16_IBM_3740`, its default 256-entry
//! table), in the same run. The bytes are those of real packets: the CRC covers all but the last
//! two bytes, so 10 (force, host → device, every cycle), 22 (state, device → host, every cycle)
//! and 30 (info, once per hello).
//!
//! Run: `nice -n 10 cargo bench -p nanopush-haptic --bench crc -- --warm-up-time 1 --measurement-time 3`.
//! Results and the decision: docs/own-or-crate.md.

use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use nanopush_haptic::serial::{ForcePacket, InfoPacket, StatePacket};

/// The CRC written by hand (polynomial 0x1021, init 0xFFFF, no reflection, no final xor), bit by
/// bit.
fn hand_written(bytes: &[u8]) -> u16 {
    let mut crc: u16 = 0xFFFF;
    for &b in bytes {
        crc ^= u16::from(b) << 8;
        for _ in 0..8 {
            crc = if crc & 0x8000 != 0 {
                (crc << 1) ^ 0x1021
            } else {
                crc << 1
            };
        }
    }
    crc
}

const CRATE: crc::Crc<u16> = crc::Crc::<u16>::new(&crc::CRC_16_IBM_3740);

fn packets() -> Vec<(&'static str, Vec<u8>)> {
    let force = ForcePacket {
        seq: 4711,
        flags: 1,
        force_un: -123_456,
    }
    .encode();
    let state = StatePacket {
        status: 0,
        echo: 4711,
        seq: 815,
        position_um: 1234,
        velocity_um_s: -5678,
        buttons: 1,
        force_un: -123_000,
    }
    .encode();
    let info = InfoPacket {
        echo: 1,
        seq: 2,
        max_force_un: 3_000_000,
        travel_um: [-40_000, 40_000],
        max_stiffness_mn_m: 800_000,
        max_damping_mns_m: 2_000,
        rate_hz: 1000,
    }
    .encode();
    vec![
        ("force_10B", force[..force.len() - 2].to_vec()),
        ("state_22B", state[..state.len() - 2].to_vec()),
        ("info_30B", info[..info.len() - 2].to_vec()),
    ]
}

fn crc16(c: &mut Criterion) {
    let mut group = c.benchmark_group("crc16");
    for (name, bytes) in packets() {
        assert_eq!(hand_written(&bytes), CRATE.checksum(&bytes), "{name}: the two disagree");
        group.bench_function(format!("{name}/hand_written"), |b| {
            b.iter(|| hand_written(black_box(&bytes)))
        });
        group.bench_function(format!("{name}/crc_crate"), |b| {
            b.iter(|| CRATE.checksum(black_box(&bytes)))
        });
    }
    group.finish();
}

criterion_group!(benches, crc16);
criterion_main!(benches);
