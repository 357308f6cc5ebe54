//! [`SerialDevice`], the [`Device`] on a serial port: the hello on opening, then one force packet
//! and one state packet a cycle, with its counters and time-outs.

use std::time::{Duration, Instant};

use super::decoder::Decoder;
use super::port::{Port, parse_serial_arg};
use super::protocol::{
    ANSWER_DEADLINE_MS, DEFAULT_BAUD, DevicePacket, FLAG_ACTIVE, FLAG_HELLO, ForcePacket, PacketError,
    STATUS_HOST_SILENT, link_rate_limit_hz, newtons_to_micronewtons, state_in_si,
};
use crate::device::{Device, DeviceError, DeviceFaults, DeviceSample, DeviceSpec, clamp_force};

// Named by a link in the documentation of `SerialDevice::status`.
#[cfg(doc)]
use super::protocol::STATUS_FORCE_LIMITED;

/// How often a hello is repeated while opening.
const HELLO_RETRY: Duration = Duration::from_millis(100);
/// Cycles in a row without a good state (a late answer, an out-of-range state) during which the
/// host keeps the previous state, so the force computed from it holds; then [`Device::read`]
/// fails and the bridge zeroes the force until good states come again.
pub const HOLD_CYCLES: u32 = 3;

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
            read_wait: Duration::from_millis(ANSWER_DEADLINE_MS),
            silent_after: Duration::from_millis(20),
            open_timeout: Duration::from_secs(3),
        }
    }
}

/// A Hapkit-class device on a serial port (see the [module documentation](super) for the protocol).
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
    seq_gaps: u64,
    out_of_range: u64,
    /// The device's newest sequence number, and the bad packets counted when it came.
    device_seq: Option<u16>,
    bad_at_seq: u64,
    /// Cycles in a row without a good state.
    missed: u32,
    /// Status byte of the newest state packet, valid or not (to see the watchdog bit rise).
    prev_status: u8,
    /// Why the newest state was refused, while it is.
    refused: Option<String>,
    /// The last packet sent was active: dropping sends an inactive one.
    force_live: bool,
}

impl SerialDevice {
    /// Opens `ARG` of `--device serial:ARG`: `PATH` at [`DEFAULT_BAUD`] or `PATH@BAUD`
    /// (`/dev/ttyUSB0@1000000`), with the default time-outs.
    pub fn open(arg: &str) -> Result<SerialDevice, DeviceError> {
        SerialDevice::open_within(arg, SerialOptions::default().open_timeout)
    }

    /// [`SerialDevice::open`], waiting at most `open_timeout` for the device's answer (a reopen
    /// after a loss tries often and briefly, so that a signal ends it promptly).
    pub fn open_within(arg: &str, open_timeout: Duration) -> Result<SerialDevice, DeviceError> {
        let (path, baud) = parse_serial_arg(arg)?;
        SerialDevice::open_with(
            path,
            SerialOptions {
                baud,
                open_timeout,
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
            seq_gaps: 0,
            out_of_range: 0,
            device_seq: None,
            bad_at_seq: 0,
            missed: 0,
            prev_status: 0,
            refused: None,
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

    /// The baud rate the port was opened at.
    pub fn baud(&self) -> u32 {
        self.options.baud
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
        let seq = match &packet {
            Ok(DevicePacket::Info(i)) => Some(i.seq),
            Ok(DevicePacket::State(s)) => Some(s.seq),
            Err(_) => None,
        };
        if let Some(seq) = seq {
            // Packets dropped for their checksum are counted there, not again as a gap.
            let bad = self.decoder.bad_packets();
            if let Some(prev) = self.device_seq {
                let missing = u64::from(seq.wrapping_sub(prev).wrapping_sub(1));
                if missing > bad - self.bad_at_seq {
                    self.seq_gaps += 1;
                }
            }
            self.device_seq = Some(seq);
            self.bad_at_seq = bad;
        }
        match packet {
            // A late answer to a repeated hello.
            Ok(DevicePacket::Info(_)) => Ok(()),
            Ok(DevicePacket::State(s)) => {
                if self.awaiting == Some(s.echo) {
                    self.awaiting = None;
                }
                // A trip is the bit rising: a device stuck with it set trips once, not each packet.
                if s.status & STATUS_HOST_SILENT != 0 && self.prev_status & STATUS_HOST_SILENT == 0 {
                    self.watchdog_trips += 1;
                }
                self.prev_status = s.status;
                // It answered: it is not silent, even if what it says cannot be true.
                self.last_valid = Instant::now();
                match state_in_si(&self.spec, &s) {
                    Ok((sample, force)) => {
                        self.sample = sample;
                        self.applied_force = force;
                        self.status = s.status;
                        self.last_valid = Instant::now();
                        self.refused = None;
                    }
                    // Dropped and counted; the previous state holds (see `read`).
                    Err(why) => {
                        self.out_of_range += 1;
                        self.refused = Some(why);
                    }
                }
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
    /// to the last force packet. A late answer or a state out of range leaves the previous state
    /// in place for up to [`HOLD_CYCLES`] cycles in a row (the force computed from it holds);
    /// past that the read fails ([`DeviceError::Silent`] for late answers, [`DeviceError::Protocol`]
    /// for bad states) until good states come again. `dt` is ignored.
    fn read(&mut self, _dt: f64) -> Result<DeviceSample, DeviceError> {
        let before = self.out_of_range;
        self.pump(self.options.read_wait)?;
        let late = self.awaiting.is_some();
        if late {
            self.timeouts += 1;
        }
        if late || self.out_of_range != before {
            self.missed += 1;
        } else {
            self.missed = 0;
        }
        let quiet = self.last_valid.elapsed();
        if quiet > self.options.silent_after || (late && self.missed > HOLD_CYCLES) {
            return Err(DeviceError::Silent {
                device: self.port.device.clone(),
                ms: quiet.as_millis() as u64,
            });
        }
        if self.missed > HOLD_CYCLES
            && let Some(why) = &self.refused
        {
            return Err(self.protocol(why.clone()));
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

    /// The fastest rate the device declares and its link carries: the lesser of its info
    /// packet's rate and [`link_rate_limit_hz`] at the port's baud.
    fn max_rate_hz(&self) -> Option<f64> {
        Some(f64::from(self.rate_hz).min(link_rate_limit_hz(self.options.baud)))
    }

    fn declared_rate_hz(&self) -> Option<f64> {
        Some(f64::from(self.rate_hz))
    }

    fn faults(&self) -> DeviceFaults {
        DeviceFaults {
            bad_packets: self.bad_packets(),
            timeouts: self.timeouts,
            seq_gaps: self.seq_gaps,
            out_of_range: self.out_of_range,
            watchdog_trips: self.watchdog_trips,
            ..DeviceFaults::default()
        }
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
