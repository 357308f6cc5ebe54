//! The wire format: the CRC, the packets with their encoding and checks, and the conversion of a
//! state to SI with its plausibility checks. Pure: no I/O.

use crate::device::{BUTTON_CLUTCH, BUTTON_ENGAGE, DeviceSample, DeviceSpec};

/// First byte of every packet.
pub const SYNC: u8 = 0xA5;
/// Kind byte of a force packet (host → device).
pub const KIND_FORCE: u8 = b'F';
/// Kind byte of a state packet (device → host).
pub const KIND_STATE: u8 = b'S';
/// Kind byte of an info packet (device → host).
pub const KIND_INFO: u8 = b'I';
/// The protocol version this host speaks.
pub const PROTOCOL_VERSION: u8 = 1;
/// Length of a force packet (bytes).
pub const FORCE_LEN: usize = 12;
/// Length of a state packet (bytes).
pub const STATE_LEN: usize = 24;
/// Length of an info packet (bytes).
pub const INFO_LEN: usize = 32;
/// CRC-16/CCITT-FALSE polynomial.
pub const CRC_POLY: u16 = 0x1021;
/// CRC-16/CCITT-FALSE initial value.
pub const CRC_INIT: u16 = 0xFFFF;
/// Force flag: render the force (clear: render none).
pub const FLAG_ACTIVE: u8 = 0x01;
/// Force flag: answer with an info packet instead of a state packet.
pub const FLAG_HELLO: u8 = 0x02;
/// Status bit: the device zeroed its force since its previous packet because the host fell silent.
pub const STATUS_HOST_SILENT: u8 = 0x01;
/// Status bit: the motor's thermal limit holds the force below the command.
pub const STATUS_FORCE_LIMITED: u8 = 0x02;
/// The device zeroes its force after this long without a valid force packet (ms).
pub const DEVICE_SILENCE_MS: u64 = 10;
/// Baud rate unless the path says otherwise (`PATH@BAUD`): exact for a 16 MHz AVR, and fast
/// enough for 1 kHz ([`link_rate_limit_hz`]: 2222 Hz).
pub const DEFAULT_BAUD: u32 = 1_000_000;
/// Bytes on the wire per exchange: a force packet and its state packet.
pub const EXCHANGE_BYTES: usize = FORCE_LEN + STATE_LEN;
/// Bits a UART sends per byte (start, 8 data, stop).
pub const UART_BITS_PER_BYTE: u32 = 10;
/// The share of the link an exchange may take: the rest is the device's turnaround and the USB
/// bridge's scheduling.
pub const LINK_SHARE: f64 = 0.8;
/// The slowest device cycle the bridge runs (Hz): the server declares the haptic link down when
/// its newest handle sample is older than its time-out (5 ms by default, one server tick of it
/// used), so the handle must be sampled at least every 2 ms.
pub const MIN_RATE_HZ: f64 = 500.0;
/// The answer to a force packet must arrive within this long of the packet's last byte leaving
/// the host, the answer's own wire time included (ms).
pub const ANSWER_DEADLINE_MS: u64 = 2;
/// Fastest handle speed a report may claim (m/s): a hand moves a handle at 1-2 m/s at most.
pub const MAX_SPEED: f64 = 10.0;
/// How far outside its travel a reported position may lie, as a fraction of the travel's span
/// (sensor calibration and the give of the end stops), and at least [`TRAVEL_MARGIN_MIN`] (m).
pub const TRAVEL_TOLERANCE: f64 = 0.1;
/// The least margin beyond the travel a position is still believed within (m).
pub const TRAVEL_MARGIN_MIN: f64 = 0.005;

/// The one range rule for a handle position, for every device: the travel `[lo, hi]` extended
/// at each end by 10 % of its span, at least 5 mm.
pub fn travel_margin(travel: [f64; 2]) -> f64 {
    (TRAVEL_TOLERANCE * (travel[1] - travel[0])).max(TRAVEL_MARGIN_MIN)
}

/// The time one exchange (a force packet and its state packet) takes on a UART at `baud`.
pub fn exchange_wire_time(baud: u32) -> std::time::Duration {
    std::time::Duration::from_secs_f64(EXCHANGE_BYTES as f64 * f64::from(UART_BITS_PER_BYTE) / f64::from(baud.max(1)))
}

/// The fastest exchange rate a UART at `baud` carries with [`LINK_SHARE`] of it (Hz): 2222 Hz
/// at 1 000 000 baud, 256 Hz at 115 200.
pub fn link_rate_limit_hz(baud: u32) -> f64 {
    LINK_SHARE / exchange_wire_time(baud).as_secs_f64()
}

