//! Packets, and strategies to make them, that the protocol and decoder tests share.

use proptest::prelude::*;

use super::{Decoder, DevicePacket, InfoPacket, PacketError, StatePacket};

pub(super) fn state(seq: u16) -> StatePacket {
    StatePacket {
        status: 0,
        echo: seq.wrapping_sub(1),
        seq,
        position_um: -12_345,
        velocity_um_s: 67_890,
        buttons: 1,
        force_un: 250_000,
    }
}

pub(super) fn info() -> InfoPacket {
    InfoPacket {
        echo: 0,
        seq: 0,
        max_force_un: 2_500_000,
        travel_um: [-40_000, 45_000],
        max_stiffness_mn_m: 400_000,
        max_damping_mns_m: 1_500,
        rate_hz: 1000,
    }
}

pub(super) fn decode_all(d: &mut Decoder) -> Vec<Result<DevicePacket, PacketError>> {
    std::iter::from_fn(|| d.next_packet()).collect()
}

pub(super) fn any_state() -> impl Strategy<Value = StatePacket> {
    (any::<(u8, u16, u16, i32, i32, u8, i32)>()).prop_map(
        |(status, echo, seq, position_um, velocity_um_s, buttons, force_un)| StatePacket {
            status,
            echo,
            seq,
            position_um,
            velocity_um_s,
            buttons,
            force_un,
        },
    )
}

pub(super) fn any_info() -> impl Strategy<Value = InfoPacket> {
    (any::<(u16, u16, i32, [i32; 2], u32, u32, u16)>()).prop_map(
        |(echo, seq, max_force_un, travel_um, max_stiffness_mn_m, max_damping_mns_m, rate_hz)| InfoPacket {
            echo,
            seq,
            max_force_un,
            travel_um,
            max_stiffness_mn_m,
            max_damping_mns_m,
            rate_hz,
        },
    )
}
