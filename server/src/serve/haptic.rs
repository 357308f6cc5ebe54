//! The server's end of the haptic link (`--haptic sim|external|none`): the iceoryx2 ports the
//! control loop uses, the link's state for `/api/status` and `/metrics` (atomics written by the
//! loop), and the supervisor that runs a simulated bridge as a child under `--haptic sim`.
//!
//! Liveness: the control loop watches the age of the newest handle sample every tick (down
//! within `--haptic-timeout-ms`, 5 ms by default: 5 missed samples at 1 kHz); the supervisor looks for dead nodes a few times
//! a second off the real-time thread and removes their resources, so a bridge killed with SIGKILL
//! leaves nothing behind for the next one.

use std::path::PathBuf;
use std::process::{Child, Command, Stdio};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering::Relaxed};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use nanopush_proto::haptic::{
    ForceFeedback, HapticState, IpcNode, SERVER_NODE_NAME, force_service, ipc_node, is_publisher_taken, monotonic_ns,
    state_service,
};

use crate::serve::metrics::Histogram;

type Ipc = iceoryx2::service::ipc::Service;

/// The default link time-out (ms, `--haptic-timeout-ms`): a silent bridge is declared down
/// within this long of its last sample.
pub const DEFAULT_TIMEOUT_MS: f64 = 5.0;

/// The age of the newest sample at which a loop ticking every `tick` seconds declares the link
/// down (ns), so that it does within `timeout_ms` of the last sample: a sample is at most one
/// tick old when a tick reads it, so the tick that sees `timeout − tick/2` is within the time-out.
pub fn down_after_ns(timeout_ms: f64, tick: f64) -> u64 {
    ((timeout_ms * 1e-3 - 0.5 * tick).max(0.5 * tick) * 1e9) as u64
}
/// Largest handle position a bridge may report (m): beyond it a sample is rejected.
pub const MAX_HANDLE: f64 = 0.5;
/// Largest device force limit a bridge may report (N).
pub const MAX_DEVICE_FORCE: f64 = 50.0;

/// How the server gets its handle.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum HapticMode {
    /// No haptic link at all.
    None,
    /// Waits for a bridge started separately (a real device).
    External,
    /// Spawns and supervises `nanopush-haptic --device sim --operator hold` (this binary).
    Sim(PathBuf),
}

/// Link state codes in [`HapticMetrics::link`].
pub const LINK_OFF: u64 = 0;
/// No sample within the time-out.
pub const LINK_DOWN: u64 = 1;
/// Samples arrive.
pub const LINK_UP: u64 = 2;

/// The haptic link's state, written by the control loop (and the supervisor), read by the
/// status route, the metrics route and the telemetry task. Floats are stored as bits.
#[derive(Debug, Default)]
pub struct HapticMetrics {
    /// `LINK_*`.
    pub link: AtomicU64,
    /// Device code of the bridge (`nanopush_proto::haptic::DEVICE_*`).
    pub device: AtomicU64,
    /// The bridge's process id.
    pub pid: AtomicU64,
    /// Index of the bilateral phase in [`PHASES`].
    pub phase: AtomicU64,
    /// Handle position (m), f64 bits.
    pub handle_m: AtomicU64,
    /// Force rendered at the hand (N), f64 bits (from the bridge's newest sample).
    pub force_n: AtomicU64,
    /// Tip force `k_z ζ_z` from the measured deflection (N), f64 bits.
    pub tip_force_n: AtomicU64,
    /// Passivity damping now (N·s/m), f64 bits.
    pub pc_damping: AtomicU64,
    /// Observed port energy (J), f64 bits.
    pub port_energy: AtomicU64,
    /// Samples with the passivity controller acting.
    pub pc_active_samples: AtomicU64,
    /// `monotonic_ns` of the last sample with the controller acting.
    pub pc_last_ns: AtomicU64,
    /// Bridge restarts by the supervisor.
    pub restarts: AtomicU64,
    /// Device samples the bridge dropped (its count).
    pub dropped_samples: AtomicU64,
    /// Samples the server rejected (not finite, out of range).
    pub rejected_samples: AtomicU64,
    /// Times the link went down.
    pub link_downs: AtomicU64,
    /// Samples received.
    pub samples: AtomicU64,
    /// `monotonic_ns` of the last sample (0: never).
    pub last_ns: AtomicU64,
    /// End-to-end latency the bridge measured (device sample → force back at the device), s.
    pub latency: Histogram,
    /// Whether a mode other than `none` runs.
    pub enabled: AtomicBool,
}