/// The plausible ranges of an info packet's limits, each as (field, low, high, unit): a device
/// reporting anything outside is refused.
pub const PLAUSIBLE_MAX_FORCE_N: (f64, f64) = (0.0, 50.0);
/// A travel end's distance from the centre (m): at least 1 mm, at most 0.5 m, on each side.
pub const PLAUSIBLE_TRAVEL_END_M: (f64, f64) = (0.001, 0.5);
/// The largest stiffness a device may claim to render stably (N/m).
pub const PLAUSIBLE_MAX_STIFFNESS: f64 = 100_000.0;
/// The largest damping a device may claim to render stably (N·s/m).
pub const PLAUSIBLE_MAX_DAMPING: f64 = 1_000.0;
/// The fastest control rate a device may claim (Hz).
pub const PLAUSIBLE_MAX_RATE_HZ: u16 = 20_000;

/// The packets' CRC: the `crc` crate's CRC-16/IBM-3740, the catalogue name of CRC-16/CCITT-FALSE
/// ([`CRC_POLY`], [`CRC_INIT`], no reflection, no final xor), table-driven. A hand-written
/// bitwise loop is no faster on the protocol's packets: 29.9, 53.8 and 73.5 ns for 10, 22 and 30
/// bytes against the loop's 27.2, 56.3 and 74.9 ns (`benches/crc.rs`, docs/own-or-crate.md).
const CRC: crc::Crc<u16> = crc::Crc::<u16>::new(&crc::CRC_16_IBM_3740);

/// CRC-16/CCITT-FALSE ([`CRC_POLY`], [`CRC_INIT`], no reflection, no final xor) of `bytes`.
pub fn crc16(bytes: &[u8]) -> u16 {
    CRC.checksum(bytes)
}

/// Why bytes are not a packet.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum PacketError {
    /// Fewer bytes than the packet's length.
    #[error("{len} bytes, a packet of this kind has {need}")]
    Truncated {
        /// Bytes given.
        len: usize,
        /// Bytes needed.
        need: usize,
    },
    /// The first byte is not [`SYNC`].
    #[error("starts with {0:#04x}, not the sync byte 0xa5")]
    NoSync(u8),
    /// Another kind of packet.
    #[error("kind {found:#04x}, expected {want:#04x}")]
    Kind {
        /// The kind byte found.
        found: u8,
        /// The kind expected.
        want: u8,
    },
    /// The checksum does not match.
    #[error("checksum {found:#06x}, computed {computed:#06x}")]
    Checksum {
        /// The CRC in the packet.
        found: u16,
        /// The CRC of its bytes.
        computed: u16,
    },
    /// A valid packet of another protocol version.
    #[error(
        "the device speaks protocol version {0}, this host version {host}: flash the sketch in haptic-bridge/firmware",
        host = PROTOCOL_VERSION
    )]
    Version(u8),
}

pub(super) fn u16_at(b: &[u8], i: usize) -> u16 {
    u16::from_le_bytes([b[i], b[i + 1]])
}

fn i32_at(b: &[u8], i: usize) -> i32 {
    i32::from_le_bytes([b[i], b[i + 1], b[i + 2], b[i + 3]])
}

fn u32_at(b: &[u8], i: usize) -> u32 {
    u32::from_le_bytes([b[i], b[i + 1], b[i + 2], b[i + 3]])
}

/// Writes the header (sync, kind, version, byte 3) into `b`.
fn put_header(b: &mut [u8], kind: u8, byte3: u8) {
    b[0] = SYNC;
    b[1] = kind;
    b[2] = PROTOCOL_VERSION;
    b[3] = byte3;
}

/// Writes the CRC of all but the last two bytes into the last two.
pub(super) fn seal(b: &mut [u8]) {
    let n = b.len() - 2;
    let crc = crc16(&b[..n]);
    b[n..].copy_from_slice(&crc.to_le_bytes());
}

/// Checks sync, kind, length, checksum and version; returns the packet's `len` bytes.
fn check(b: &[u8], kind: u8, len: usize) -> Result<&[u8], PacketError> {
    let Some(b) = b.get(..len) else {
        return Err(PacketError::Truncated {
            len: b.len(),
            need: len,
        });
    };
    if b[0] != SYNC {
        return Err(PacketError::NoSync(b[0]));
    }
    if b[1] != kind {
        return Err(PacketError::Kind {
            found: b[1],
            want: kind,
        });
    }
    let (found, computed) = (u16_at(b, len - 2), crc16(&b[..len - 2]));
    if found != computed {
        return Err(PacketError::Checksum { found, computed });
    }
    if b[2] != PROTOCOL_VERSION {
        return Err(PacketError::Version(b[2]));
    }
    Ok(b)
}

/// Host → device: the force to render.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ForcePacket {
    /// Host sequence number.
    pub seq: u16,
    /// [`FLAG_ACTIVE`], [`FLAG_HELLO`].
    pub flags: u8,
    /// Force (µN), positive up.
    pub force_un: i32,
}

