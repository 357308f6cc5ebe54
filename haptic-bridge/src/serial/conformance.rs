//! The conformance test a hardware maker runs against their board
//! (`nanopush-haptic conformance serial:PATH[@BAUD]`): each rule of the protocol that the bridge
//! relies on, checked on the wire with the numbers, one [`Check`] each.
//!
//! The checks, in order: the hello is answered with an info packet within 3 s; the limits are
//! plausible; the declared rate and the baud carry at least [`MIN_RATE_HZ`]; 200 exchanges are
//! each answered within the answer deadline with the right echo, a valid CRC and the device's
//! sequence number one on; a corrupted force packet is ignored (no answer); an inactive packet
//! renders no force whatever its force field says; an active force is rendered, and one above
//! the device's maximum is clamped to it; the watchdog zeroes the force within 11 ms of silence
//! and says so once (status bit 0); a closing zero-force packet renders nothing.

use std::time::{Duration, Instant};

use super::decoder::Decoder;
use super::port::{Port, parse_serial_arg};
use super::protocol::{
    ANSWER_DEADLINE_MS, DEVICE_SILENCE_MS, DevicePacket, FLAG_ACTIVE, FLAG_HELLO, ForcePacket, InfoPacket, MIN_RATE_HZ,
    STATUS_HOST_SILENT, StatePacket, link_rate_limit_hz,
};
use crate::device::DeviceError;

/// How many exchanges the timing check runs.
pub const EXCHANGES: usize = 200;

/// One rule checked: its name, whether the board passed, and the numbers.
#[derive(Debug, Clone, PartialEq)]
pub struct Check {
    /// What was checked.
    pub name: &'static str,
    /// It held.
    pub pass: bool,
    /// The numbers (what was sent, what came back, the limits).
    pub detail: String,
}

impl std::fmt::Display for Check {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let verdict = if self.pass { "PASS" } else { "FAIL" };
        write!(f, "{verdict} {}: {}", self.name, self.detail)
    }
}

/// The host's side of the test: the port, a receiver and the host's sequence number.
struct Host {
    port: Port,
    decoder: Decoder,
    seq: u16,
    /// Bad packets counted before the timing check.
    bad_before: u64,
    /// The newest packet error (another version, an unknown length), to name it.
    last_error: Option<String>,
}

impl Host {
    fn send(&mut self, flags: u8, force_un: i32) -> Result<u16, DeviceError> {
        let seq = self.seq;
        self.port.write_all(&ForcePacket { seq, flags, force_un }.encode())?;
        self.seq = seq.wrapping_add(1);
        Ok(seq)
    }

    /// The next packet within `wait`, if any.
    fn next(&mut self, wait: Duration) -> Result<Option<DevicePacket>, DeviceError> {
        let deadline = Instant::now() + wait;
        loop {
            if let Some(p) = self.decoder.next_packet() {
                match p {
                    Ok(p) => return Ok(Some(p)),
                    // Counted by the decoder; named by the check that misses its answer.
                    Err(e) => {
                        self.last_error = Some(e.to_string());
                        continue;
                    }
                }
            }
            let now = Instant::now();
            if now >= deadline {
                return Ok(None);
            }
            if self.port.poll(libc::POLLIN, deadline - now)? & libc::POLLIN != 0 {
                self.port.read_into(&mut self.decoder)?;
            }
        }
    }

    /// The state answering `seq` within `wait` (other packets are skipped), and how long it took.
    fn answer(&mut self, seq: u16, wait: Duration) -> Result<Option<(StatePacket, Duration)>, DeviceError> {
        let start = Instant::now();
        while let Some(p) = self.next(wait.saturating_sub(start.elapsed()))? {
            if let DevicePacket::State(s) = p
                && s.echo == seq
            {
                return Ok(Some((s, start.elapsed())));
            }
        }
        Ok(None)
    }

    /// One exchange: `flags` and `force_un` out, its state back within `wait`.
    fn exchange(&mut self, flags: u8, force_un: i32, wait: Duration) -> Result<Option<StatePacket>, DeviceError> {
        let seq = self.send(flags, force_un)?;
        Ok(self.answer(seq, wait)?.map(|(s, _)| s))
    }
}

