//! The argon2 checks of tokens, server-wide: at most [`AT_ONCE`] run at a time (each takes
//! ~19 MiB and ~30 ms of a core), at most [`WAITING`] more wait for their turn, each for at most
//! [`WAIT_MAX`]; beyond, the attempt is answered "busy" (HTTP 503) at once instead of queueing
//! threads and memory without bound. The per-address limit ([`super::limiter`]) keeps one
//! address to its burst; this keeps many addresses from starving the control loop's machine.

use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering::Relaxed};
use std::time::Duration;

use tokio::sync::Semaphore;

/// Checks running at once (the CI and lab machines have 2 cores, one of them the loop's).
pub const AT_ONCE: usize = 2;

/// Checks waiting for their turn; more are refused as busy.
pub const WAITING: usize = 32;

/// Longest wait for a turn.
pub const WAIT_MAX: Duration = Duration::from_secs(5);

/// The checks' turns.
#[derive(Debug)]
pub struct Checks {
    turns: Arc<Semaphore>,
    waiting: AtomicUsize,
}

impl Default for Checks {
    fn default() -> Self {
        Checks {
            turns: Arc::new(Semaphore::new(AT_ONCE)),
            waiting: AtomicUsize::new(0),
        }
    }
}

/// One less waiting when a wait ends, however it ends (the request dropped included).
struct Waiting<'a>(&'a AtomicUsize);

impl Drop for Waiting<'_> {
    fn drop(&mut self) {
        self.0.fetch_sub(1, Relaxed);
    }
}

impl Checks {
    /// Runs `check` on a blocking thread when its turn comes, or None when too many wait or
    /// the wait is over [`WAIT_MAX`]. The turn is held by the blocking task itself: a request
    /// dropped while its check runs (the client gone) does not free a turn early.
    pub async fn run<T: Send + 'static>(&self, check: impl FnOnce() -> T + Send + 'static) -> Option<T> {
        if self.waiting.fetch_add(1, Relaxed) >= WAITING {
            self.waiting.fetch_sub(1, Relaxed);
            return None;
        }
        let waiting = Waiting(&self.waiting);
        let turn = tokio::time::timeout(WAIT_MAX, self.turns.clone().acquire_owned())
            .await
            .ok()?
            .ok()?;
        drop(waiting);
        tokio::task::spawn_blocking(move || {
            let out = check();
            drop(turn);
            out
        })
        .await
        .ok()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::{Condvar, Mutex};

    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn a_few_checks_run_some_wait_and_the_rest_are_told_busy_at_once() {
        let checks = Arc::new(Checks::default());
        // Every check blocks until the gate opens: the crowd is all there before any ends.
        let gate = Arc::new((Mutex::new(false), Condvar::new()));
        let (now, peak, busy) = (
            Arc::new(AtomicUsize::new(0)),
            Arc::new(AtomicUsize::new(0)),
            Arc::new(AtomicUsize::new(0)),
        );
        let tasks: Vec<_> = (0..60)
            .map(|_| {
                let (checks, gate, now, peak, busy) =
                    (checks.clone(), gate.clone(), now.clone(), peak.clone(), busy.clone());
                tokio::spawn(async move {
                    let ran = checks
                        .run(move || {
                            peak.fetch_max(now.fetch_add(1, Relaxed) + 1, Relaxed);
                            let (open, cv) = &*gate;
                            let _open = cv.wait_while(open.lock().unwrap(), |o| !*o).unwrap();
                            now.fetch_sub(1, Relaxed);
                        })
                        .await
                        .is_some();
                    if !ran {
                        busy.fetch_add(1, Relaxed);
                    }
                    ran
                })
            })
            .collect();
        let deadline = std::time::Instant::now() + Duration::from_secs(4);
        while busy.load(Relaxed) + checks.waiting.load(Relaxed) + now.load(Relaxed) < 60 {
            assert!(std::time::Instant::now() < deadline, "the crowd never arrived");
            tokio::time::sleep(Duration::from_millis(1)).await;
        }
        *gate.0.lock().unwrap() = true;
        gate.1.notify_all();
        let mut ran = 0;
        for t in tasks {
            ran += usize::from(t.await.unwrap());
        }
        assert_eq!((AT_ONCE, WAITING), (2, 32), "as proto/README.md says");
        assert_eq!(peak.load(Relaxed), AT_ONCE, "checks running at once");
        assert_eq!(ran, AT_ONCE + WAITING, "2 ran and 32 waited for their turn");
        assert_eq!(busy.load(Relaxed), 60 - AT_ONCE - WAITING, "the rest told busy");
        assert_eq!(checks.waiting.load(Relaxed), 0, "no wait left counted");
    }
}
