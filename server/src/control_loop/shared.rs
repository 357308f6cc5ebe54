//! The state the control loop shares with the network side: the lock-free queues, the latest
//! snapshot, the counters, and the loop's settings.

use std::sync::Mutex;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering::Relaxed};
use std::time::Instant;

use crossbeam_queue::ArrayQueue;

use super::messages::{LoopCommand, LoopEvent, RecordMsg};
use crate::haptic::HapticMetrics;
use crate::metrics::LoopMetrics;
use nanopush_instrument::afm::Afm;

/// The latest state, for telemetry.
#[derive(Debug, Clone, PartialEq)]
pub struct Snapshot {
    /// Loop time (s).
    pub t: f64,
    /// Stage (m).
    pub stage: [f64; 3],
    /// Reading (V).
    pub volts: f64,
    /// Phase (`idle` when nothing runs).
    pub phase: &'static str,
    /// Estimated particle centre during a push (m).
    pub estimate: Option<[f64; 2]>,
    /// The particles where they are (id, x, y, radius; m) — the sample, which scans image.
    pub particles: Vec<(u32, f64, f64, f64)>,
    /// Ticks so far.
    pub tick: u64,
}

/// State shared between the loop thread and the network side.
#[derive(Debug)]
pub struct Shared {
    /// Commands in.
    pub commands: ArrayQueue<LoopCommand>,
    /// Events out.
    pub events: ArrayQueue<LoopEvent>,
    /// Trace rows out.
    pub records: ArrayQueue<RecordMsg>,
    /// Latest state.
    pub snapshot: Mutex<Snapshot>,
    /// Counters.
    pub metrics: LoopMetrics,
    /// A push runs (or was accepted and not yet finished).
    pub busy: AtomicBool,
    /// The loop thread ended.
    pub finished: AtomicBool,
    /// Start of the server (for ages and telemetry time).
    pub start: Instant,
    /// Runs started.
    pub runs: AtomicU64,
}

impl Shared {
    /// Shared state with the given queue capacities.
    pub fn new(afm: &Afm) -> Shared {
        let particles = afm.particles().iter().map(|p| (p.id, p.x, p.y, p.radius)).collect();
        Shared {
            commands: ArrayQueue::new(64),
            events: ArrayQueue::new(64),
            records: ArrayQueue::new(1 << 16),
            snapshot: Mutex::new(Snapshot {
                t: 0.0,
                stage: [0.0; 3],
                volts: 0.0,
                phase: "idle",
                estimate: None,
                particles,
                tick: 0,
            }),
            metrics: LoopMetrics::default(),
            busy: AtomicBool::new(false),
            finished: AtomicBool::new(false),
            start: Instant::now(),
            runs: AtomicU64::new(0),
        }
    }

    /// Queues a command for the loop (never blocking); a full queue drops it and counts it.
    pub fn command(&self, cmd: LoopCommand) -> Result<(), QueueFull> {
        self.commands.push(cmd).map_err(|_| {
            self.metrics.dropped_commands.fetch_add(1, Relaxed);
            QueueFull
        })
    }

    /// Nanoseconds since start.
    pub fn now_ns(&self) -> u64 {
        self.start.elapsed().as_nanos() as u64
    }
}

/// The loop's command queue was full: the command was dropped (and counted).
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error("the control loop's command queue is full")]
pub struct QueueFull;

impl AsRef<HapticMetrics> for Shared {
    fn as_ref(&self) -> &HapticMetrics {
        &self.metrics.haptic
    }
}

/// Loop settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LoopConfig {
    /// Tick rate (Hz), 1 kHz by default, at most 10 kHz.
    pub rate_hz: f64,
    /// Ask for SCHED_FIFO and affinity.
    pub realtime: bool,
    /// CPU to pin to (None: the last one).
    pub cpu: Option<usize>,
    /// With `realtime` and the loop pinned, keep the loop's core polling instead of halting
    /// while the loop runs ([`super::no_halt::NoHalt`]).
    pub no_halt: bool,
    /// Connect the haptic link over iceoryx2.
    pub haptic: bool,
    /// The haptic link is down within this long of the last handle sample.
    pub haptic_timeout: std::time::Duration,
}
