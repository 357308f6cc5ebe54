//! The TCP Logger's stream, read on a thread of its own: the newest frame, how many came, and the
//! rate they come at. The stream is the only way a Nanonis controller reports a signal at kHz;
//! polled reads are averaged over the acquisition period (10-100 Hz).

use std::io::Read;
use std::net::{SocketAddr, TcpStream};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Condvar, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use nanopush_proto::nanonis::{LOGGER_HEADER_LEN, LoggerFrame};

/// The logger's state in a frame that carries the columns' signal indexes, not data.
const STATE_START: u16 = 2;

#[derive(Debug, Default)]
struct Shared {
    latest: Option<LoggerFrame>,
    frames: u64,
    first: Option<Instant>,
    error: Option<String>,
}

/// A running reader of the logger stream.
#[derive(Debug)]
pub struct LoggerStream {
    shared: Arc<(Mutex<Shared>, Condvar)>,
    stop: Arc<AtomicBool>,
    stream: TcpStream,
    thread: Option<JoinHandle<()>>,
}

impl LoggerStream {
    /// Connects to the stream's port and starts reading.
    pub fn open(addr: SocketAddr, timeout: Duration) -> Result<LoggerStream, String> {
        let stream = TcpStream::connect_timeout(&addr, timeout).map_err(|e| format!("logger stream {addr}: {e}"))?;
        stream
            .set_read_timeout(Some(Duration::from_millis(200)))
            .map_err(|e| e.to_string())?;
        let reader = stream.try_clone().map_err(|e| e.to_string())?;
        let shared = Arc::new((Mutex::new(Shared::default()), Condvar::new()));
        let stop = Arc::new(AtomicBool::new(false));
        let (s, st) = (shared.clone(), stop.clone());
        let thread = std::thread::Builder::new()
            .name("nanonis-logger".into())
            .spawn(move || read_frames(reader, &s, &st))
            .map_err(|e| e.to_string())?;
        Ok(LoggerStream {
            shared,
            stop,
            stream,
            thread: Some(thread),
        })
    }

    /// Waits up to `timeout` for a frame newer than the `seen`-th; returns it and its number.
    pub fn next_after(&self, seen: u64, timeout: Duration) -> Result<(LoggerFrame, u64), String> {
        let (lock, changed) = &*self.shared;
        let (s, _) = changed
            .wait_timeout_while(lock.lock().expect("logger lock"), timeout, |s| {
                s.frames <= seen && s.error.is_none()
            })
            .expect("logger lock");
        if let Some(e) = &s.error {
            return Err(e.clone());
        }
        match &s.latest {
            Some(f) if s.frames > seen => Ok((f.clone(), s.frames)),
            _ => Err(format!("no logger frame within {:.1} s", timeout.as_secs_f64())),
        }
    }

    /// Frames per second since the first data frame (None before two frames).
    pub fn rate_hz(&self) -> Option<f64> {
        let s = self.shared.0.lock().expect("logger lock");
        let secs = s.first?.elapsed().as_secs_f64();
        (s.frames >= 2 && secs > 0.0).then(|| (s.frames - 1) as f64 / secs)
    }
}

fn read_frames(mut stream: TcpStream, shared: &(Mutex<Shared>, Condvar), stop: &AtomicBool) {
    let fail = |e: String| {
        shared.0.lock().expect("logger lock").error = Some(e);
        shared.1.notify_all();
    };
    let mut header = [0u8; LOGGER_HEADER_LEN];
    while !stop.load(Ordering::Relaxed) {
        match read_full(&mut stream, &mut header, stop) {
            Ok(true) => {}
            Ok(false) => return,
            Err(e) => return fail(format!("logger stream: {e}")),
        }
        let n = match LoggerFrame::channels_in_header(&header) {
            Ok(n) => n,
            Err(e) => return fail(format!("logger stream out of step: {e}")),
        };
        let mut frame = header.to_vec();
        frame.resize(LOGGER_HEADER_LEN + 4 * n, 0);
        match read_full(&mut stream, &mut frame[LOGGER_HEADER_LEN..], stop) {
            Ok(true) => {}
            Ok(false) => return,
            Err(e) => return fail(format!("logger stream: {e}")),
        }
        let frame = match LoggerFrame::decode(&frame) {
            Ok(f) => f,
            Err(e) => return fail(format!("logger stream: {e}")),
        };
        if frame.state == STATE_START {
            continue;
        }
        let (lock, changed) = shared;
        let mut s = lock.lock().expect("logger lock");
        s.first.get_or_insert_with(Instant::now);
        s.frames += 1;
        s.latest = Some(frame);
        drop(s);
        changed.notify_all();
    }
}

/// Fills `buf`; Ok(false) when asked to stop first.
fn read_full(stream: &mut TcpStream, buf: &mut [u8], stop: &AtomicBool) -> Result<bool, String> {
    let mut got = 0;
    while got < buf.len() {
        if stop.load(Ordering::Relaxed) {
            return Ok(false);
        }
        match stream.read(&mut buf[got..]) {
            Ok(0) => return Err("the controller closed the stream".into()),
            Ok(n) => got += n,
            Err(e) if matches!(e.kind(), std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut) => {}
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            Err(e) => return Err(e.to_string()),
        }
    }
    Ok(true)
}

impl Drop for LoggerStream {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        let _ = self.stream.shutdown(std::net::Shutdown::Both);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}