/// Names of the bilateral phases, in [`crate::control::bilateral::Phase`] order.
pub const PHASES: [&str; 10] = [
    "off",
    "approach",
    "park",
    "settle",
    "ramp",
    "engaged",
    "clutched",
    "pushing",
    "link_lost",
    "retract",
];

/// The index of a phase name in [`PHASES`].
pub fn phase_index(name: &str) -> u64 {
    PHASES.iter().position(|p| *p == name).unwrap_or(0) as u64
}

fn f(bits: &AtomicU64) -> f64 {
    f64::from_bits(bits.load(Relaxed))
}

impl HapticMetrics {
    /// `up`, `down` or `off`.
    pub fn link_name(&self) -> &'static str {
        if !self.enabled.load(Relaxed) {
            return "off";
        }
        match self.link.load(Relaxed) {
            LINK_UP => "up",
            _ => "down",
        }
    }

    /// The phase's name.
    pub fn phase_name(&self) -> &'static str {
        PHASES[(self.phase.load(Relaxed) as usize).min(PHASES.len() - 1)]
    }

    /// Tip force (N).
    pub fn tip_force_n(&self) -> f64 {
        f(&self.tip_force_n)
    }

    /// Handle position (m).
    pub fn handle_m(&self) -> f64 {
        f(&self.handle_m)
    }

    /// Force at the hand (N).
    pub fn force_n(&self) -> f64 {
        f(&self.force_n)
    }

    /// Passivity damping (N·s/m).
    pub fn pc_damping(&self) -> f64 {
        f(&self.pc_damping)
    }

    /// Observed port energy (J).
    pub fn port_energy(&self) -> f64 {
        f(&self.port_energy)
    }

    /// Whether the passivity controller acted within the last 100 ms.
    pub fn pc_active(&self) -> bool {
        let last = self.pc_last_ns.load(Relaxed);
        last != 0 && monotonic_ns().saturating_sub(last) < 100_000_000
    }

    /// Records a sample from the bridge (called by the loop).
    pub fn sample(&self, s: &HapticState, now_ns: u64) {
        self.samples.fetch_add(1, Relaxed);
        self.last_ns.store(now_ns, Relaxed);
        self.device.store(u64::from(s.device), Relaxed);
        self.pid.store(u64::from(s.pid), Relaxed);
        self.handle_m.store(s.position.to_bits(), Relaxed);
        self.force_n.store(s.force.to_bits(), Relaxed);
        self.pc_damping.store(s.pc_damping.to_bits(), Relaxed);
        self.port_energy.store(s.port_energy.to_bits(), Relaxed);
        self.dropped_samples.store(s.dropped, Relaxed);
        if s.pc_damping > 0.0 {
            self.pc_active_samples.fetch_add(1, Relaxed);
            self.pc_last_ns.store(now_ns, Relaxed);
        }
    }
}

/// Whether a sample from a bridge can be believed: finite, the handle within ±0.5 m, a device
/// force limit in (0, 50] N.
pub fn believable(s: &HapticState) -> bool {
    s.position.is_finite()
        && s.velocity.is_finite()
        && s.position.abs() <= MAX_HANDLE
        && s.max_force.is_finite()
        && s.max_force > 0.0
        && s.max_force <= MAX_DEVICE_FORCE
        && s.force.is_finite()
}

/// The control loop's two ports.
pub struct ServerLink {
    _node: IpcNode,
    publisher: iceoryx2::port::publisher::Publisher<Ipc, ForceFeedback, ()>,
    subscriber: iceoryx2::port::subscriber::Subscriber<Ipc, HapticState, ()>,
}

