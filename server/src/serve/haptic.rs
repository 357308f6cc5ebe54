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

/// The age of the newest sample — since the bridge read the handle, on the clock both
/// processes share — at which a loop ticking every `tick` seconds declares the link down (ns):
/// the tick that first sees `timeout − tick` is at most one tick later, within the time-out.
pub fn down_after_ns(timeout_ms: f64, tick: f64) -> u64 {
    ((timeout_ms * 1e-3 - tick).max(tick) * 1e9) as u64
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
    /// Times the link came up.
    pub link_ups: AtomicU64,
    /// Age of the newest sample when the link last went down (ns).
    pub last_down_age_ns: AtomicU64,
    /// The tip's height above the detected surface (m), f64 bits; NaN before an approach.
    pub tip_z_m: AtomicU64,
    /// The last fault of haptic z-control ([`FAULTS`] index; 0: none).
    pub fault: AtomicU64,
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

/// Names of the faults in [`HapticMetrics::fault`].
pub const FAULTS: [&str; 3] = ["none", "no_surface", "second_server"];

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

    /// The tip's height above the detected surface (m).
    pub fn tip_z_m(&self) -> f64 {
        f(&self.tip_z_m)
    }

    /// The last fault's name (`none` when there was none).
    pub fn fault_name(&self) -> &'static str {
        FAULTS[(self.fault.load(Relaxed) as usize).min(FAULTS.len() - 1)]
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
    pub fn start(bin: Option<PathBuf>, shared: Arc<crate::serve::control_loop::Shared>) -> Supervisor {
        let stop = Arc::new(AtomicBool::new(false));
        let stop2 = stop.clone();
        let thread = std::thread::Builder::new()
            .name("haptic-monitor".into())
            .spawn(move || monitor(bin.as_deref(), &stop2, &Mutex::new(None), &shared.metrics.haptic))
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

fn monitor(bin: Option<&std::path::Path>, stop: &AtomicBool, slot: &Mutex<Option<Child>>, h: &HapticMetrics) {
    let cleaner = ipc_node("nanopush-serve-monitor").ok();
    let mut last_clean = Instant::now();
    let (mut downs, mut ups) = (0u64, 0u64);
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
        assert_eq!(down_after_ns(5.0, 1e-3), 4_000_000);
        assert_eq!(down_after_ns(100.0, 1e-3), 99_000_000);
        // Never below a tick (a link is not down between two samples).
        assert_eq!(down_after_ns(0.1, 1e-3), 1_000_000);
    }

    /// README, "Faults": under `--haptic sim` the supervisor restarts the bridge "with a back-off
    /// (0.2 s doubling to 5 s)".
    #[test]
    fn the_supervisors_back_off_is_0_2_s_doubling_to_5_s() {
        let mut b = BACKOFF_FIRST;
        let mut seq = vec![b];
        for _ in 0..6 {
            b = next_backoff(b);
            seq.push(b);
        }
        let ms: Vec<u128> = seq.iter().map(|d| d.as_millis()).collect();
        assert_eq!(ms, [200, 400, 800, 1600, 3200, 5000, 5000]);
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
