//! A fake Nanonis controller for the tests: the TCP Programming Interface's framing on a command
//! port, a TCP Logger stream on a second port, the small microscope of [`world`] behind them, and
//! faults on demand ([`faults`]). It listens on 127.0.0.1 only.
//!
//! Timing as a controller has it: polled reads (`Signals.ValGet`, `Signals.ValsGet`,
//! `FolMe.XYPosGet`) answer after half an acquisition period; the logger streams at its own rate;
//! a scan takes `lines / line_rate` seconds and `Scan.WaitEndOfScan` waits for it. At most four
//! command connections are served at once, like the controller's four ports.

pub mod faults;
pub mod world;

use std::io::{Read, Write};
use std::net::{SocketAddr, TcpListener, TcpStream};
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use nanopush_instrument::scene::Scene;
use nanopush_proto::nanonis::{HEADER_LEN, LoggerFrame, decode_request_header, encode_response};

use faults::{Fault, FaultKind};
use world::World;

/// The most command connections served at once.
pub const MAX_CONNECTIONS: usize = 4;

/// How the fake is set up.
#[derive(Debug, Clone)]
pub struct FakeOptions {
    /// The sample: a scene's substrate and particles.
    pub scene: Scene,
    /// Scan lines per second.
    pub line_rate: f64,
    /// Logger frames per second.
    pub logger_rate_hz: f64,
    /// Faults to commit.
    pub faults: Vec<Fault>,
    /// Command port (0: any free one).
    pub port: u16,
    /// Logger port (0: any free one).
    pub logger_port: u16,
}

impl Default for FakeOptions {
    fn default() -> FakeOptions {
        FakeOptions {
            scene: Scene::default_scene(),
            line_rate: 400.0,
            logger_rate_hz: 1000.0,
            faults: Vec::new(),
            port: 0,
            logger_port: 0,
        }
    }
}

struct Shared {
    world: Mutex<World>,
    faults: Mutex<Vec<Fault>>,
    stop: AtomicBool,
    connections: AtomicUsize,
    next_id: AtomicU64,
    logger_rate_hz: f64,
}

/// A running fake controller; it stops when dropped.
pub struct FakeController {
    shared: Arc<Shared>,
    addr: SocketAddr,
    logger_addr: SocketAddr,
    threads: Vec<JoinHandle<()>>,
}

impl std::fmt::Debug for FakeController {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "FakeController({}, logger {})", self.addr, self.logger_addr)
    }
}

fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|p| p.into_inner())
}

impl FakeController {
    /// Starts listening on 127.0.0.1.
    pub fn start(o: FakeOptions) -> std::io::Result<FakeController> {
        let commands = TcpListener::bind(("127.0.0.1", o.port))?;
        let logger = TcpListener::bind(("127.0.0.1", o.logger_port))?;
        commands.set_nonblocking(true)?;
        logger.set_nonblocking(true)?;
        let (addr, logger_addr) = (commands.local_addr()?, logger.local_addr()?);
        let shared = Arc::new(Shared {
            world: Mutex::new(World::new(&o.scene, o.line_rate)),
            faults: Mutex::new(o.faults),
            stop: AtomicBool::new(false),
            connections: AtomicUsize::new(0),
            next_id: AtomicU64::new(0),
            logger_rate_hz: o.logger_rate_hz,
        });
        let mut threads = Vec::new();
        let s = shared.clone();
        threads.push(std::thread::spawn(move || physics(&s)));
        let s = shared.clone();
        threads.push(std::thread::spawn(move || accept(&s, &commands, serve_commands)));
        let s = shared.clone();
        threads.push(std::thread::spawn(move || accept(&s, &logger, serve_logger)));
        Ok(FakeController {
            shared,
            addr,
            logger_addr,
            threads,
        })
    }

    /// The command port's address.
    pub fn addr(&self) -> SocketAddr {
        self.addr
    }

