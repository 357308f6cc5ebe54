//! The argon2 checks of tokens, server-wide: at most [`AT_ONCE`] run at a time (each takes
//! ~19 MiB and ~30 ms of a core), at most [`WAITING`] more wait for their turn, each for at most
//! [`WAIT_MAX`]; beyond, the attempt is answered "busy" (HTTP 503) at once instead of queueing
//! threads and memory without bound. The per-address limit ([`super::limiter`]) keeps one
//! address to its burst; this keeps many addresses from starving the control loop's machine.
//!
//! The checks run on [`AT_ONCE`] threads of their own (`token-check-N`, started at the first
//! check), each with one argon2 buffer ([`Scratch`]) it keeps: the memory checks cost is bounded
//! by `AT_ONCE` buffers (2 × 19 MiB), whatever the number of checks. (On tokio's blocking pool,
//! each check's 19 MiB was allocated on whichever thread ran it, and glibc kept it in that
//! thread's arena: 24 failed checks one after the other took a server from 27 to 483 MiB.)

use std::sync::atomic::{AtomicUsize, Ordering::Relaxed};
use std::sync::{Arc, Mutex, OnceLock, mpsc};
use std::time::Duration;

use tokio::sync::Semaphore;

use super::tokens::Scratch;

/// Checks running at once (the CI and lab machines have 2 cores, one of them the loop's).
pub const AT_ONCE: usize = 2;

/// Checks waiting for their turn; more are refused as busy.
pub const WAITING: usize = 32;

/// Longest wait for a turn.
pub const WAIT_MAX: Duration = Duration::from_secs(5);

/// A check, given its thread's argon2 memory.
type Job = Box<dyn FnOnce(&mut Scratch) + Send>;

/// The checks' turns and threads.
#[derive(Debug)]
pub struct Checks {
    turns: Arc<Semaphore>,
    waiting: AtomicUsize,
    /// The checking threads' queue, once started; None if no thread could be started (the
    /// checks then run on tokio's blocking pool, each with memory of its own).
    threads: OnceLock<Option<mpsc::Sender<Job>>>,
}

impl Default for Checks {
    fn default() -> Self {
        Checks {
            turns: Arc::new(Semaphore::new(AT_ONCE)),
            waiting: AtomicUsize::new(0),
            threads: OnceLock::new(),
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

/// Starts the [`AT_ONCE`] checking threads: their queue, or None when none could be started.
fn start_threads() -> Option<mpsc::Sender<Job>> {
    let (tx, rx) = mpsc::channel::<Job>();
    let rx = Arc::new(Mutex::new(rx));
    let started = (0..AT_ONCE)
        .filter(|i| {
            let rx = rx.clone();
            let spawned = std::thread::Builder::new()
                .name(format!("token-check-{i}"))
                .spawn(move || {
                    let mut scratch = Scratch::default();
                    loop {
                        let job = match rx.lock() {
                            Ok(rx) => rx.recv(),
                            Err(_) => return,
                        };
                        let Ok(job) = job else { return };
                        // A check that panicked drops its answer (the attempt is told busy) and
                        // its turn; the thread goes on.
                        let _ = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| job(&mut scratch)));
                    }
                });
            if let Err(e) = &spawned {
                tracing::error!("cannot start a token-checking thread: {e}");
            }
            spawned.is_ok()
        })
        .count();
    (started > 0).then_some(tx)
}

impl Checks {
    /// Runs `check` on a checking thread, with that thread's argon2 memory, when its turn comes;
    /// or None when too many wait or the wait is over [`WAIT_MAX`]. The turn is held by the check
    /// itself: a request dropped while its check runs (the client gone) does not free a turn
    /// early.
    pub async fn run<T: Send + 'static>(&self, check: impl FnOnce(&mut Scratch) -> T + Send + 'static) -> Option<T> {
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
        let (done, answer) = tokio::sync::oneshot::channel();
        let job: Job = Box::new(move |scratch| {
            let out = check(scratch);
            drop(turn);
            let _ = done.send(out);
        });
        match self.threads.get_or_init(start_threads) {
            Some(threads) => threads.send(job).ok()?,
            None => {
                tokio::task::spawn_blocking(move || job(&mut Scratch::default()));
            }
        }
        answer.await.ok()
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
                        .run(move |_| {
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