/// Why the server's end of the link could not be opened.
#[derive(Debug, thiserror::Error)]
pub enum LinkError {
    /// Another server publishes forces on this machine.
    #[error("another nanopush serve holds the haptic link on this machine (the force service has its one publisher)")]
    ServerLive,
    /// iceoryx2 failed.
    #[error("haptic link (iceoryx2): {0}")]
    Ipc(String),
}

impl ServerLink {
    /// Opens the server's node and ports.
    pub fn open() -> Result<ServerLink, LinkError> {
        let node = ipc_node(SERVER_NODE_NAME).map_err(|e| LinkError::Ipc(e.0))?;
        let force = force_service(&node).map_err(|e| LinkError::Ipc(e.0))?;
        let state = state_service(&node).map_err(|e| LinkError::Ipc(e.0))?;
        let publisher = match force.publisher_builder().create() {
            Ok(p) => p,
            Err(e) if is_publisher_taken(&e) => return Err(LinkError::ServerLive),
            Err(e) => return Err(LinkError::Ipc(format!("{e:?}"))),
        };
        let subscriber = state
            .subscriber_builder()
            .create()
            .map_err(|e| LinkError::Ipc(format!("{e:?}")))?;
        Ok(ServerLink {
            _node: node,
            publisher,
            subscriber,
        })
    }

    /// Publishes a force sample (a failed loan or send is dropped: the next tick sends anew).
    pub fn publish(&self, f: ForceFeedback) {
        if let Ok(sample) = self.publisher.loan_uninit() {
            let _ = sample.write_payload(f).send();
        }
    }

    /// Drains the subscriber; the newest sample and how many arrived.
    pub fn newest(&self) -> (Option<HapticState>, u32) {
        let (mut last, mut n) = (None, 0);
        while let Ok(Some(s)) = self.subscriber.receive() {
            last = Some(*s);
            n += 1;
        }
        (last, n)
    }
}

