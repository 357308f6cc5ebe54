//! The haptic link's monitor thread and, under `--haptic sim`, the bridge it runs as a child.

use std::path::PathBuf;
use std::process::{Child, Command, Stdio};
use std::sync::atomic::{AtomicBool, Ordering::Relaxed};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use nanopush_proto::haptic::ipc_node;

use super::metrics::HapticMetrics;

/// The haptic link's monitor, a plain thread beside the real-time loop: it logs the link's
/// transitions the loop counts (so the loop never writes a log line), removes dead iceoryx2
/// nodes a few times a second, and under `--haptic sim` runs `nanopush-haptic --device sim
/// --operator hold` as a child — restarted with back-off when it exits (0.2 s doubling to 5 s;
/// reset after 10 s of life), always reaped, in a process group of its own (a Ctrl-C to the
/// server does not reach it before the tip is parked), stopped by the kernel if the server dies
/// (`PR_SET_PDEATHSIG`), stopped with SIGTERM on shutdown.
pub struct Supervisor {
    stop: Arc<AtomicBool>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl Supervisor {
    /// Starts the monitor; with `bin`, it runs that bridge as a child.
    pub fn start<S: AsRef<HapticMetrics> + Send + Sync + 'static>(bin: Option<PathBuf>, shared: Arc<S>) -> Supervisor {
        let stop = Arc::new(AtomicBool::new(false));
        let stop2 = stop.clone();
        let thread = std::thread::Builder::new()
            .name("haptic-monitor".into())
            .spawn(move || monitor(bin.as_deref(), &stop2, &Mutex::new(None), (*shared).as_ref()))
            .ok();
        Supervisor { stop, thread }
    }

