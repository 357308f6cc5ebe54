//! The fake 1-DOF device on the master side of a pseudo-terminal, and the helpers the tests share.

use std::ffi::CStr;
use std::os::fd::{AsRawFd, FromRawFd, OwnedFd};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Condvar, Mutex, MutexGuard};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use nanopush_haptic::device::{Device, DeviceSample};
use nanopush_haptic::serial::{SerialDevice, SerialOptions, crc16};

/// How long any condition may take before the test fails.
pub const PATIENCE: Duration = Duration::from_secs(20);

// The fake device's limits, as its info packet reports them.
pub const MAX_FORCE_UN: i32 = 2_000_000;
pub const TRAVEL_UM: [i32; 2] = [-30_000, 30_000];
pub const STIFFNESS_MN_M: u32 = 300_000;
pub const DAMPING_MNS_M: u32 = 1_200;
pub const RATE_HZ: u16 = 1000;
/// The firmware's host-silence time-out.
pub const DEVICE_SILENCE: Duration = Duration::from_millis(10);

/// A pseudo-terminal: the master for the fake device, the slave's path for `SerialDevice`. The
/// slave stays open so the master never sees a hang-up between tests' steps.
pub fn open_pty() -> (OwnedFd, OwnedFd, String) {
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
    assert_eq!(rc, 0, "openpty: {}", std::io::Error::last_os_error());
    // SAFETY: both were just opened and are ours.
    let (master, slave) = unsafe { (OwnedFd::from_raw_fd(master), OwnedFd::from_raw_fd(slave)) };
    let mut name = [0 as libc::c_char; 256];
    // SAFETY: the buffer is valid for its length.
    let rc = unsafe { libc::ttyname_r(slave.as_raw_fd(), name.as_mut_ptr(), name.len()) };
    assert_eq!(rc, 0, "ttyname_r failed");
    // SAFETY: ttyname_r wrote a NUL-terminated string.
    let path = unsafe { CStr::from_ptr(name.as_ptr()) }.to_str().unwrap().to_owned();
    // SAFETY: plain fcntl on open descriptors. Close-on-exec: a bridge process the test starts
    // must not hold the master open, or pulling the "cable" (closing it) would hang nothing up.
    unsafe {
        let flags = libc::fcntl(master.as_raw_fd(), libc::F_GETFL);
        libc::fcntl(master.as_raw_fd(), libc::F_SETFL, flags | libc::O_NONBLOCK);
        libc::fcntl(master.as_raw_fd(), libc::F_SETFD, libc::FD_CLOEXEC);
        libc::fcntl(slave.as_raw_fd(), libc::F_SETFD, libc::FD_CLOEXEC);
    }
    (master, slave, path)
}

/// What the fake device is and what it saw.
pub struct World {
    /// Every valid force packet: (seq, flags, force µN as sent).
    pub received: Vec<(u16, u8, i32)>,
    /// Report this (position µm, velocity µm/s) instead of the model's.
    pub pose: Option<(i32, i32)>,
    /// The handle model: position (m), velocity (m/s).
    pub position: f64,
    pub velocity: f64,
    pub buttons: u8,
    /// Force rendered (µN).
    pub applied_un: i32,
    pub active: bool,
    /// The watchdog zeroed the force since the last state packet.
    pub silent_latch: bool,
    pub watchdog_trips: u32,
    /// Answer nothing (still read).
    pub mute: bool,
    /// Corrupt this many of the next state packets.
    pub corrupt: u32,
    /// Send these bytes before the next state packet.
    pub garbage: Vec<u8>,
    /// Protocol version of the packets it sends.
    pub version: u8,
    pub seq: u16,
    /// Pace the wire like a UART at this baud: each answer leaves after the request's and its own
    /// wire time (10 bits a byte).
    pub baud: Option<u32>,
    /// The control rate its info packet declares (Hz).
    pub rate_hz: u16,
    /// Its watchdog zeroes the force after 10 ms without a valid force packet.
    pub watchdog: bool,
    /// Skip this many of its own sequence numbers before the next state packet.
    pub skip_seq: u16,
    /// Hold each answer this long after reading its request (a slow firmware).
    pub answer_delay: Duration,
}