fn check(name: &'static str, pass: bool, detail: String) -> Check {
    Check { name, pass, detail }
}

/// What the timing check holds the device to.
#[derive(Clone, Copy, Debug)]
pub struct Deadline {
    /// An answer later than this after its request, measured on the host, is late.
    pub answer: Duration,
}

impl Deadline {
    /// The specification's: every force packet answered within [`ANSWER_DEADLINE_MS`].
    pub const SPEC: Deadline = Deadline {
        answer: Duration::from_millis(ANSWER_DEADLINE_MS),
    };
}

/// Runs every check against the device at `arg` (`PATH[@BAUD]`), the timing against the
/// specification's deadline. An I/O error on the way (the board unplugged) ends the list with a
/// failed check naming it.
pub fn run(arg: &str) -> Result<Vec<Check>, DeviceError> {
    run_with(arg, Deadline::SPEC)
}

/// [`run`] with another answer deadline. The time is measured on the host, so the host's
/// scheduling counts against the device: a fake device in a test process on a loaded machine is
/// judged with a looser deadline, and the rule itself by a device that is late by construction.
pub fn run_with(arg: &str, deadline: Deadline) -> Result<Vec<Check>, DeviceError> {
    let (path, baud) = parse_serial_arg(arg)?;
    let port = Port::open(path, baud)?;
    let mut host = Host {
        port,
        decoder: Decoder::new(),
        seq: 0,
        bad_before: 0,
        last_error: None,
    };
    let mut checks = Vec::new();
    let Some(info) = hello(&mut host, &mut checks)? else {
        return Ok(checks);
    };
    if !limits(&info, baud, &mut checks) {
        // No force is commanded to a board whose limits cannot be believed.
        return Ok(checks);
    }
    if let Err(e) = on_the_wire(&mut host, &info, deadline.answer, &mut checks) {
        checks.push(check("the board stays connected", false, e.to_string()));
    }
    Ok(checks)
}

/// The hello is answered with an info packet of this protocol's version within 3 s.
fn hello(host: &mut Host, checks: &mut Vec<Check>) -> Result<Option<InfoPacket>, DeviceError> {
    let start = Instant::now();
    let deadline = start + Duration::from_secs(3);
    while Instant::now() < deadline {
        let seq = host.send(FLAG_HELLO, 0)?;
        let retry = Instant::now() + Duration::from_millis(100);
        while let Some(p) = host.next(retry.saturating_duration_since(Instant::now()))? {
            if let DevicePacket::Info(info) = p
                && info.echo <= seq
            {
                checks.push(check(
                    "hello answered with an info packet within 3 s",
                    true,
                    format!(
                        "after {:.0} ms, echo {}",
                        start.elapsed().as_secs_f64() * 1e3,
                        info.echo
                    ),
                ));
                return Ok(Some(info));
            }
        }
    }
    checks.push(check(
        "hello answered with an info packet within 3 s",
        false,
        match &host.last_error {
            Some(e) => format!("no info packet in 3 s: {e}"),
            None => format!("no info packet in 3 s ({} bad packets)", host.decoder.bad_packets()),
        },
    ));
    Ok(None)
}

/// The limits are plausible, and the declared rate and the baud carry the floor. Whether the
/// limits can be believed (forces are commanded only then).
fn limits(info: &InfoPacket, baud: u32, checks: &mut Vec<Check>) -> bool {
    let plausible = info.spec().is_ok();
    match info.spec() {
        Ok(s) => checks.push(check(
            "limits plausible",
            true,
            format!(
                "{} N, travel [{:.1}, {:.1}] mm, {} N/m, {} N·s/m, {} Hz",
                s.max_force,
                s.travel[0] * 1e3,
                s.travel[1] * 1e3,
                s.max_stiffness,
                s.max_damping,
                info.rate_hz
            ),
        )),
        Err(why) => checks.push(check("limits plausible", false, why)),
    }
    let rate = f64::from(info.rate_hz).min(link_rate_limit_hz(baud));
    checks.push(check(
        "rate and baud carry the floor",
        rate >= MIN_RATE_HZ,
        format!(
            "declared {} Hz, link limit {:.0} Hz at {baud} baud: {rate:.0} Hz against the floor {MIN_RATE_HZ:.0} Hz",
            info.rate_hz,
            link_rate_limit_hz(baud)
        ),
    ));
    plausible
}