    /// The logger stream's port.
    pub fn logger_port(&self) -> u16 {
        self.logger_addr.port()
    }

    /// The microscope, to look at or change.
    pub fn world(&self) -> MutexGuard<'_, World> {
        lock(&self.shared.world)
    }

    /// Adds a fault.
    pub fn add_fault(&self, f: Fault) {
        lock(&self.shared.faults).push(f);
    }

    /// Every command received so far, in order.
    pub fn commands(&self) -> Vec<String> {
        self.world().log.iter().map(|(_, c)| c.clone()).collect()
    }

    /// Commands received on each connection, in the order the connections opened.
    pub fn commands_by_connection(&self) -> Vec<Vec<String>> {
        let log = self.world().log.clone();
        let mut out: Vec<(u64, Vec<String>)> = Vec::new();
        for (id, c) in log {
            match out.iter_mut().find(|(i, _)| *i == id) {
                Some((_, v)) => v.push(c),
                None => out.push((id, vec![c])),
            }
        }
        out.into_iter().map(|(_, v)| v).collect()
    }
}

impl Drop for FakeController {
    fn drop(&mut self) {
        self.shared.stop.store(true, Ordering::Relaxed);
        for t in self.threads.drain(..) {
            let _ = t.join();
        }
    }
}

fn physics(s: &Shared) {
    let mut last = Instant::now();
    while !s.stop.load(Ordering::Relaxed) {
        std::thread::sleep(Duration::from_millis(1));
        let now = Instant::now();
        lock(&s.world).step((now - last).as_secs_f64());
        last = now;
    }
}

fn accept(s: &Arc<Shared>, listener: &TcpListener, serve: fn(&Shared, TcpStream, u64)) {
    let mut conns: Vec<JoinHandle<()>> = Vec::new();
    while !s.stop.load(Ordering::Relaxed) {
        match listener.accept() {
            Ok((stream, _)) => {
                let _ = stream.set_nonblocking(false);
                let id = s.next_id.fetch_add(1, Ordering::Relaxed);
                let s = s.clone();
                conns.push(std::thread::spawn(move || serve(&s, stream, id)));
            }
            Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => std::thread::sleep(Duration::from_millis(2)),
            Err(_) => std::thread::sleep(Duration::from_millis(10)),
        }
        conns.retain(|t| !t.is_finished());
    }
    for t in conns {
        let _ = t.join();
    }
}

/// Reads exactly `buf`, checking the stop flag; false when the peer closed or the fake stops.
fn read_exact(s: &Shared, stream: &mut TcpStream, buf: &mut [u8]) -> bool {
    let mut got = 0;
    while got < buf.len() {
        if s.stop.load(Ordering::Relaxed) {
            return false;
        }
        match stream.read(&mut buf[got..]) {
            Ok(0) => return false,
            Ok(n) => got += n,
            Err(e) if matches!(e.kind(), std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut) => {}
            Err(_) => return false,
        }
    }
    true
}