/// Runs `nanopush-haptic --device sim --operator hold` as a child: restarts it with back-off when
/// it exits (0.2 s doubling to 5 s; reset after 10 s of life), always reaps it, kills it on
/// shutdown, and looks for dead iceoryx2 nodes a few times a second.
pub struct Supervisor {
    stop: Arc<AtomicBool>,
    child: Arc<Mutex<Option<Child>>>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl Supervisor {
    /// Starts the supervisor of `bin`.
    pub fn start(bin: PathBuf, shared: Arc<crate::serve::control_loop::Shared>) -> Supervisor {
        let stop = Arc::new(AtomicBool::new(false));
        let child: Arc<Mutex<Option<Child>>> = Arc::new(Mutex::new(None));
        let (stop2, child2) = (stop.clone(), child.clone());
        let thread = std::thread::Builder::new()
            .name("haptic-supervisor".into())
            .spawn(move || supervise(&bin, &stop2, &child2, &shared.metrics.haptic))
            .ok();
        Supervisor { stop, child, thread }
    }

    /// The child's pid now, if one runs.
    pub fn pid(&self) -> Option<u32> {
        self.child.lock().ok()?.as_ref().map(Child::id)
    }

    /// Kills the child, reaps it, and ends the supervisor.
    pub fn shutdown(mut self) {
        self.stop.store(true, Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

fn supervise(bin: &PathBuf, stop: &AtomicBool, slot: &Mutex<Option<Child>>, metrics: &HapticMetrics) {
    let mut backoff = Duration::from_millis(200);
    let cleaner = ipc_node("nanopush-serve-supervisor").ok();
    let mut last_clean = Instant::now();
    let mut first = true;
    'outer: while !stop.load(Relaxed) {
        let mut cmd = Command::new(bin);
        cmd.args(["--device", "sim", "--operator", "hold"])
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::inherit());
        let parent = std::process::id() as libc::pid_t;
        // SAFETY: the closure runs in the child between fork and exec and calls only
        // async-signal-safe functions (prctl, getppid, _exit).
        unsafe {
            use std::os::unix::process::CommandExt;
            cmd.pre_exec(move || {
                // The bridge goes with its server, even one killed with SIGKILL (which cannot
                // run this supervisor's clean-up): the kernel sends it SIGTERM, on which it
                // zeroes its force and exits.
                libc::prctl(libc::PR_SET_PDEATHSIG, libc::SIGTERM);
                if libc::getppid() != parent {
                    libc::_exit(0);
                }
                Ok(())
            });
        }
        let spawned = cmd.spawn();
        let started = Instant::now();
        match spawned {
            Ok(c) => {
                tracing::info!(
                    "haptic: started the simulated bridge {} (pid {})",
                    bin.display(),
                    c.id()
                );
                if let Ok(mut s) = slot.lock() {
                    *s = Some(c);
                }
                if !first {
                    metrics.restarts.fetch_add(1, Relaxed);
                }
                first = false;
            }
            Err(e) => tracing::error!("haptic: cannot start the bridge {}: {e}", bin.display()),
        }
        // Wait for it to exit (or for shutdown), reaping it; clean dead nodes meanwhile.
        loop {
            if stop.load(Relaxed) {
                break 'outer;
            }
            let status = slot
                .lock()
                .ok()
                .and_then(|mut s| s.as_mut().and_then(|c| c.try_wait().ok().flatten()));
            let gone = status.is_some() || slot.lock().map(|s| s.is_none()).unwrap_or(true);
            if let Some(st) = status {
                if let Ok(mut s) = slot.lock() {
                    *s = None;
                }
                if started.elapsed() > Duration::from_secs(10) {
                    backoff = Duration::from_millis(200);
                }
                tracing::warn!(
                    "haptic: the simulated bridge exited ({st}); restarting in {:.1} s",
                    backoff.as_secs_f64()
                );
            }
            if gone {
                break;
            }
            if last_clean.elapsed() > Duration::from_millis(100) {
                if let Some(n) = &cleaner {
                    let _ = n.try_cleanup_dead_nodes();
                }
                last_clean = Instant::now();
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        if let Some(n) = &cleaner {
            let _ = n.try_cleanup_dead_nodes();
        }
        let until = Instant::now() + backoff;
        while Instant::now() < until {
            if stop.load(Relaxed) {
                break 'outer;
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        backoff = (backoff * 2).min(Duration::from_secs(5));
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

    #[test]
    fn samples_that_cannot_be_believed_are_rejected() {
        let good = HapticState {
            position: 0.01,
            max_force: 2.5,
            ..Default::default()
        };
        assert!(believable(&good));
        for bad in [
            HapticState {
                position: f64::NAN,
                ..good
            },
            HapticState {
                velocity: f64::INFINITY,
                ..good
            },
            HapticState { position: 1.0, ..good },
            HapticState { max_force: 0.0, ..good },
            HapticState { max_force: 1e6, ..good },
            HapticState {
                force: f64::NAN,
                ..good
            },
        ] {
            assert!(!believable(&bad), "{bad:?}");
        }
    }

    #[test]
    fn the_down_threshold_keeps_detection_within_the_time_out() {
        assert_eq!(down_after_ns(5.0, 1e-3), 4_500_000);
        assert_eq!(down_after_ns(100.0, 1e-3), 99_500_000);
        // Never below half a tick (a link is not down between two samples).
        assert_eq!(down_after_ns(0.1, 1e-3), 500_000);
    }

    #[test]
    fn phase_names_match_the_law() {
        use crate::control::bilateral::Phase;
        for p in [
            Phase::Off,
            Phase::Approach,
            Phase::Park,
            Phase::Settle { small: 0 },
            Phase::Ramp { gain: 0.0 },
            Phase::Engaged,
            Phase::Clutched,
            Phase::Pushing,
            Phase::LinkLost,
            Phase::Retract,
        ] {
            assert_eq!(PHASES[phase_index(p.name()) as usize], p.name());
        }
    }
}
