//! An alternating run (`--alternate PHASE_S`): this process takes the machine through three
//! regimes in turn (every core may halt; the loop's core polls; every core polls) and gives the
//! loop core's setting back however the run ends.

use std::io::Write;
use std::sync::atomic::{AtomicBool, Ordering::Relaxed};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use crate::stats::{Regime, Regimes};

/// Puts the machine in `regime` for an alternating run: the loop core's PM QoS resume latency
/// `n/a` (0 µs: it polls, as the server keeps it) or the value found at the start (`original`),
/// and a system-wide zero latency request (`/dev/cpu_dma_latency`) held in `all` or not.
fn enter(regime: Regime, setting: &str, original: &str, all: &mut Option<std::fs::File>) {
    let value = if regime == Regime::CorePolls { "n/a" } else { original };
    if let Err(e) = std::fs::write(setting, value) {
        panic!("--alternate needs to write {setting} (root): {e}");
    }
    if regime != Regime::AllPoll {
        *all = None;
    } else if all.is_none() {
        let mut f = std::fs::OpenOptions::new()
            .write(true)
            .open("/dev/cpu_dma_latency")
            .expect("--alternate needs to write /dev/cpu_dma_latency (root)");
        f.write_all(&0i32.to_ne_bytes()).expect("writing /dev/cpu_dma_latency");
        *all = Some(f);
    }
}

/// The loop core's setting as found, written back if the run is interrupted (SIGINT, SIGTERM,
/// SIGHUP): the path and the value, prepared before the handler is installed.
static GIVE_BACK: std::sync::OnceLock<(std::ffi::CString, Vec<u8>)> = std::sync::OnceLock::new();

/// The server's pid, for the signal handler to end it too.
pub static SERVER_PID: std::sync::atomic::AtomicI32 = std::sync::atomic::AtomicI32::new(0);

/// Writes the setting back with async-signal-safe calls only, asks the server to end (it gives
/// its own state back), then ends the process.
extern "C" fn give_back(sig: libc::c_int) {
    let server = SERVER_PID.load(Relaxed);
    if server > 0 {
        // SAFETY: kill(2) is async-signal-safe; the pid is our child's, not yet reaped.
        unsafe { libc::kill(server, libc::SIGTERM) };
    }
    if let Some((path, value)) = GIVE_BACK.get() {
        // SAFETY: open/write/close/_exit are async-signal-safe; the buffers live forever.
        unsafe {
            let fd = libc::open(path.as_ptr(), libc::O_WRONLY);
            if fd >= 0 {
                libc::write(fd, value.as_ptr().cast(), value.len());
                libc::close(fd);
            }
        }
    }
    // SAFETY: ends the process at once, as the signal's default action would have.
    unsafe { libc::_exit(128 + sig) };
}

/// An alternating run sets the loop core's setting itself: it must give it back however the run
/// ends. On a normal end and a panic the returned guard does; on a signal, the handler.
pub fn give_back_at_the_end(setting: &str, original: &str) -> impl Drop {
    struct Guard(String, String);
    impl Drop for Guard {
        fn drop(&mut self) {
            let _ = std::fs::write(&self.0, &self.1);
        }
    }
    let path = std::ffi::CString::new(setting).expect("a path without NUL");
    let _ = GIVE_BACK.set((path, original.as_bytes().to_vec()));
    for sig in [libc::SIGINT, libc::SIGTERM, libc::SIGHUP] {
        // SAFETY: installs a handler that uses async-signal-safe calls only.
        unsafe { libc::signal(sig, give_back as *const () as libc::sighandler_t) };
    }
    Guard(setting.to_string(), original.to_string())
}

/// Cycles the regimes, `phase` seconds each, from now until `alternating` is cleared, recording
/// each switch in `regimes`. The system-wide request ends with the thread; the guard of
/// [`give_back_at_the_end`] restores the core's setting.
pub fn alternate(
    phase: f64,
    setting: String,
    original: String,
    regimes: Arc<Mutex<Regimes>>,
    alternating: Arc<AtomicBool>,
) -> JoinHandle<()> {
    std::thread::spawn(move || {
        let (mut all, mut next) = (None, Instant::now());
        for &regime in Regime::ALL.iter().cycle() {
            enter(regime, &setting, &original, &mut all);
            regimes.lock().unwrap().switches.push((Instant::now(), regime));
            next += Duration::from_secs_f64(phase);
            while alternating.load(Relaxed) && Instant::now() < next {
                std::thread::sleep(Duration::from_millis(20));
            }
            if !alternating.load(Relaxed) {
                break;
            }
        }
    })
}