fn serve_commands(s: &Shared, mut stream: TcpStream, id: u64) {
    if s.connections.fetch_add(1, Ordering::SeqCst) >= MAX_CONNECTIONS {
        s.connections.fetch_sub(1, Ordering::SeqCst);
        return;
    }
    let _ = stream.set_read_timeout(Some(Duration::from_millis(100)));
    let _ = stream.set_nodelay(true);
    loop {
        let mut header = [0u8; HEADER_LEN];
        if !read_exact(s, &mut stream, &mut header) {
            break;
        }
        let Ok(h) = decode_request_header(&header) else { break };
        let mut body = vec![0u8; h.body_size];
        if !read_exact(s, &mut stream, &mut body) {
            break;
        }
        lock(&s.world).log.push((id, h.name.clone()));
        let fault = faults::take(&mut lock(&s.faults), &h.name);
        if let Some(FaultKind::Slow(ms)) = fault {
            std::thread::sleep(Duration::from_millis(ms));
        }
        if fault == Some(FaultKind::Drop) {
            break;
        }
        let reply = match fault {
            Some(FaultKind::Error) => {
                let mut w = nanopush_proto::nanonis::BodyWriter::new();
                nanopush_proto::nanonis::ErrorBlock {
                    status: 1,
                    description: format!("Fake fault: {} failed", h.name),
                }
                .write(&mut w);
                w.into_bytes()
            }
            _ => answer(s, &h.name, &body),
        };
        if !h.send_response {
            continue;
        }
        let name = if fault == Some(FaultKind::WrongName) {
            "Bias.Get"
        } else {
            h.name.as_str()
        };
        let Ok(mut bytes) = encode_response(name, &reply) else {
            break;
        };
        if fault == Some(FaultKind::Short) {
            let announced = (reply.len() + 64) as i32;
            bytes[32..36].copy_from_slice(&announced.to_be_bytes());
            let _ = stream.write_all(&bytes);
            break;
        }
        if stream.write_all(&bytes).is_err() {
            break;
        }
    }
    s.connections.fetch_sub(1, Ordering::SeqCst);
}

/// The reply to one command, with the waits a controller has outside the world's lock.
fn answer(s: &Shared, name: &str, body: &[u8]) -> Vec<u8> {
    match name {
        "Signals.ValGet" | "Signals.ValsGet" | "FolMe.XYPosGet" => {
            let half = lock(&s.world).acq_period / 2.0;
            std::thread::sleep(Duration::from_secs_f64(half));
        }
        "Scan.WaitEndOfScan" => {
            let ms = body
                .get(..4)
                .map_or(0, |b| i32::from_be_bytes([b[0], b[1], b[2], b[3]]));
            let deadline = (ms >= 0).then(|| Instant::now() + Duration::from_millis(ms as u64));
            while lock(&s.world).scanning()
                && deadline.is_none_or(|d| Instant::now() < d)
                && !s.stop.load(Ordering::Relaxed)
            {
                std::thread::sleep(Duration::from_millis(2));
            }
        }
        "ZCtrl.Withdraw" => std::thread::sleep(Duration::from_millis(20)),
        _ => {}
    }
    lock(&s.world).handle(name, body)
}

fn serve_logger(s: &Shared, mut stream: TcpStream, _id: u64) {
    let _ = stream.set_nodelay(true);
    let drop_after = lock(&s.faults).iter_mut().find_map(|f| match f.kind {
        FaultKind::LoggerDrop(ms) if f.times > 0 => {
            f.times = f.times.saturating_sub(1);
            Some(Duration::from_millis(ms))
        }
        _ => None,
    });
    let opened = Instant::now();
    let period = Duration::from_secs_f64(1.0 / s.logger_rate_hz.max(1.0));
    let mut counter = 0u64;
    let mut started = false;
    let mut next = Instant::now();
    while !s.stop.load(Ordering::Relaxed) {
        if drop_after.is_some_and(|d| opened.elapsed() >= d) {
            return;
        }
        let frame = {
            let w = lock(&s.world);
            if !w.log_running {
                started = false;
                None
            } else if !started {
                started = true;
                Some(LoggerFrame {
                    oversampling: w.log_oversampling as f32,
                    counter: 0,
                    state: 2,
                    values: w.log_channels.iter().map(|&c| c as f32).collect(),
                })
            } else {
                counter += 1;
                Some(LoggerFrame {
                    oversampling: w.log_oversampling as f32,
                    counter,
                    state: 4,
                    values: w.log_channels.iter().map(|&c| w.signal(c as usize) as f32).collect(),
                })
            }
        };
        if let Some(f) = frame
            && stream.write_all(&f.encode()).is_err()
        {
            return;
        }
        next += period;
        let now = Instant::now();
        if next > now {
            std::thread::sleep(next - now);
        } else {
            next = now;
        }
    }
}
