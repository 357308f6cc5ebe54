//! The processes the tests and benchmarks start: read the address a `nanopush serve` listens on,
//! and stop a child as a service manager would, by hand ([`sigterm`], [`stop`]) or on drop
//! ([`Proc`]).

use std::io::{BufRead, BufReader};
use std::process::Child;
use std::time::{Duration, Instant};

/// What `nanopush serve` prints first on stdout, before its address.
const LISTENING: &str = "nanopush serve: listening on ";

/// The address in the first line of a `nanopush serve` child's stdout (`nanopush serve:
/// listening on ADDR`; stdout piped); the rest of its stdout is read and dropped on a thread of
/// its own, so the server never blocks on a full pipe. An Err holds the first line as it came
/// (empty when stdout ended first).
pub fn listening_addr(child: &mut Child) -> Result<String, String> {
    let out = child.stdout.take().expect("the server's stdout is piped");
    let mut lines = BufReader::new(out).lines();
    let first = lines.next().and_then(Result::ok).unwrap_or_default();
    let addr = first.strip_prefix(LISTENING).ok_or_else(|| first.clone())?.to_string();
    std::thread::spawn(move || for _ in lines {});
    Ok(addr)
}

/// Sends SIGTERM to a child process (the way an operator or a service manager stops it).
pub fn sigterm(child: &Child) {
    // SAFETY: kill(2) on the pid of our own child, not yet reaped (so not reused).
    let r = unsafe { libc::kill(child.id() as libc::pid_t, libc::SIGTERM) };
    assert_eq!(r, 0, "kill(SIGTERM) of pid {}", child.id());
}

/// Stops a child as a service manager would: SIGTERM, up to 10 s to end, then SIGKILL; reaped
/// either way. A server stopped so gives its loop's core back (`server/src/no_halt.rs`); one killed
/// outright leaves it polling until another server starts and ends.
pub fn stop(child: &mut Child) {
    if matches!(child.try_wait(), Ok(None)) {
        // SAFETY: kill(2) on the pid of our own child, not yet reaped (so not reused).
        unsafe { libc::kill(child.id() as libc::pid_t, libc::SIGTERM) };
        let t = Instant::now();
        while matches!(child.try_wait(), Ok(None)) {
            if t.elapsed() > Duration::from_secs(10) {
                let _ = child.kill();
                break;
            }
            std::thread::sleep(Duration::from_millis(5));
        }
    }
    let _ = child.wait();
}

/// A child process, [`stop`]ped and reaped when dropped.
pub struct Proc(pub Child);

impl Drop for Proc {
    fn drop(&mut self) {
        stop(&mut self.0);
    }
}