impl ForcePacket {
    /// The packet's bytes.
    pub fn encode(&self) -> [u8; FORCE_LEN] {
        let mut b = [0; FORCE_LEN];
        put_header(&mut b, KIND_FORCE, self.flags);
        b[4..6].copy_from_slice(&self.seq.to_le_bytes());
        b[6..10].copy_from_slice(&self.force_un.to_le_bytes());
        seal(&mut b);
        b
    }

    /// The packet at the start of `b`, checked.
    pub fn decode(b: &[u8]) -> Result<ForcePacket, PacketError> {
        let b = check(b, KIND_FORCE, FORCE_LEN)?;
        Ok(ForcePacket {
            seq: u16_at(b, 4),
            flags: b[3],
            force_un: i32_at(b, 6),
        })
    }
}

/// Device → host: the handle now, in the device's fixed-point units.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct StatePacket {
    /// [`STATUS_HOST_SILENT`], [`STATUS_FORCE_LIMITED`].
    pub status: u8,
    /// Sequence number of the last force packet the device applied.
    pub echo: u16,
    /// Device sequence number.
    pub seq: u16,
    /// Handle position (µm), positive up.
    pub position_um: i32,
    /// Handle velocity (µm/s), positive up.
    pub velocity_um_s: i32,
    /// Buttons: bit 0 engage, bit 1 clutch.
    pub buttons: u8,
    /// Force the motor renders (µN), positive up.
    pub force_un: i32,
}

impl StatePacket {
    /// The packet's bytes.
    pub fn encode(&self) -> [u8; STATE_LEN] {
        let mut b = [0; STATE_LEN];
        put_header(&mut b, KIND_STATE, self.status);
        b[4..6].copy_from_slice(&self.echo.to_le_bytes());
        b[6..8].copy_from_slice(&self.seq.to_le_bytes());
        b[8..12].copy_from_slice(&self.position_um.to_le_bytes());
        b[12..16].copy_from_slice(&self.velocity_um_s.to_le_bytes());
        b[16] = self.buttons;
        b[18..22].copy_from_slice(&self.force_un.to_le_bytes());
        seal(&mut b);
        b
    }

    /// The packet at the start of `b`, checked.
    pub fn decode(b: &[u8]) -> Result<StatePacket, PacketError> {
        let b = check(b, KIND_STATE, STATE_LEN)?;
        Ok(StatePacket {
            status: b[3],
            echo: u16_at(b, 4),
            seq: u16_at(b, 6),
            position_um: i32_at(b, 8),
            velocity_um_s: i32_at(b, 12),
            buttons: b[16],
            force_un: i32_at(b, 18),
        })
    }
}

/// Device → host, the answer to a hello: the device's own limits.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct InfoPacket {
    /// Sequence number of the hello it answers.
    pub echo: u16,
    /// Device sequence number.
    pub seq: u16,
    /// Largest force the device renders (µN).
    pub max_force_un: i32,
    /// Travel `[lower, upper]` (µm), 0 at the centre.
    pub travel_um: [i32; 2],
    /// Largest stiffness it renders stably (mN/m).
    pub max_stiffness_mn_m: u32,
    /// Largest damping it renders stably (mN·s/m).
    pub max_damping_mns_m: u32,
    /// Its control rate (Hz).
    pub rate_hz: u16,
}

impl InfoPacket {
    /// The packet's bytes.
    pub fn encode(&self) -> [u8; INFO_LEN] {
        let mut b = [0; INFO_LEN];
        put_header(&mut b, KIND_INFO, 0);
        b[4..6].copy_from_slice(&self.echo.to_le_bytes());
        b[6..8].copy_from_slice(&self.seq.to_le_bytes());
        b[8..12].copy_from_slice(&self.max_force_un.to_le_bytes());
        b[12..16].copy_from_slice(&self.travel_um[0].to_le_bytes());
        b[16..20].copy_from_slice(&self.travel_um[1].to_le_bytes());
        b[20..24].copy_from_slice(&self.max_stiffness_mn_m.to_le_bytes());
        b[24..28].copy_from_slice(&self.max_damping_mns_m.to_le_bytes());
        b[28..30].copy_from_slice(&self.rate_hz.to_le_bytes());
        seal(&mut b);
        b
    }

    /// The packet at the start of `b`, checked.
    pub fn decode(b: &[u8]) -> Result<InfoPacket, PacketError> {
        let b = check(b, KIND_INFO, INFO_LEN)?;
        Ok(InfoPacket {
            echo: u16_at(b, 4),
            seq: u16_at(b, 6),
            max_force_un: i32_at(b, 8),
            travel_um: [i32_at(b, 12), i32_at(b, 16)],
            max_stiffness_mn_m: u32_at(b, 20),
            max_damping_mns_m: u32_at(b, 24),
            rate_hz: u16_at(b, 28),
        })
    }