/// The checks on the wire, after the hello.
fn on_the_wire(
    host: &mut Host,
    info: &InfoPacket,
    deadline: Duration,
    checks: &mut Vec<Check>,
) -> Result<(), DeviceError> {
    let patient = Duration::from_millis(50);
    // Settle: the first state, then the bad-packet count to compare with.
    host.exchange(0, 0, patient)?;
    while host.next(Duration::from_millis(5))?.is_some() {}
    host.bad_before = host.decoder.bad_packets();
    timing(host, deadline, checks)?;
    corrupted(host, patient, checks)?;
    let max_un = info.max_force_un;
    rendering(host, max_un, patient, checks)?;
    watchdog(host, max_un, patient, checks)?;
    let closed = host.exchange(0, 0, patient)?;
    checks.push(check(
        "a closing zero-force packet renders nothing",
        closed.is_some_and(|s| s.force_un == 0),
        format!("renders {:?} µN", closed.map(|s| s.force_un)),
    ));
    Ok(())
}

/// [`EXCHANGES`] exchanges, each answered within `deadline`, the echo right, the CRC valid and the
/// device's sequence number one on.
fn timing(host: &mut Host, deadline: Duration, checks: &mut Vec<Check>) -> Result<(), DeviceError> {
    let (mut late, mut worst, mut gaps) = (0, Duration::ZERO, 0);
    let mut prev_seq: Option<u16> = None;
    for _ in 0..EXCHANGES {
        let seq = host.send(0, 0)?;
        // Waited a little past the deadline (poll counts whole ms), judged on the time measured.
        match host.answer(seq, deadline + Duration::from_millis(2))? {
            Some((s, took)) => {
                worst = worst.max(took);
                if took > deadline {
                    late += 1;
                }
                if prev_seq.is_some_and(|p| s.seq != p.wrapping_add(1)) {
                    gaps += 1;
                }
                prev_seq = Some(s.seq);
            }
            None => {
                late += 1;
                prev_seq = None;
                // Let a late answer land before the next request.
                host.answer(seq, Duration::from_millis(20))?;
            }
        }
        std::thread::sleep(Duration::from_micros(200));
    }
    checks.push(check(
        "every force packet answered in time with its echo",
        late == 0,
        format!(
            "{EXCHANGES} exchanges: {late} not answered within {} ms (the wire time included); slowest answer {}",
            deadline.as_millis(),
            if worst > Duration::ZERO {
                format!("{:.2} ms", worst.as_secs_f64() * 1e3)
            } else {
                "– (none came)".into()
            }
        ),
    ));
    checks.push(check(
        "the device's sequence number goes one on",
        gaps == 0,
        format!("{gaps} jumps other than +1"),
    ));
    let bad = host.decoder.bad_packets() - host.bad_before;
    checks.push(check(
        "packets framed and checksummed right",
        bad == 0,
        format!("{bad} bad packets"),
    ));
    Ok(())
}

/// A force packet with a wrong CRC is not answered (and so not applied).
fn corrupted(host: &mut Host, patient: Duration, checks: &mut Vec<Check>) -> Result<(), DeviceError> {
    let seq = host.seq;
    let mut bytes = ForcePacket {
        seq,
        flags: FLAG_ACTIVE,
        force_un: 1,
    }
    .encode();
    let last = bytes.len() - 1;
    bytes[last] ^= 0x5A;
    host.port.write_all(&bytes)?;
    host.seq = seq.wrapping_add(1);
    // Any state at all within 10 ms answers it (whatever its echo says).
    let answered = loop {
        match host.next(Duration::from_millis(10))? {
            Some(DevicePacket::State(s)) => break Some(s),
            Some(DevicePacket::Info(_)) => continue,
            None => break None,
        }
    };
    checks.push(check(
        "a corrupted force packet is ignored",
        answered.is_none(),
        match answered {
            Some(s) => format!("answered it (echo {}, renders {} µN)", s.echo, s.force_un),
            None => "no answer in 10 ms".into(),
        },
    ));
    host.exchange(0, 0, patient)?;
    Ok(())
}

