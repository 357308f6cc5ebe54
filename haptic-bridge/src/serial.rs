//! The `serial` backend: an open-hardware 1-DOF device (Hapkit-class: an Arduino-compatible MCU,
//! a motor driving a sector through a capstan, a magnetoresistive or encoder position sensor) on
//! a serial port, spoken to with a small binary request/response protocol at up to 1 kHz.
//! `haptic-bridge/firmware/hapkit_nanopush/hapkit_nanopush.ino` is the reference firmware.
//!
//! # Protocol, version 1
//!
//! Fixed-length packets, every multi-byte field little-endian. Each starts with the sync byte
//! [`SYNC`] (`0xA5`), a kind byte and the protocol version ([`PROTOCOL_VERSION`]), and ends with
//! a CRC-16/CCITT-FALSE ([`crc16`]: polynomial `0x1021`, initial value `0xFFFF`, no reflection,
//! no final xor; `0x29B1` for the ASCII bytes `123456789`) of all the bytes before it, stored
//! little-endian. Reserved bits and bytes are sent as 0 and ignored.
//!
//! **Force**, host → device, kind `'F'` (`0x46`), [`FORCE_LEN`] = 12 bytes:
//!
//! | offset | type | field | unit |
//! |---|---|---|---|
//! | 0 | u8 | sync `0xA5` | |
//! | 1 | u8 | kind `'F'` | |
//! | 2 | u8 | version `1` | |
//! | 3 | u8 | flags: bit 0 [`FLAG_ACTIVE`] (clear: render no force, whatever the force field says), bit 1 [`FLAG_HELLO`] (answer with an info packet) | |
//! | 4 | u16 | host sequence number, +1 per packet, wrapping | |
//! | 6 | i32 | force, positive up | µN |
//! | 10 | u16 | CRC of bytes 0..10 | |
//!
//! **State**, device → host, kind `'S'` (`0x53`), [`STATE_LEN`] = 24 bytes:
//!
//! | offset | type | field | unit |
//! |---|---|---|---|
//! | 0 | u8 | sync `0xA5` | |
//! | 1 | u8 | kind `'S'` | |
//! | 2 | u8 | version `1` | |
//! | 3 | u8 | status: bit 0 [`STATUS_HOST_SILENT`] (the device zeroed its force since its previous packet because no valid force packet came for [`DEVICE_SILENCE_MS`]), bit 1 [`STATUS_FORCE_LIMITED`] (the motor's thermal limit holds the force below the command) | |
//! | 4 | u16 | echo: the sequence number of the last force packet the device applied | |
//! | 6 | u16 | device sequence number, +1 per state or info packet, wrapping | |
//! | 8 | i32 | handle position, positive up, 0 at the centre | µm |
//! | 12 | i32 | handle velocity, positive up | µm/s |
//! | 16 | u8 | buttons: bit 0 engage, bit 1 clutch ([`BUTTON_ENGAGE`], [`BUTTON_CLUTCH`]) | |
//! | 17 | u8 | reserved | |
//! | 18 | i32 | force the motor renders now, after the device's clamp, thermal limit and watchdog | µN |
//! | 22 | u16 | CRC of bytes 0..22 | |
//!
//! **Info**, device → host, kind `'I'` (`0x49`), [`INFO_LEN`] = 32 bytes, the answer to a force
//! packet with [`FLAG_HELLO`]; it tells the host the device's own limits ([`Device::spec`]):
//!
//! | offset | type | field | unit |
//! |---|---|---|---|
//! | 0 | u8 | sync `0xA5` | |
//! | 1 | u8 | kind `'I'` | |
//! | 2 | u8 | version (a device answers a hello even when its version differs, so a mismatch is named) | |
//! | 3 | u8 | reserved | |
//! | 4 | u16 | echo: the sequence number of the hello | |
//! | 6 | u16 | device sequence number | |
//! | 8 | i32 | largest force the device renders (its own clamp) | µN |
//! | 12 | i32 | travel, lower end (< 0) | µm |
//! | 16 | i32 | travel, upper end (> 0) | µm |
//! | 20 | u32 | largest stiffness it renders stably | mN/m |
//! | 24 | u32 | largest damping it renders stably | mN·s/m |
//! | 28 | u16 | the device's control rate | Hz |
//! | 30 | u16 | CRC of bytes 0..30 | |
//!
//! # Exchange and timing
//!
//! [`SerialDevice::open_with`] flushes the port and sends a hello (zero force, inactive) every
//! 100 ms until an info packet answers, for at most [`SerialOptions::open_timeout`] (an Arduino
//! resets when its port opens and spends 0.5-2 s in its bootloader); then one inactive
//! zero-force packet fetches the first state. After that, strictly request/response: each
//! [`Device::write_force`] sends one force packet, the device answers each valid force packet with
//! one state packet, and [`Device::read`] waits at most [`SerialOptions::read_wait`] (2 ms) for
//! the answer to the last force packet, then returns the newest valid state (a read that ends
//! without that answer counts in [`SerialDevice::timeouts`] and returns the previous state). The
//! receiver resyncs on the sync byte after garbage; a packet with a bad checksum (a packet cut
//! short shows up as one: its tail is the next packet's head) is skipped and counted in
//! [`SerialDevice::bad_packets`].
//!
//! Wire time bounds the rate: an exchange is 12 + 24 = 36 bytes, 3.1 ms at 115 200 baud on a
//! UART (10 bits a byte), so a board behind a USB-UART bridge (FTDI, CH340, an Uno's ATmega16U2)
//! manages about 300 Hz at the default [`DEFAULT_BAUD`]; at 1 000 000 baud (exact for a 16 MHz
//! AVR; set `BAUD` in the sketch and open `PATH@1000000`) the wire takes 0.36 ms and 1 kHz fits.
//! A board whose MCU speaks USB itself (ATmega32U4, SAMD, RP2040, Teensy) ignores the baud rate;
//! full-speed USB (1 ms frames) reaches 0.5-1 kHz request/response.
//!
//! **FTDI adapters** hold received bytes up to their latency timer, 16 ms by default: about 62 Hz
//! request/response, every read timing out. Set it to 1 ms (as root):
//! `echo 1 > /sys/bus/usb-serial/devices/ttyUSB0/latency_timer`.
//!
//! # Safety
//!
//! - The host clamps every force to the device's own maximum ([`clamp_force`], NaN renders as no
//!   force) and converts it to µN with saturation, never wrapping; the device clamps it again.
//! - The device zeroes its force when no valid force packet came for [`DEVICE_SILENCE_MS`]
//!   (10 ms) and says so with [`STATUS_HOST_SILENT`].
//! - The host reports [`DeviceError::Silent`] when no valid state packet came for
//!   [`SerialOptions::silent_after`] (20 ms), and [`DeviceError::Protocol`] for a state out of the
//!   device's physical range (a position outside its travel by more than [`TRAVEL_TOLERANCE`] of
//!   it, a speed above [`MAX_SPEED`], a rendered force above its maximum) or of another protocol
//!   version: such values are never passed on. (Fixed-point fields cannot carry NaN.)
//! - [`Device::close`] sends an inactive zero-force packet and waits for the device to confirm it
//!   renders nothing; dropping a [`SerialDevice`] that last sent a live force sends one too.
//! - The port is opened exclusive (`TIOCEXCL`): a second bridge cannot drive the same motor.