    /// The limits in SI as a [`DeviceSpec`], or why they are implausible (each check names the
    /// field, the value and the allowed range).
    pub fn spec(&self) -> Result<DeviceSpec, String> {
        let [lo, hi] = self.travel_um;
        let max_force = f64::from(self.max_force_un) * 1e-6;
        let (lo_m, hi_m) = (f64::from(lo) * 1e-6, f64::from(hi) * 1e-6);
        let stiffness = f64::from(self.max_stiffness_mn_m) * 1e-3;
        let damping = f64::from(self.max_damping_mns_m) * 1e-3;
        let (f_lo, f_hi) = PLAUSIBLE_MAX_FORCE_N;
        if !(max_force > f_lo && max_force <= f_hi) {
            return Err(format!(
                "the device reports a maximum force of {max_force} N; allowed: ({f_lo}, {f_hi}] N"
            ));
        }
        let (t_lo, t_hi) = PLAUSIBLE_TRAVEL_END_M;
        for (end, v) in [("lower", -lo_m), ("upper", hi_m)] {
            if !(t_lo..=t_hi).contains(&v) {
                return Err(format!(
                    "the device reports a travel of [{lo}, {hi}] µm: its {end} end must lie {} to {} mm from the centre",
                    t_lo * 1e3,
                    t_hi * 1e3
                ));
            }
        }
        if !(stiffness > 0.0 && stiffness <= PLAUSIBLE_MAX_STIFFNESS) {
            return Err(format!(
                "the device reports a largest stable stiffness of {stiffness} N/m; allowed: (0, {PLAUSIBLE_MAX_STIFFNESS}] N/m"
            ));
        }
        if !(damping > 0.0 && damping <= PLAUSIBLE_MAX_DAMPING) {
            return Err(format!(
                "the device reports a largest stable damping of {damping} N·s/m; allowed: (0, {PLAUSIBLE_MAX_DAMPING}] N·s/m"
            ));
        }
        if self.rate_hz == 0 || self.rate_hz > PLAUSIBLE_MAX_RATE_HZ {
            return Err(format!(
                "the device reports a control rate of {} Hz; allowed: (0, {PLAUSIBLE_MAX_RATE_HZ}] Hz",
                self.rate_hz
            ));
        }
        Ok(DeviceSpec {
            name: "serial",
            max_force,
            travel: [lo_m, hi_m],
            max_damping: damping,
            max_stiffness: stiffness,
            spec_rate_hz: f64::from(self.rate_hz),
        })
    }
}

/// A packet the host receives.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DevicePacket {
    /// The handle now.
    State(StatePacket),
    /// The device's limits.
    Info(InfoPacket),
}

/// Force (N) to the wire's µN, rounded, saturating at the `i32` range (never wrapping); NaN is 0.
pub fn newtons_to_micronewtons(force: f64) -> i32 {
    let un = (force * 1e6).round();
    if un.is_nan() {
        0
    } else if un >= f64::from(i32::MAX) {
        i32::MAX
    } else if un <= f64::from(i32::MIN) {
        i32::MIN
    } else {
        un as i32
    }
}

/// A state packet in SI, checked against the device's physical range: the sample and the force
/// the motor renders (N), or why the packet cannot be true.
pub fn state_in_si(spec: &DeviceSpec, s: &StatePacket) -> Result<(DeviceSample, f64), String> {
    let position = f64::from(s.position_um) * 1e-6;
    let velocity = f64::from(s.velocity_um_s) * 1e-6;
    let force = f64::from(s.force_un) * 1e-6;
    let [lo, hi] = spec.travel;
    let give = travel_margin(spec.travel);
    if !(lo - give..=hi + give).contains(&position) {
        return Err(format!(
            "position {:.3} mm is outside the travel [{:.3}, {:.3}] mm (was the handle centred when the board started?)",
            position * 1e3,
            lo * 1e3,
            hi * 1e3
        ));
    }
    if velocity.abs() > MAX_SPEED {
        return Err(format!(
            "velocity {velocity:.3} m/s is faster than a hand moves a handle ({MAX_SPEED} m/s)"
        ));
    }
    // 1 µN of slack (one unit of the field: the limit itself went through the same fixed point),
    // compared in whole µN so that the float rounding of the limit cannot take it away.
    if i64::from(s.force_un).abs() > i64::from(newtons_to_micronewtons(spec.max_force)) + 1 {
        return Err(format!(
            "the device renders {force:.6} N, more than its own maximum {:.6} N",
            spec.max_force
        ));
    }
    let buttons = u32::from(s.buttons) & (BUTTON_ENGAGE | BUTTON_CLUTCH);
    Ok((
        DeviceSample {
            position,
            velocity,
            buttons,
        },
        force,
    ))
}

#[cfg(test)]
mod tests;