impl Default for World {
    fn default() -> World {
        World {
            received: Vec::new(),
            pose: None,
            position: 0.0,
            velocity: 0.0,
            buttons: 0,
            applied_un: 0,
            active: false,
            silent_latch: false,
            watchdog_trips: 0,
            mute: false,
            corrupt: 0,
            garbage: Vec::new(),
            version: 1,
            seq: 0,
            baud: None,
            rate_hz: RATE_HZ,
            watchdog: true,
            skip_seq: 0,
            answer_delay: Duration::ZERO,
        }
    }
}

impl World {
    /// One millisecond of the handle under the rendered force: 50 g, 1 N·s/m, end stops.
    pub fn step(&mut self) {
        let (mass, damping, dt) = (0.05, 1.0, 1e-3);
        let force = f64::from(self.applied_un) * 1e-6;
        self.velocity += (force - damping * self.velocity) / mass * dt;
        self.position += self.velocity * dt;
        let stop = 0.029;
        if self.position.abs() > stop {
            self.position = stop.copysign(self.position);
            self.velocity = 0.0;
        }
    }

    pub fn next_seq(&mut self) -> u16 {
        self.seq = self.seq.wrapping_add(1 + std::mem::take(&mut self.skip_seq));
        self.seq
    }

    pub fn state_bytes(&mut self, echo: u16) -> Vec<u8> {
        let (pos, vel) = self.pose.unwrap_or((
            (self.position * 1e6).round() as i32,
            (self.velocity * 1e6).round() as i32,
        ));
        let status = if std::mem::take(&mut self.silent_latch) {
            0x01
        } else {
            0
        };
        let mut b = vec![0xA5, b'S', self.version, status];
        b.extend(echo.to_le_bytes());
        b.extend(self.next_seq().to_le_bytes());
        b.extend(pos.to_le_bytes());
        b.extend(vel.to_le_bytes());
        b.extend([self.buttons, 0]);
        b.extend(self.applied_un.to_le_bytes());
        b.extend(crc16(&b).to_le_bytes());
        assert_eq!(b.len(), 24);
        b
    }

    pub fn info_bytes(&mut self, echo: u16) -> Vec<u8> {
        let mut b = vec![0xA5, b'I', self.version, 0];
        b.extend(echo.to_le_bytes());
        b.extend(self.next_seq().to_le_bytes());
        b.extend(MAX_FORCE_UN.to_le_bytes());
        b.extend(TRAVEL_UM[0].to_le_bytes());
        b.extend(TRAVEL_UM[1].to_le_bytes());
        b.extend(STIFFNESS_MN_M.to_le_bytes());
        b.extend(DAMPING_MNS_M.to_le_bytes());
        b.extend(self.rate_hz.to_le_bytes());
        b.extend(crc16(&b).to_le_bytes());
        assert_eq!(b.len(), 32);
        b
    }

    /// Applies one valid force packet; returns the answer.
    pub fn on_force(&mut self, seq: u16, flags: u8, force_un: i32) -> Vec<u8> {
        self.received.push((seq, flags, force_un));
        if flags & 0x02 != 0 {
            self.active = false;
            self.applied_un = 0;
            return self.info_bytes(seq);
        }
        self.active = flags & 0x01 != 0;
        self.applied_un = if self.active {
            force_un.clamp(-MAX_FORCE_UN, MAX_FORCE_UN)
        } else {
            0
        };
        self.step();
        let mut answer = std::mem::take(&mut self.garbage);
        let mut state = self.state_bytes(seq);
        if self.corrupt > 0 {
            self.corrupt -= 1;
            // The position's top byte: read as valid, the handle would be 1 km away.
            state[11] ^= 0x40;
        }
        answer.extend(state);
        answer
    }
}

/// Force packets out of `buf` as the firmware parses them: (seq, flags, force µN); resyncs on
/// the sync byte after garbage or a bad checksum; packets of another version are dropped.
pub fn take_force_packets(buf: &mut Vec<u8>) -> Vec<(u16, u8, i32)> {
    let mut out = Vec::new();
    loop {
        match buf.iter().position(|&b| b == 0xA5) {
            Some(i) => drop(buf.drain(..i)),
            None => {
                buf.clear();
                return out;
            }
        }
        if buf.len() < 2 {
            return out;
        }
        if buf[1] != b'F' {
            buf.drain(..1);
            continue;
        }
        if buf.len() < 12 {
            return out;
        }
        if u16::from_le_bytes([buf[10], buf[11]]) != crc16(&buf[..10]) {
            buf.drain(..1);
            continue;
        }
        if buf[2] == 1 {
            let seq = u16::from_le_bytes([buf[4], buf[5]]);
            let force = i32::from_le_bytes([buf[6], buf[7], buf[8], buf[9]]);
            out.push((seq, buf[3], force));
        }
        buf.drain(..12);
    }
}