use std::ffi::CString;
use std::io;
use std::os::fd::{AsRawFd, FromRawFd, OwnedFd};
use std::time::{Duration, Instant};

use crate::device::{BUTTON_CLUTCH, BUTTON_ENGAGE, Device, DeviceError, DeviceSample, DeviceSpec, clamp_force};

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
/// Baud rate unless the path says otherwise (`PATH@BAUD`).
pub const DEFAULT_BAUD: u32 = 115_200;
/// Fastest handle speed a report may claim (m/s): a hand moves a handle at 1-2 m/s at most.
pub const MAX_SPEED: f64 = 10.0;
/// How far outside its travel a reported position may lie, as a fraction of the travel (sensor
/// calibration and the give of the end stops).
pub const TRAVEL_TOLERANCE: f64 = 0.1;

/// How often a hello is repeated while opening.
const HELLO_RETRY: Duration = Duration::from_millis(100);
/// How long a force packet may wait for room in the port's output buffer.
const WRITE_WAIT: Duration = Duration::from_millis(5);

/// CRC-16/CCITT-FALSE ([`CRC_POLY`], [`CRC_INIT`], no reflection, no final xor) of `bytes`.
pub fn crc16(bytes: &[u8]) -> u16 {
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

fn u16_at(b: &[u8], i: usize) -> u16 {
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
fn seal(b: &mut [u8]) {
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

    /// The limits in SI as a [`DeviceSpec`], or why they are implausible.
    pub fn spec(&self) -> Result<DeviceSpec, String> {
        let [lo, hi] = self.travel_um;
        if self.max_force_un <= 0 {
            return Err(format!(
                "the device reports a maximum force of {} µN",
                self.max_force_un
            ));
        }
        if !(lo < 0 && hi > 0) {
            return Err(format!(
                "the device reports a travel of [{lo}, {hi}] µm, which does not contain 0"
            ));
        }
        if self.max_stiffness_mn_m == 0 || self.max_damping_mns_m == 0 || self.rate_hz == 0 {
            return Err(format!(
                "the device reports a zero stiffness ({} mN/m), damping ({} mN·s/m) or rate ({} Hz)",
                self.max_stiffness_mn_m, self.max_damping_mns_m, self.rate_hz
            ));
        }
        Ok(DeviceSpec {
            name: "serial",
            max_force: f64::from(self.max_force_un) * 1e-6,
            travel: [f64::from(lo) * 1e-6, f64::from(hi) * 1e-6],
            max_damping: f64::from(self.max_damping_mns_m) * 1e-3,
            max_stiffness: f64::from(self.max_stiffness_mn_m) * 1e-3,
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
    let give = TRAVEL_TOLERANCE * (hi - lo);
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
    // 1 µN of slack: the limit itself went through the same fixed point.
    if force.abs() > spec.max_force + 1e-6 {
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

/// How a [`SerialDevice`] talks and how long it waits.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SerialOptions {
    /// Baud rate ([`DEFAULT_BAUD`]); a USB CDC device ignores it.
    pub baud: u32,
    /// How long [`Device::read`] waits for the answer to the last force packet (2 ms).
    pub read_wait: Duration,
    /// No valid state packet for this long is [`DeviceError::Silent`] (20 ms).
    pub silent_after: Duration,
    /// How long opening waits for the device to answer a hello (3 s: an Arduino resets when its
    /// port opens).
    pub open_timeout: Duration,
}

impl Default for SerialOptions {
    fn default() -> SerialOptions {
        SerialOptions {
            baud: DEFAULT_BAUD,
            read_wait: Duration::from_millis(2),
            silent_after: Duration::from_millis(20),
            open_timeout: Duration::from_secs(3),
        }
    }
}

/// Baud rates the port can be set to.
fn speed(baud: u32) -> Option<libc::speed_t> {
    Some(match baud {
        9600 => libc::B9600,
        19_200 => libc::B19200,
        38_400 => libc::B38400,
        57_600 => libc::B57600,
        115_200 => libc::B115200,
        230_400 => libc::B230400,
        #[cfg(any(target_os = "linux", target_os = "android"))]
        460_800 => libc::B460800,
        #[cfg(any(target_os = "linux", target_os = "android"))]
        500_000 => libc::B500000,
        #[cfg(any(target_os = "linux", target_os = "android"))]
        921_600 => libc::B921600,
        #[cfg(any(target_os = "linux", target_os = "android"))]
        1_000_000 => libc::B1000000,
        #[cfg(any(target_os = "linux", target_os = "android"))]
        2_000_000 => libc::B2000000,
        _ => return None,
    })
}

/// Splits the argument of `--device serial:ARG` into the path and the baud rate: `PATH` or
/// `PATH@BAUD`.
pub fn parse_serial_arg(arg: &str) -> Result<(&str, u32), DeviceError> {
    let bad = |why: String| DeviceError::BadSpec {
        given: format!("serial:{arg}"),
        why,
    };
    let (path, baud) = match arg.rsplit_once('@') {
        Some((_, "")) => return Err(bad("no baud rate after '@'".into())),
        Some((path, baud)) if baud.bytes().all(|c| c.is_ascii_digit()) => {
            let baud = baud
                .parse::<u32>()
                .map_err(|_| bad(format!("baud rate {baud} is too large")))?;
            (path, baud)
        }
        _ => (arg, DEFAULT_BAUD),
    };
    if path.is_empty() {
        return Err(bad("the serial device needs a path, e.g. serial:/dev/ttyACM0".into()));
    }
    if speed(baud).is_none() {
        return Err(bad(format!(
            "{baud} baud is not supported (9600, 19200, 38400, 57600, 115200, 230400; on Linux also 460800, 500000, 921600, 1000000, 2000000)"
        )));
    }
    Ok((path, baud))
}

/// The open port: raw, non-blocking, exclusive.
struct Port {
    fd: OwnedFd,
    device: String,
}

impl Port {
    fn open(path: &str, baud: u32) -> Result<Port, DeviceError> {
        let device = format!("serial:{path}");
        let bad = |why: String| DeviceError::BadSpec {
            given: device.clone(),
            why,
        };
        let speed = speed(baud).ok_or_else(|| bad(format!("{baud} baud is not supported")))?;
        let cpath = CString::new(path).map_err(|_| bad("the path contains a NUL byte".into()))?;
        // SAFETY: a valid NUL-terminated path and plain flags.
        let raw = unsafe {
            libc::open(
                cpath.as_ptr(),
                libc::O_RDWR | libc::O_NOCTTY | libc::O_NONBLOCK | libc::O_CLOEXEC,
            )
        };
        if raw < 0 {
            return Err(DeviceError::Io {
                device,
                source: io::Error::last_os_error(),
            });
        }
        // SAFETY: `raw` is a file descriptor we just opened and own.
        let port = Port {
            fd: unsafe { OwnedFd::from_raw_fd(raw) },
            device,
        };
        port.configure(speed)?;
        Ok(port)
    }

    /// Raw mode at `speed`, no flow control, reads return at once; exclusive; stale bytes dropped.
    fn configure(&self, speed: libc::speed_t) -> Result<(), DeviceError> {
        let fd = self.fd.as_raw_fd();
        let step = |what: &str, rc: libc::c_int| {
            if rc == 0 {
                Ok(())
            } else {
                let e = io::Error::last_os_error();
                Err(self.io(io::Error::new(e.kind(), format!("{what}: {e}"))))
            }
        };
        // SAFETY: `t` is a plain C struct filled by tcgetattr before use; `fd` is open.
        unsafe {
            let mut t: libc::termios = std::mem::zeroed();
            step("not a terminal", libc::tcgetattr(fd, &mut t))?;
            libc::cfmakeraw(&mut t);
            // cfmakeraw leaves IXOFF: the driver would inject XON/XOFF bytes into the stream.
            t.c_iflag &= !(libc::IXOFF | libc::IXANY);
            t.c_cflag |= libc::CLOCAL | libc::CREAD;
            t.c_cflag &= !(libc::CRTSCTS | libc::CSTOPB | libc::PARENB);
            t.c_cc[libc::VMIN] = 0;
            t.c_cc[libc::VTIME] = 0;
            step("setting the input speed", libc::cfsetispeed(&mut t, speed))?;
            step("setting the output speed", libc::cfsetospeed(&mut t, speed))?;
            step("setting raw mode", libc::tcsetattr(fd, libc::TCSANOW, &t))?;
            step("taking the port exclusively", libc::ioctl(fd, libc::TIOCEXCL))?;
            step("flushing stale bytes", libc::tcflush(fd, libc::TCIOFLUSH))?;
        }
        Ok(())
    }

    fn io(&self, source: io::Error) -> DeviceError {
        DeviceError::Io {
            device: self.device.clone(),
            source,
        }
    }

    /// Waits up to `timeout` for `events`; returns the events that happened. A hang-up or an error
    /// on the port is an error.
    fn poll(&self, events: libc::c_short, timeout: Duration) -> Result<libc::c_short, DeviceError> {
        let ms = timeout.as_micros().div_ceil(1000).min(libc::c_int::MAX as u128) as libc::c_int;
        let mut pfd = libc::pollfd {
            fd: self.fd.as_raw_fd(),
            events,
            revents: 0,
        };
        loop {
            // SAFETY: one valid pollfd.
            if unsafe { libc::poll(&mut pfd, 1, ms) } >= 0 {
                break;
            }
            let e = io::Error::last_os_error();
            if e.kind() != io::ErrorKind::Interrupted {
                return Err(self.io(e));
            }
        }
        if pfd.revents & (libc::POLLERR | libc::POLLHUP | libc::POLLNVAL) != 0 {
            return Err(self.io(io::Error::new(
                io::ErrorKind::BrokenPipe,
                "the device hung up (unplugged?)",
            )));
        }
        Ok(pfd.revents)
    }

    /// Reads everything available into `decoder`. (With VMIN = VTIME = 0 a read returns 0 when
    /// nothing is there; a hang-up shows in `poll` or as an error.)
    fn read_into(&self, decoder: &mut Decoder) -> Result<(), DeviceError> {
        let mut buf = [0u8; 512];
        loop {
            // SAFETY: `buf` is valid for `buf.len()` bytes.
            let n = unsafe { libc::read(self.fd.as_raw_fd(), buf.as_mut_ptr().cast(), buf.len()) };
            if n > 0 {
                decoder.push(&buf[..n as usize]);
                continue;
            }
            if n == 0 {
                return Ok(());
            }
            let e = io::Error::last_os_error();
            match e.kind() {
                io::ErrorKind::Interrupted => continue,
                io::ErrorKind::WouldBlock => return Ok(()),
                _ => return Err(self.io(e)),
            }
        }
    }

    /// Writes all of `bytes`, waiting at most [`WRITE_WAIT`] for room.
    fn write_all(&self, bytes: &[u8]) -> Result<(), DeviceError> {
        let deadline = Instant::now() + WRITE_WAIT;
        let mut done = 0;
        while done < bytes.len() {
            let rest = &bytes[done..];
            // SAFETY: `rest` is valid for `rest.len()` bytes.
            let n = unsafe { libc::write(self.fd.as_raw_fd(), rest.as_ptr().cast(), rest.len()) };
            if n > 0 {
                done += n as usize;
                continue;
            }
            if n < 0 {
                let e = io::Error::last_os_error();
                match e.kind() {
                    io::ErrorKind::Interrupted => continue,
                    io::ErrorKind::WouldBlock => {}
                    _ => return Err(self.io(e)),
                }
            }
            let now = Instant::now();
            if now >= deadline {
                return Err(self.io(io::Error::new(
                    io::ErrorKind::TimedOut,
                    "the device does not take its input (output buffer full)",
                )));
            }
            self.poll(libc::POLLOUT, deadline - now)?;
        }
        Ok(())
    }
}

/// A Hapkit-class device on a serial port (see the [module documentation](self) for the protocol).
pub struct SerialDevice {
    port: Port,
    decoder: Decoder,
    options: SerialOptions,
    spec: DeviceSpec,
    rate_hz: u16,
    next_seq: u16,
    /// The force packet whose answer has not come yet.
    awaiting: Option<u16>,
    sample: DeviceSample,
    applied_force: f64,
    status: u8,
    last_valid: Instant,
    timeouts: u64,
    watchdog_trips: u64,
    /// The last packet sent was active: dropping sends an inactive one.
    force_live: bool,
}

impl SerialDevice {
    /// Opens `ARG` of `--device serial:ARG`: `PATH` at [`DEFAULT_BAUD`] or `PATH@BAUD`
    /// (`/dev/ttyUSB0@1000000`), with the default time-outs.
    pub fn open(arg: &str) -> Result<SerialDevice, DeviceError> {
        let (path, baud) = parse_serial_arg(arg)?;
        SerialDevice::open_with(
            path,
            SerialOptions {
                baud,
                ..SerialOptions::default()
            },
        )
    }

    /// Opens the port at `path`, asks the device for its limits (hello → info) and reads its first
    /// state. [`DeviceError::Silent`] when it does not answer within `options.open_timeout`,
    /// [`DeviceError::Protocol`] when it speaks another version or reports implausible limits.
    pub fn open_with(path: &str, options: SerialOptions) -> Result<SerialDevice, DeviceError> {
        let port = Port::open(path, options.baud)?;
        let mut decoder = Decoder::new();
        let started = Instant::now();
        let deadline = started + options.open_timeout;
        let protocol = |port: &Port, why: String| DeviceError::Protocol {
            device: port.device.clone(),
            why,
        };
        let mut seq: u16 = 0;
        let mut next_hello = started;
        let info = 'hello: loop {
            let now = Instant::now();
            if now >= deadline {
                return Err(DeviceError::Silent {
                    device: port.device.clone(),
                    ms: options.open_timeout.as_millis() as u64,
                });
            }
            if now >= next_hello {
                port.write_all(
                    &ForcePacket {
                        seq,
                        flags: FLAG_HELLO,
                        force_un: 0,
                    }
                    .encode(),
                )?;
                seq = seq.wrapping_add(1);
                next_hello = now + HELLO_RETRY;
            }
            let revents = port.poll(libc::POLLIN, next_hello.min(deadline).saturating_duration_since(now))?;
            if revents & libc::POLLIN != 0 {
                port.read_into(&mut decoder)?;
            }
            while let Some(p) = decoder.next_packet() {
                match p {
                    Ok(DevicePacket::Info(info)) if info.echo < seq => break 'hello info,
                    Ok(_) => {}
                    Err(e) => return Err(protocol(&port, e.to_string())),
                }
            }
        };
        let spec = info.spec().map_err(|why| protocol(&port, why))?;
        let mut dev = SerialDevice {
            port,
            decoder,
            options,
            spec,
            rate_hz: info.rate_hz,
            next_seq: seq,
            awaiting: None,
            sample: DeviceSample::default(),
            applied_force: 0.0,
            status: 0,
            last_valid: Instant::now(),
            timeouts: 0,
            watchdog_trips: 0,
            force_live: false,
        };
        dev.send(0, 0)?;
        dev.pump(
            deadline
                .saturating_duration_since(Instant::now())
                .max(options.silent_after),
        )?;
        if dev.awaiting.is_some() {
            return Err(DeviceError::Silent {
                device: dev.port.device.clone(),
                ms: started.elapsed().as_millis() as u64,
            });
        }
        Ok(dev)
    }

    /// The path, as `serial:PATH`.
    pub fn device(&self) -> &str {
        &self.port.device
    }

    /// Packets skipped for a bad checksum or cut short.
    pub fn bad_packets(&self) -> u64 {
        self.decoder.bad_packets()
    }

    /// Reads that ended without the answer to the last force packet.
    pub fn timeouts(&self) -> u64 {
        self.timeouts
    }

    /// Times the device reported zeroing its force because the host fell silent.
    pub fn watchdog_trips(&self) -> u64 {
        self.watchdog_trips
    }

    /// Status byte of the newest state packet ([`STATUS_HOST_SILENT`], [`STATUS_FORCE_LIMITED`]).
    pub fn status(&self) -> u8 {
        self.status
    }

    /// The force the motor renders (N), from the newest state packet.
    pub fn applied_force(&self) -> f64 {
        self.applied_force
    }

    /// The device's control rate (Hz), from its info packet.
    pub fn rate_hz(&self) -> u16 {
        self.rate_hz
    }

    fn protocol(&self, why: String) -> DeviceError {
        DeviceError::Protocol {
            device: self.port.device.clone(),
            why,
        }
    }

    /// Sends one force packet and awaits its answer.
    fn send(&mut self, flags: u8, force_un: i32) -> Result<(), DeviceError> {
        let seq = self.next_seq;
        self.port.write_all(&ForcePacket { seq, flags, force_un }.encode())?;
        self.next_seq = seq.wrapping_add(1);
        self.awaiting = Some(seq);
        Ok(())
    }

    /// Takes in every packet received, waiting up to `wait` for the answer being awaited (not at
    /// all when none is).
    fn pump(&mut self, wait: Duration) -> Result<(), DeviceError> {
        let deadline = Instant::now() + wait;
        let mut polled = false;
        loop {
            while let Some(p) = self.decoder.next_packet() {
                self.accept(p)?;
            }
            let now = Instant::now();
            if polled && (self.awaiting.is_none() || now >= deadline) {
                return Ok(());
            }
            let timeout = match self.awaiting {
                Some(_) => deadline.saturating_duration_since(now),
                None => Duration::ZERO,
            };
            let revents = self.port.poll(libc::POLLIN, timeout)?;
            polled = true;
            if revents & libc::POLLIN != 0 {
                self.port.read_into(&mut self.decoder)?;
            }
        }
    }

    fn accept(&mut self, packet: Result<DevicePacket, PacketError>) -> Result<(), DeviceError> {
        match packet {
            // A late answer to a repeated hello.
            Ok(DevicePacket::Info(_)) => Ok(()),
            Ok(DevicePacket::State(s)) => {
                let (sample, force) = state_in_si(&self.spec, &s).map_err(|why| self.protocol(why))?;
                self.sample = sample;
                self.applied_force = force;
                self.status = s.status;
                if s.status & STATUS_HOST_SILENT != 0 {
                    self.watchdog_trips += 1;
                }
                if self.awaiting == Some(s.echo) {
                    self.awaiting = None;
                }
                self.last_valid = Instant::now();
                Ok(())
            }
            Err(e) => Err(self.protocol(e.to_string())),
        }
    }
}

impl Device for SerialDevice {
    fn spec(&self) -> DeviceSpec {
        self.spec
    }

    /// The newest valid state, after waiting at most [`SerialOptions::read_wait`] for the answer
    /// to the last force packet. `dt` is ignored.
    fn read(&mut self, _dt: f64) -> Result<DeviceSample, DeviceError> {
        self.pump(self.options.read_wait)?;
        if self.awaiting.is_some() {
            self.timeouts += 1;
        }
        let quiet = self.last_valid.elapsed();
        if quiet > self.options.silent_after {
            return Err(DeviceError::Silent {
                device: self.port.device.clone(),
                ms: quiet.as_millis() as u64,
            });
        }
        Ok(self.sample)
    }

    /// Sends one active force packet: `force` clamped to the device's maximum, in µN.
    fn write_force(&mut self, force: f64) -> Result<(), DeviceError> {
        let force_un = newtons_to_micronewtons(clamp_force(force, self.spec.max_force));
        self.send(FLAG_ACTIVE, force_un)?;
        self.force_live = true;
        Ok(())
    }

    /// Sends an inactive zero-force packet and waits up to [`SerialOptions::silent_after`] for the
    /// device to confirm it renders no force.
    fn close(&mut self) -> Result<(), DeviceError> {
        self.send(0, 0)?;
        self.force_live = false;
        self.pump(self.options.silent_after)?;
        if self.awaiting.is_some() {
            return Err(DeviceError::Silent {
                device: self.port.device.clone(),
                ms: self.options.silent_after.as_millis() as u64,
            });
        }
        if self.applied_force != 0.0 {
            return Err(self.protocol(format!(
                "still renders {:.6} N after the zero-force packet",
                self.applied_force
            )));
        }
        Ok(())
    }
}

impl Drop for SerialDevice {
    fn drop(&mut self) {
        if self.force_live {
            // Best effort: the device's own watchdog zeroes the force 10 ms later anyway.
            let _ = self.send(0, 0);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn state(seq: u16) -> StatePacket {
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

    fn info() -> InfoPacket {
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

    fn decode_all(d: &mut Decoder) -> Vec<Result<DevicePacket, PacketError>> {
        std::iter::from_fn(|| d.next_packet()).collect()
    }

    #[test]
    fn the_crc_is_ccitt_false() {
        assert_eq!(crc16(b"123456789"), 0x29B1);
        assert_eq!(crc16(b""), 0xFFFF);
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
                0xA5, b'S', 1, 2, 0x04, 0x03, 0x06, 0x05, 0x07, 0x08, 0x09, 0x0A, 0xFE, 0xFF, 0xFF, 0xFF, 3, 0, 0x0C,
                0x0D, 0x0E, 0x0F
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
                0xA5, b'I', 1, 0, 0x01, 0x02, 0x03, 0x04, 0x05, 0x06, 0x07, 0x08, 0xFF, 0xFF, 0xFF, 0xFF, 0x00, 0x01,
                0, 0, 0x0A, 0x0B, 0x0C, 0x0D, 0x0E, 0x0F, 0x10, 0x11, 0x12, 0x13
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

    #[test]
    fn implausible_limits_are_refused() {
        assert!(
            InfoPacket {
                max_force_un: 0,
                ..info()
            }
            .spec()
            .unwrap_err()
            .contains("maximum force of 0")
        );
        assert!(
            InfoPacket {
                max_force_un: -5,
                ..info()
            }
            .spec()
            .is_err()
        );
        assert!(
            InfoPacket {
                travel_um: [0, 10],
                ..info()
            }
            .spec()
            .unwrap_err()
            .contains("does not contain 0")
        );
        assert!(
            InfoPacket {
                travel_um: [-10, -1],
                ..info()
            }
            .spec()
            .is_err()
        );
        assert!(
            InfoPacket {
                max_stiffness_mn_m: 0,
                ..info()
            }
            .spec()
            .is_err()
        );
        assert!(
            InfoPacket {
                max_damping_mns_m: 0,
                ..info()
            }
            .spec()
            .is_err()
        );
        assert!(InfoPacket { rate_hz: 0, ..info() }.spec().is_err());
    }

    #[test]
    fn the_serial_argument_is_a_path_with_an_optional_baud_rate() {
        assert_eq!(parse_serial_arg("/dev/ttyACM0").unwrap(), ("/dev/ttyACM0", 115_200));
        assert_eq!(
            parse_serial_arg("/dev/ttyUSB0@1000000").unwrap(),
            ("/dev/ttyUSB0", 1_000_000)
        );
        assert_eq!(parse_serial_arg("/dev/by-id/a@b").unwrap(), ("/dev/by-id/a@b", 115_200));
        let e = |a: &str| parse_serial_arg(a).unwrap_err().to_string();
        assert!(e("/dev/ttyUSB0@").contains("no baud rate after '@'"));
        assert!(e("/dev/ttyUSB0@12345").contains("12345 baud is not supported"));
        assert!(e("/dev/ttyUSB0@99999999999").contains("too large"));
        assert!(e("@115200").contains("needs a path"));
        assert!(e("/dev/ttyUSB0@12345").contains("\"serial:/dev/ttyUSB0@12345\""));
    }

    #[test]
    fn the_sketch_speaks_the_same_protocol() {
        let ino = include_str!("../firmware/hapkit_nanopush/hapkit_nanopush.ino");
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

    fn any_state() -> impl Strategy<Value = StatePacket> {
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

    fn any_info() -> impl Strategy<Value = InfoPacket> {
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