    /// Stops the child (SIGTERM, SIGKILL after 1 s), reaps it, and ends the monitor.
    pub fn shutdown(mut self) {
        self.stop.store(true, Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

fn spawn_bridge(bin: &std::path::Path) -> std::io::Result<Child> {
    let mut cmd = Command::new(bin);
    cmd.args(["--device", "sim", "--operator", "hold"])
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::inherit());
    let parent = std::process::id() as libc::pid_t;
    // SAFETY: the closure runs in the child between fork and exec and calls only
    // async-signal-safe functions (setpgid, prctl, getppid, _exit).
    unsafe {
        use std::os::unix::process::CommandExt;
        cmd.pre_exec(move || {
            libc::setpgid(0, 0);
            // The bridge goes with its server, even one killed with SIGKILL: the kernel sends
            // it SIGTERM, on which it zeroes its force and exits.
            libc::prctl(libc::PR_SET_PDEATHSIG, libc::SIGTERM);
            if libc::getppid() != parent {
                libc::_exit(0);
            }
            Ok(())
        });
    }
    cmd.spawn()
}

/// The supervisor's first restart delay of the simulated bridge, and again once it has run
/// [`BACKOFF_RESET`].
pub const BACKOFF_FIRST: Duration = Duration::from_millis(200);
/// The longest delay between two restarts.
pub const BACKOFF_MAX: Duration = Duration::from_secs(5);
/// A bridge that ran this long before it exited is restarted after [`BACKOFF_FIRST`] again.
pub const BACKOFF_RESET: Duration = Duration::from_secs(10);

/// The delay after `backoff` for the next restart: doubled, at most [`BACKOFF_MAX`].
pub fn next_backoff(backoff: Duration) -> Duration {
    (backoff * 2).min(BACKOFF_MAX)
}

/// Logs an energy bounding (the passivity damper pinned at its cap: the force scale halved) and
/// a change of the reason the scales in force differ from those asked.
fn note_scales(h: &HapticMetrics, bounds: &mut u64, limit: &mut u64) {
    let (b, l) = (h.energy_bounds.load(Relaxed), h.scales.limit.load(Relaxed));
    if b == *bounds && l == *limit {
        return;
    }
    let s = h.scales.snapshot();
    if b > *bounds {
        tracing::warn!(
            "haptic energy bounding: the passivity damper stayed at its cap for more than 50 ms; the pull-off at the hand is now {:.3} N (asked {:.3} N)",
            s.pull_off_at_hand_n,
            s.asked_pull_off_at_hand_n
        );
    } else if l != *limit {
        tracing::info!(
            "haptic scales in force: {} nm/mm, {:.3} N of pull-off (asked {:.3} N), felt as {:.0} N/m: {}",
            s.nm_per_mm,
            s.pull_off_at_hand_n,
            s.asked_pull_off_at_hand_n,
            s.felt_stiffness_n_per_m,
            s.reason.as_deref().unwrap_or("as asked")
        );
    }
    (*bounds, *limit) = (b, l);
}

fn monitor(bin: Option<&std::path::Path>, stop: &AtomicBool, slot: &Mutex<Option<Child>>, h: &HapticMetrics) {
    let cleaner = ipc_node("nanopush-serve-monitor").ok();
    let mut last_clean = Instant::now();
    let (mut downs, mut ups) = (0u64, 0u64);
    let (mut bounds, mut limit) = (0u64, 0u64);
    let mut backoff = BACKOFF_FIRST;
    let mut started = Instant::now();
    let mut respawn_at: Option<Instant> = bin.map(|_| Instant::now());
    let mut first = true;
    while !stop.load(Relaxed) {
        // The link's transitions, as the loop counted them.
        let (d, u) = (h.link_downs.load(Relaxed), h.link_ups.load(Relaxed));
        if u > ups {
            tracing::info!(
                "haptic link up: {} bridge, pid {}",
                nanopush_proto::haptic::device_name(h.device.load(Relaxed) as u32),
                h.pid.load(Relaxed)
            );
        }
        if d > downs {
            tracing::warn!(
                "haptic link down: no handle sample for {:.1} ms (bridge pid {}); z frozen, tip to its parking height",
                h.last_down_age_ns.load(Relaxed) as f64 * 1e-6,
                h.pid.load(Relaxed)
            );
        }
        (downs, ups) = (d, u);
        note_scales(h, &mut bounds, &mut limit);
        // The simulated bridge: reap it when it exits, start it again after the back-off.
        if let Some(bin) = bin {
            if let Ok(mut s) = slot.lock()
                && let Some(c) = s.as_mut()
                && let Ok(Some(status)) = c.try_wait()
            {
                *s = None;
                if started.elapsed() > BACKOFF_RESET {
                    backoff = BACKOFF_FIRST;
                }
                tracing::warn!(
                    "haptic: the simulated bridge exited ({status}); restarting in {:.1} s",
                    backoff.as_secs_f64()
                );
                respawn_at = Some(Instant::now() + backoff);
                backoff = next_backoff(backoff);
            }
            if respawn_at.is_some_and(|t| Instant::now() >= t) {
                respawn_at = None;
                if let Some(n) = &cleaner {
                    let _ = n.try_cleanup_dead_nodes();
                }
                match spawn_bridge(bin) {
                    Ok(c) => {
                        tracing::info!(
                            "haptic: started the simulated bridge {} (pid {})",
                            bin.display(),
                            c.id()
                        );
                        if !first {
                            h.restarts.fetch_add(1, Relaxed);
                        }
                        first = false;
                        started = Instant::now();
                        if let Ok(mut s) = slot.lock() {
                            *s = Some(c);
                        }
                    }
                    Err(e) => {
                        tracing::error!("haptic: cannot start the bridge {}: {e}", bin.display());
                        respawn_at = Some(Instant::now() + backoff);
                        backoff = next_backoff(backoff);
                    }
                }
            }
        }
        if last_clean.elapsed() > Duration::from_millis(100) {
            if let Some(n) = &cleaner {
                let _ = n.try_cleanup_dead_nodes();
            }
            last_clean = Instant::now();
        }
        std::thread::sleep(Duration::from_millis(2));
    }
    // Shutdown: SIGTERM (the bridge zeroes its force and exits), SIGKILL after 1 s; always reap.
    if let Ok(mut s) = slot.lock()
        && let Some(mut c) = s.take()
    {
        // SAFETY: kill(2) on the pid of a child we have not reaped yet (so not reused).
        unsafe {
            libc::kill(c.id() as libc::pid_t, libc::SIGTERM);
        }
        let deadline = Instant::now() + Duration::from_secs(1);
        while Instant::now() < deadline {
            if let Ok(Some(_)) = c.try_wait() {
                return;
            }
            std::thread::sleep(Duration::from_millis(10));
        }
        let _ = c.kill();
        let _ = c.wait();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// docs/haptics.md, "Faults": under `--haptic sim` the supervisor restarts the bridge "with a
    /// back-off (0.2 s doubling to 5 s)".
    #[test]
    fn the_supervisors_back_off_doubles_up_to_its_cap() {
        let mut b = BACKOFF_FIRST;
        let mut seq = vec![b];
        for _ in 0..6 {
            b = next_backoff(b);
            seq.push(b);
        }
        let ms: Vec<u128> = seq.iter().map(|d| d.as_millis()).collect();
        assert_eq!(ms, [200, 400, 800, 1600, 3200, 5000, 5000]);
    }
}