pub fn write_all(fd: &OwnedFd, mut bytes: &[u8]) {
    while !bytes.is_empty() {
        // SAFETY: `bytes` is valid for its length.
        let n = unsafe { libc::write(fd.as_raw_fd(), bytes.as_ptr().cast(), bytes.len()) };
        if n > 0 {
            bytes = &bytes[n as usize..];
        } else {
            std::thread::yield_now();
        }
    }
}

/// The fake device's thread and its world.
pub struct Fake {
    pub world: Arc<(Mutex<World>, Condvar)>,
    pub stop: Arc<AtomicBool>,
    pub thread: Option<JoinHandle<()>>,
}

impl Fake {
    pub fn start(master: OwnedFd, world: World) -> Fake {
        let world = Arc::new((Mutex::new(world), Condvar::new()));
        let stop = Arc::new(AtomicBool::new(false));
        let (w, s) = (world.clone(), stop.clone());
        let thread = std::thread::spawn(move || {
            let mut buf = Vec::new();
            let mut last_host = Instant::now();
            while !s.load(Ordering::Relaxed) {
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
                let (lock, changed) = &*w;
                let mut world = lock.lock().unwrap();
                for (seq, flags, force) in take_force_packets(&mut buf) {
                    last_host = Instant::now();
                    let answer = world.on_force(seq, flags, force);
                    if let Some(baud) = world.baud {
                        // The request's wire time and the answer's, as a UART paces them.
                        let bits = (12 + answer.len()) as f64 * 10.0;
                        std::thread::sleep(Duration::from_secs_f64(bits / f64::from(baud)));
                    }
                    std::thread::sleep(world.answer_delay);
                    if !world.mute {
                        write_all(&master, &answer);
                    }
                }
                if world.watchdog && world.active && last_host.elapsed() >= DEVICE_SILENCE {
                    world.active = false;
                    world.applied_un = 0;
                    world.silent_latch = true;
                    world.watchdog_trips += 1;
                }
                drop(world);
                changed.notify_all();
            }
        });
        Fake {
            world,
            stop,
            thread: Some(thread),
        }
    }

    pub fn world(&self) -> MutexGuard<'_, World> {
        self.world.0.lock().unwrap()
    }

    /// Waits until the fake's world satisfies `cond`.
    pub fn wait_until(&self, what: &str, cond: impl Fn(&World) -> bool) {
        let (lock, changed) = &*self.world;
        let (_world, timeout) = changed
            .wait_timeout_while(lock.lock().unwrap(), PATIENCE, |w| !cond(w))
            .unwrap();
        assert!(!timeout.timed_out(), "the fake device never saw: {what}");
    }
}

impl Drop for Fake {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            t.join().unwrap();
        }
    }
}

/// Long time-outs, so a loaded machine cannot make the device look silent.
pub fn patient() -> SerialOptions {
    SerialOptions {
        silent_after: PATIENCE,
        open_timeout: PATIENCE,
        ..SerialOptions::default()
    }
}

/// A pty with a fake device on it, and `SerialDevice` open on the other side.
pub fn setup(world: World, options: SerialOptions) -> (SerialDevice, Fake, OwnedFd) {
    let (master, slave, path) = open_pty();
    let fake = Fake::start(master, world);
    let dev = SerialDevice::open_with(&path, options).expect("open the fake device");
    (dev, fake, slave)
}

/// One device cycle: write, then read the answer.
pub fn cycle(dev: &mut SerialDevice, force: f64) -> DeviceSample {
    dev.write_force(force).expect("write_force");
    dev.read(1e-3).expect("read")
}

/// Cycles with `force` until `cond` holds for a sample.
pub fn cycle_until(
    dev: &mut SerialDevice,
    force: f64,
    what: &str,
    cond: impl Fn(&DeviceSample) -> bool,
) -> DeviceSample {
    let start = Instant::now();
    loop {
        let s = cycle(dev, force);
        if cond(&s) {
            return s;
        }
        assert!(start.elapsed() < PATIENCE, "never saw {what}; last sample {s:?}");
    }
}
