//! A fake serial board for end-to-end tests and demonstrations: it speaks the protocol on a
//! pseudo-terminal as the reference firmware does (a hello answered with an info packet, each
//! force packet with a state packet, the 10 ms host-silence watchdog), with the simulated Hapkit
//! handle and scripted hand of `--device sim` ([`SimDevice`]) as its motor and sensor. Its path
//! can be a symlink (as a udev `/dev/serial/by-id/` link is), and [`FakeBoard::unplug`] pulls the
//! cable: the master side closes and the bridge sees a hang-up.

use std::ffi::CStr;
use std::os::fd::{AsRawFd, FromRawFd, OwnedFd};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use super::protocol::{
    DEVICE_SILENCE_MS, FLAG_ACTIVE, FLAG_HELLO, FORCE_LEN, ForcePacket, InfoPacket, KIND_FORCE, STATUS_HOST_SILENT,
    SYNC, StatePacket, newtons_to_micronewtons,
};
use crate::device::{Device, LinkView};
use crate::operator::Script;
use crate::sim::SimDevice;

/// What the board shares with whoever drives it.
#[derive(Default)]
struct Shared {
    stop: AtomicBool,
    /// The hand starts its script (the person "sees" the engagement).
    engaged: AtomicBool,
    /// Every active force packet: when it came and its force (µN), the last [`LOG_LEN`].
    forces: Mutex<std::collections::VecDeque<(Instant, i32)>>,
}

/// How many force packets [`FakeBoard::forces`] keeps.
const LOG_LEN: usize = 100_000;

/// A fake board on a pseudo-terminal, answering in a thread of its own.
pub struct FakeBoard {
    shared: Arc<Shared>,
    thread: Option<JoinHandle<()>>,
    /// The symlink pointing at the terminal, if any.
    link: Option<PathBuf>,
    /// The terminal's own path.
    tty: String,
}

/// Opens a pseudo-terminal: the master (non-blocking, close-on-exec) and the slave's path.
fn open_pty() -> std::io::Result<(OwnedFd, String)> {
    let (mut master, mut slave) = (-1, -1);
    // SAFETY: out-pointers to two ints; no name buffer, default termios and window size.
    let rc = unsafe {
        libc::openpty(
            &mut master,
            &mut slave,
            std::ptr::null_mut(),
            std::ptr::null(),
            std::ptr::null(),
        )
    };
    if rc != 0 {
        return Err(std::io::Error::last_os_error());
    }
    // SAFETY: both were just opened and are ours.
    let (master, slave) = unsafe { (OwnedFd::from_raw_fd(master), OwnedFd::from_raw_fd(slave)) };
    let mut name = [0 as libc::c_char; 256];
    // SAFETY: the buffer is valid for its length.
    if unsafe { libc::ttyname_r(slave.as_raw_fd(), name.as_mut_ptr(), name.len()) } != 0 {
        return Err(std::io::Error::other("ttyname_r failed"));
    }
    // SAFETY: ttyname_r wrote a NUL-terminated string.
    let path = unsafe { CStr::from_ptr(name.as_ptr()) }.to_string_lossy().into_owned();
    // SAFETY: plain fcntl calls on an open descriptor. Close-on-exec: a process the caller
    // starts must not hold the master open, or pulling the cable would hang nothing up.
    unsafe {
        let flags = libc::fcntl(master.as_raw_fd(), libc::F_GETFL);
        libc::fcntl(master.as_raw_fd(), libc::F_SETFL, flags | libc::O_NONBLOCK);
        libc::fcntl(master.as_raw_fd(), libc::F_SETFD, libc::FD_CLOEXEC);
    }
    // The slave closes here: the bridge opens it by its path.
    drop(slave);
    Ok((master, path))
}

impl FakeBoard {
    /// Plugs a board in: a new terminal, `link` (if given) pointing at it, and a handle held by
    /// a hand that runs `script` once [`FakeBoard::engage`] is called.
    pub fn plug_in(link: Option<&Path>, script: Script) -> std::io::Result<FakeBoard> {
        let (master, tty) = open_pty()?;
        if let Some(link) = link {
            let _ = std::fs::remove_file(link);
            std::os::unix::fs::symlink(&tty, link)?;
        }
        let shared = Arc::new(Shared::default());
        let s = shared.clone();
        let thread = std::thread::Builder::new()
            .name("fake-board".into())
            .spawn(move || run(master, SimDevice::new(script, 1e-3), &s))?;
        Ok(FakeBoard {
            shared,
            thread: Some(thread),
            link: link.map(Path::to_path_buf),
            tty,
        })
    }

    /// The path to open: the symlink, or the terminal itself.
    pub fn path(&self) -> String {
        self.link
            .as_ref()
            .map_or_else(|| self.tty.clone(), |l| l.display().to_string())
    }

    /// The person holding the handle starts the script (they see the engagement).
    pub fn engage(&self) {
        self.shared.engaged.store(true, Ordering::Relaxed);
    }

    /// The active force packets received (when, force in N), oldest first.
    pub fn forces(&self) -> Vec<(Instant, f64)> {
        let log = self.shared.forces.lock().expect("board lock");
        log.iter().map(|&(t, f)| (t, f64::from(f) * 1e-6)).collect()
    }

