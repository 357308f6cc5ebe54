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
//! Wire time bounds the rate: an exchange is [`EXCHANGE_BYTES`] = 12 + 24 = 36 bytes, 10 bits a
//! byte on a UART ([`exchange_wire_time`]); the host uses at most [`LINK_SHARE`] (80 %) of the link
//! ([`link_rate_limit_hz`]: 2222 Hz at the default [`DEFAULT_BAUD`] of 1 000 000, exact for a
//! 16 MHz AVR; 256 Hz at 115 200). The bridge runs at the lesser of `--rate-hz`, the device's
//! declared rate and that limit ([`negotiate_rate`]), and refuses a device that cannot carry
//! [`MIN_RATE_HZ`] (500 Hz), naming the numbers. A board whose MCU speaks USB itself (ATmega32U4,
//! SAMD, RP2040, Teensy) ignores the baud rate; full-speed USB (1 ms frames) reaches 0.5-1 kHz
//! request/response.
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
//! - A late answer or a state out of the device's physical range (a position outside its travel
//!   by more than [`travel_margin`], a speed above [`MAX_SPEED`], a rendered force above its
//!   maximum plus 1 µN) is counted and the previous state holds for up to [`HOLD_CYCLES`] cycles
//!   (one lost packet does not zero the force); past that the read fails:
//!   [`DeviceError::Silent`] (also when no valid state packet came for
//!   [`SerialOptions::silent_after`], 20 ms) or [`DeviceError::Protocol`]. Another protocol
//!   version is [`DeviceError::Protocol`]. Such values are never passed on.
//! - A hang-up, an I/O error or a vanished path is [`DeviceError::Lost`] (an unplugged cable): the
//!   bridge zeroes the force and reopens the device by its path ([`conformance`] checks a board).
//! - [`Device::close`] sends an inactive zero-force packet and waits for the device to confirm it
//!   renders nothing; dropping a [`SerialDevice`] that last sent a live force sends one too.
//! - The port is opened exclusive (`TIOCEXCL`): a second bridge cannot drive the same motor.

pub mod conformance;
mod decoder;
mod device;
pub mod fake;
#[cfg(test)]
mod fixtures;
mod port;
mod protocol;
mod rate;

pub use decoder::Decoder;
pub use device::HOLD_CYCLES;
pub use device::{SerialDevice, SerialOptions};
pub use port::parse_serial_arg;
pub use protocol::{
    ANSWER_DEADLINE_MS, CRC_INIT, CRC_POLY, DEFAULT_BAUD, DEVICE_SILENCE_MS, DevicePacket, EXCHANGE_BYTES, FLAG_ACTIVE,
    FLAG_HELLO, FORCE_LEN, ForcePacket, INFO_LEN, InfoPacket, KIND_FORCE, KIND_INFO, KIND_STATE, LINK_SHARE, MAX_SPEED,
    MIN_RATE_HZ, PLAUSIBLE_MAX_DAMPING, PLAUSIBLE_MAX_FORCE_N, PLAUSIBLE_MAX_RATE_HZ, PLAUSIBLE_MAX_STIFFNESS,
    PLAUSIBLE_TRAVEL_END_M, PROTOCOL_VERSION, PacketError, STATE_LEN, STATUS_FORCE_LIMITED, STATUS_HOST_SILENT, SYNC,
    StatePacket, TRAVEL_MARGIN_MIN, TRAVEL_TOLERANCE, UART_BITS_PER_BYTE, crc16, exchange_wire_time,
    link_rate_limit_hz, newtons_to_micronewtons, state_in_si, travel_margin,
};
pub use rate::negotiate_rate;

// Named by the links in the module documentation.
#[cfg(doc)]
use crate::device::{BUTTON_CLUTCH, BUTTON_ENGAGE, Device, DeviceError, clamp_force};