/// An inactive packet renders nothing; an active one its force; one above the maximum the maximum.
fn rendering(host: &mut Host, max_un: i32, patient: Duration, checks: &mut Vec<Check>) -> Result<(), DeviceError> {
    let tenth = (max_un / 10).max(1);
    let inactive = host.exchange(0, tenth, patient)?;
    checks.push(check(
        "an inactive packet renders no force",
        inactive.is_some_and(|s| s.force_un == 0),
        format!(
            "sent {tenth} µN inactive, renders {:?} µN",
            inactive.map(|s| s.force_un)
        ),
    ));
    // A device may take a cycle or two to apply a command: the next answers show it.
    let follows = settle(host, FLAG_ACTIVE, tenth, patient)?;
    checks.push(check(
        "an active force is rendered",
        follows.is_some_and(|f| (f - tenth).abs() <= 1),
        format!("sent {tenth} µN, renders {follows:?} µN"),
    ));
    let over = max_un.saturating_mul(2);
    let clamped = settle(host, FLAG_ACTIVE, over, patient)?;
    checks.push(check(
        "a force above the maximum is clamped to it",
        clamped.is_some_and(|f| f.abs() <= max_un.saturating_add(1) && f > 0),
        format!("sent {over} µN, renders {clamped:?} µN, maximum {max_un} µN"),
    ));
    host.exchange(0, 0, patient)?;
    Ok(())
}

/// The force the device renders after a few exchanges of the same command.
fn settle(host: &mut Host, flags: u8, force_un: i32, patient: Duration) -> Result<Option<i32>, DeviceError> {
    let mut last = None;
    for _ in 0..5 {
        last = host.exchange(flags, force_un, patient)?.map(|s| s.force_un);
        std::thread::sleep(Duration::from_millis(1));
    }
    Ok(last)
}

/// Active force, then silence: after 8 ms the watchdog has not tripped (not too early); after
/// 12 ms it has (within the 11 ms the specification allows) and the next state says so, once.
/// (The wire cannot show the force rendered during the silence: the bit is the device's word.)
fn watchdog(host: &mut Host, max_un: i32, patient: Duration, checks: &mut Vec<Check>) -> Result<(), DeviceError> {
    let tenth = (max_un / 10).max(1);
    // Returns whether the bit was set in the two states after the silence, and how long the
    // silence really was (a loaded host may oversleep).
    let mut silent = |ms: u64| -> Result<(bool, bool, Duration), DeviceError> {
        settle(host, FLAG_ACTIVE, tenth, patient)?;
        // The silence starts when the last packet was sent, not when its answer came.
        let last = host.send(FLAG_ACTIVE, tenth)?;
        let quiet = Instant::now();
        host.answer(last, patient)?;
        std::thread::sleep(Duration::from_millis(ms).saturating_sub(quiet.elapsed()));
        let seq = host.send(FLAG_ACTIVE, tenth)?;
        let gap = quiet.elapsed();
        let first = host.answer(seq, patient)?.map(|(s, _)| s);
        let second = host.exchange(FLAG_ACTIVE, tenth, patient)?;
        let bit = |s: Option<StatePacket>| s.is_some_and(|s| s.status & STATUS_HOST_SILENT != 0);
        Ok((bit(first), bit(second), gap))
    };
    // Not too early: a silence of 8 ms must not trip it (tried again if the host overslept).
    let mut early = false;
    for _ in 0..5 {
        let (bit, _, gap) = silent(DEVICE_SILENCE_MS - 2)?;
        if gap < Duration::from_millis(DEVICE_SILENCE_MS - 1) {
            early = bit;
            break;
        }
    }
    let (tripped, still, _) = silent(DEVICE_SILENCE_MS + 2)?;
    host.exchange(0, 0, patient)?;
    checks.push(check(
        "the watchdog zeroes the force after 10 ms of silence and says so once",
        !early && tripped && !still,
        format!(
            "after {} ms of silence status bit 0 {}; after {} ms {} in the next state and {} in the one after",
            DEVICE_SILENCE_MS - 2,
            if early { "set (too early)" } else { "clear" },
            DEVICE_SILENCE_MS + 2,
            if tripped { "set" } else { "not set" },
            if still { "still set" } else { "clear" }
        ),
    ));
    Ok(())
}