    /// Pulls the cable: the board stops, the terminal's master closes (a hang-up for whoever has
    /// it open) and the symlink goes.
    pub fn unplug(mut self) {
        self.stop();
    }

    fn stop(&mut self) {
        self.shared.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
        if let Some(link) = &self.link {
            let _ = std::fs::remove_file(link);
        }
    }
}

impl Drop for FakeBoard {
    fn drop(&mut self) {
        self.stop();
    }
}

/// The board's loop: force packets in, answers out, the watchdog, until stopped.
fn run(master: OwnedFd, mut sim: SimDevice, shared: &Shared) {
    let spec = sim.spec();
    let mut buf = Vec::new();
    let (mut seq, mut active, mut silent_latch) = (0u16, false, false);
    let mut last_packet = Instant::now();
    let started = Instant::now();
    while !shared.stop.load(Ordering::Relaxed) {
        let mut pfd = libc::pollfd {
            fd: master.as_raw_fd(),
            events: libc::POLLIN,
            revents: 0,
        };
        // SAFETY: one valid pollfd.
        unsafe { libc::poll(&mut pfd, 1, 1) };
        let mut chunk = [0u8; 256];
        loop {
            // SAFETY: `chunk` is valid for its length.
            let n = unsafe { libc::read(master.as_raw_fd(), chunk.as_mut_ptr().cast(), chunk.len()) };
            if n <= 0 {
                break;
            }
            buf.extend_from_slice(&chunk[..n as usize]);
        }
        for p in take_force_packets(&mut buf) {
            let dt = last_packet.elapsed().as_secs_f64().clamp(1e-4, 5e-3);
            last_packet = Instant::now();
            seq = seq.wrapping_add(1);
            if p.flags & FLAG_HELLO != 0 {
                let info = InfoPacket {
                    echo: p.seq,
                    seq,
                    max_force_un: newtons_to_micronewtons(spec.max_force),
                    travel_um: spec.travel.map(|t| (t * 1e6).round() as i32),
                    max_stiffness_mn_m: (spec.max_stiffness * 1e3).round() as u32,
                    max_damping_mns_m: (spec.max_damping * 1e3).round() as u32,
                    rate_hz: 1000,
                };
                write_all(&master, &info.encode());
                continue;
            }
            active = p.flags & FLAG_ACTIVE != 0;
            if active {
                let mut log = shared.forces.lock().expect("board lock");
                if log.len() == LOG_LEN {
                    log.pop_front();
                }
                log.push_back((Instant::now(), p.force_un));
            }
            let force = if active { f64::from(p.force_un) * 1e-6 } else { 0.0 };
            let _ = sim.write_force(force.clamp(-spec.max_force, spec.max_force));
            sim.observe(&LinkView {
                t: started.elapsed().as_secs_f64(),
                up: true,
                engaged: shared.engaged.load(Ordering::Relaxed),
                tip_z: f64::NAN,
            });
            let Ok(s) = sim.read(dt) else { continue };
            let rendered = newtons_to_micronewtons(force.clamp(-spec.max_force, spec.max_force));
            let state = StatePacket {
                status: if std::mem::take(&mut silent_latch) {
                    STATUS_HOST_SILENT
                } else {
                    0
                },
                echo: p.seq,
                seq,
                position_um: (s.position * 1e6).round() as i32,
                velocity_um_s: (s.velocity * 1e6).round() as i32,
                buttons: s.buttons as u8,
                force_un: rendered,
            };
            write_all(&master, &state.encode());
        }
        if active && last_packet.elapsed() >= Duration::from_millis(DEVICE_SILENCE_MS) {
            active = false;
            silent_latch = true;
            let _ = sim.write_force(0.0);
        }
    }
}

/// The valid force packets in `buf` (as the firmware frames them: resync on the sync byte, a
/// packet of another version or a bad checksum skipped).
fn take_force_packets(buf: &mut Vec<u8>) -> Vec<ForcePacket> {
    let mut out = Vec::new();
    loop {
        match buf.iter().position(|&b| b == SYNC) {
            Some(i) => drop(buf.drain(..i)),
            None => {
                buf.clear();
                return out;
            }
        }
        if buf.len() < 2 {
            return out;
        }
        if buf[1] != KIND_FORCE {
            buf.drain(..1);
            continue;
        }
        if buf.len() < FORCE_LEN {
            return out;
        }
        match ForcePacket::decode(&buf[..FORCE_LEN]) {
            Ok(p) => {
                out.push(p);
                buf.drain(..FORCE_LEN);
            }
            Err(_) => drop(buf.drain(..1)),
        }
    }
}

fn write_all(fd: &OwnedFd, mut bytes: &[u8]) {
    let deadline = Instant::now() + Duration::from_millis(100);
    while !bytes.is_empty() && Instant::now() < deadline {
        // SAFETY: `bytes` is valid for its length.
        let n = unsafe { libc::write(fd.as_raw_fd(), bytes.as_ptr().cast(), bytes.len()) };
        if n > 0 {
            bytes = &bytes[n as usize..];
        } else {
            std::thread::yield_now();
        }
    }
}
