//! The control loop: a dedicated OS thread stepping the instrument at 1 kHz (up to 10 kHz) on an
//! absolute-deadline schedule — sleep until shortly before the deadline, then spin
//! (spin_sleep) — with SCHED_FIFO, CPU affinity and a core that polls instead of halting when the
//! system grants them (logged fallback when not: [`crate::serve::realtime`],
//! [`crate::serve::no_halt`]). Tokio's timer rounds to the millisecond, which is why this is not
//! a task.
//!
//! Each tick, in order, each phase timed:
//! 1. *control*: take pending commands (a bounded lock-free queue, never blocking) and the
//!    newest haptic sample; tick the strategy of the running push, if any;
//! 2. *physics*: advance the instrument one tick to the strategy's stage target;
//! 3. *publish*: the force to the haptic bridge (iceoryx2), the telemetry snapshot (a
//!    `try_lock`: skipped, never waited for, if a reader holds it), the trace row to the
//!    recorder (a bounded lock-free queue).
//!
//! Haptic z-control ([`crate::control::bilateral`]) runs in the control phase: the newest handle
//! sample (rejected and counted if not believable), the link's watchdog (down after 4.5 ms
//! without a sample: logged as "haptic link down", the tip retracts to its parking height), the
//! law's stage target while the hand owns z (outside pushes), and the force with its local model
//! published every tick.

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering::Relaxed};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use crossbeam_queue::ArrayQueue;
use nanopush_proto::haptic::{ForceFeedback, HapticState, monotonic_ns};

use crate::control::bilateral::{Bilateral, BilateralParams, Input as HapticInput, Phase as HapticPhase};
use crate::control::{Leg, Prepared, Strategy, StrategyParams};
use crate::instrument::{Afm, Reading};
use crate::serve::haptic::{LINK_DOWN, LINK_UP, ServerLink, believable, phase_index};
use crate::serve::metrics::LoopMetrics;
use crate::serve::no_halt::NoHalt;
use crate::serve::realtime::make_realtime;

/// A push prepared off the loop (localization, model prediction, plan), ready to run.
#[derive(Debug, Clone)]
pub struct PushJob {
    /// Run number (for the record's name).
    pub run: u64,
    /// Particle id.
    pub particle: u32,
    /// The legs, in order.
    pub legs: Vec<Leg>,
    /// The model prediction and geometry.
    pub prepared: Prepared,
}

/// What the network side asks of the loop.
#[derive(Debug)]
pub enum LoopCommand {
    /// Start a push.
    Push(Box<PushJob>),
    /// Stop the running push: the tip retracts.
    Stop,
    /// Finish: stop any push, retract, release the haptic force, end the thread.
    Shutdown,
    /// Haptic z-control.
    Haptic(HapticCommand),
}

/// What the lease holder asks of haptic z-control.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum HapticCommand {
    /// Approach, park, and give z to the hand.
    Engage,
    /// Park the tip and let the handle go.
    Release,
    /// Re-centre the handle: the tip stays, the hand gets its travel back.
    Recenter,
    /// New scales (each only when given).
    Scale {
        /// Tip metres per handle metre.
        position_gain: Option<f64>,
        /// Hand newtons per tip newton.
        force_gain: Option<f64>,
    },
}

/// What the loop reports back.
#[derive(Debug, Clone, PartialEq)]
pub enum LoopEvent {
    /// A push ended.
    RunDone {
        /// Run number.
        run: u64,
        /// Particle.
        particle: u32,
        /// `ok` or a failure code.
        outcome: &'static str,
        /// The failure in words.
        failure: Option<String>,
        /// Estimated final centre (m).
        estimate: [f64; 2],
        /// True final centre (m), from the simulator, for the record.
        truth: [f64; 2],
        /// Legs run.
        legs: usize,
    },
}

/// One trace row for the recorder.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum RecordMsg {
    /// A push begins.
    Begin {
        /// Run number.
        run: u64,
        /// Particle.
        particle: u32,
    },
    /// One tick of it.
    Row {
        /// Leg (1-based).
        leg: u32,
        /// Time (s).
        t: f64,
        /// Phase.
        phase: &'static str,
        /// Stage (m).
        stage: [f64; 3],
        /// Reading (V).
        volts: f64,
        /// Estimated displacement of this leg (m).
        estimate: f64,
    },
    /// It ended (its summary follows as a [`LoopEvent::RunDone`]).
    End {
        /// Run number.
        run: u64,
    },
}

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

    /// Nanoseconds since start.
    pub fn now_ns(&self) -> u64 {
        self.start.elapsed().as_nanos() as u64
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
    /// while the loop runs ([`NoHalt`]).
    pub no_halt: bool,
    /// Connect the haptic link over iceoryx2.
    pub haptic: bool,
    /// The haptic link is down within this long of the last handle sample (ms).
    pub haptic_timeout_ms: f64,
}

/// A push in progress.
struct Active {
    job: Box<PushJob>,
    leg: usize,
    strategy: Strategy,
    stop: bool,
}

/// A push that ends after this tick's physics.
struct Ending {
    job: Box<PushJob>,
    leg: usize,
    estimate: (f64, f64),
    /// Estimated distance of the last leg (m), for the final trace row.
    distance: f64,
    outcome: &'static str,
    failure: Option<String>,
}

/// Marks the loop finished when dropped.
struct Finished<'a>(&'a Shared);

impl Drop for Finished<'_> {
    fn drop(&mut self) {
        self.0.finished.store(true, std::sync::atomic::Ordering::Release);
    }
}

/// Everything the loop owns.
pub struct ControlLoop {
    afm: Afm,
    params: StrategyParams,
    bilateral: Bilateral,
    target: [f64; 3],
    active: Option<Active>,
    ending: Option<Ending>,
    shutting_down: bool,
    /// Told once the haptic link is open (or could not be).
    ready: Option<std::sync::mpsc::SyncSender<Result<(), String>>>,
}

impl ControlLoop {
    /// A loop over `afm` with the scene's strategy settings and the haptic z-control's.
    pub fn new(afm: Afm, params: StrategyParams, haptic: BilateralParams) -> ControlLoop {
        let target = afm.stage();
        ControlLoop {
            afm,
            params,
            bilateral: Bilateral::new(haptic),
            target,
            active: None,
            ending: None,
            shutting_down: false,
            ready: None,
        }
    }

    /// Tells `tx` once the haptic link is open (`Ok`) or could not be (`Err` with the reason).
    pub fn with_ready(mut self, tx: std::sync::mpsc::SyncSender<Result<(), String>>) -> ControlLoop {
        self.ready = Some(tx);
        self
    }

    fn report_ready(&mut self, r: Result<(), String>) {
        if let Some(tx) = self.ready.take() {
            let _ = tx.send(r);
        }
    }

    /// Starts the leg after `a`'s and returns this tick's stage target.
    fn next_then(&mut self, a: Active, estimate: (f64, f64), distance: f64, reading: &Reading) -> [f64; 3] {
        self.next_leg(a.job, a.leg + 1, estimate, distance, reading);
        self.target
    }

    /// Starts leg `leg` of `job` from where the particle is believed to be (`estimate`); a leg
    /// that is already done (within 10 nm) ends the run there.
    fn next_leg(&mut self, job: Box<PushJob>, leg: usize, estimate: (f64, f64), distance: f64, reading: &Reading) {
        match job.prepared.request(job.particle, estimate, job.legs[leg].to, None) {
            Some(request) => {
                let task = job.prepared.task(&request, self.params.tick);
                let strategy = Strategy::new(self.params, task, job.prepared.hxy(), reading);
                self.active = Some(Active {
                    job,
                    leg,
                    strategy,
                    stop: false,
                });
            }
            None => {
                self.ending = Some(Ending {
                    job,
                    leg,
                    estimate,
                    distance,
                    outcome: "ok",
                    failure: None,
                })
            }
        }
    }

    fn finish(&mut self, shared: &Shared, e: Ending) {
        let truth = self
            .afm
            .particles()
            .iter()
            .find(|p| p.id == e.job.particle)
            .map_or([f64::NAN; 2], |p| [p.x, p.y]);
        let _ = shared.records.push(RecordMsg::End { run: e.job.run });
        let _ = shared.events.push(LoopEvent::RunDone {
            run: e.job.run,
            particle: e.job.particle,
            outcome: e.outcome,
            failure: e.failure,
            estimate: [e.estimate.0, e.estimate.1],
            truth,
            legs: e.leg + 1,
        });
        shared.busy.store(false, Relaxed);
    }

    /// The control phase of one tick: commands, then the strategy. Returns the stage target.
    fn control(&mut self, shared: &Shared, reading: &Reading) -> [f64; 3] {
        while let Some(cmd) = shared.commands.pop() {
            match cmd {
                LoopCommand::Push(job) => {
                    if self.active.is_some() || self.shutting_down {
                        shared.metrics.dropped_commands.fetch_add(1, Relaxed);
                        continue;
                    }
                    let _ = shared.records.push(RecordMsg::Begin {
                        run: job.run,
                        particle: job.particle,
                    });
                    let start = job.legs.first().map_or((0.0, 0.0), |l| l.from);
                    self.next_leg(job, 0, start, 0.0, reading);
                }
                LoopCommand::Stop => {
                    if let Some(a) = &mut self.active {
                        a.stop = true;
                        a.strategy.abort("stop requested by the operator", reading.t);
                    }
                }
                LoopCommand::Shutdown => {
                    self.shutting_down = true;
                    self.bilateral.release();
                    if let Some(a) = &mut self.active {
                        a.stop = true;
                        a.strategy.abort("server shutting down", reading.t);
                    }
                }
                LoopCommand::Haptic(h) => match h {
                    HapticCommand::Engage if !self.shutting_down => self.bilateral.engage(reading.stage),
                    HapticCommand::Engage => {}
                    HapticCommand::Release => self.bilateral.release(),
                    HapticCommand::Recenter => {
                        let x = f64::from_bits(shared.metrics.haptic.handle_m.load(Relaxed));
                        if x.is_finite() {
                            self.bilateral.recenter(x);
                        }
                    }
                    HapticCommand::Scale {
                        position_gain,
                        force_gain,
                    } => {
                        let x = f64::from_bits(shared.metrics.haptic.handle_m.load(Relaxed));
                        self.bilateral.rescale(position_gain, force_gain, Some(x));
                    }
                },
            }
        }
        if let Some(mut a) = self.active.take() {
            self.target = a.strategy.tick(reading);
            if !a.strategy.done() {
                self.active = Some(a);
            } else {
                let estimate = a.strategy.summary.estimated_particle;
                let distance = a.strategy.summary.estimated_distance;
                let failure = a.strategy.summary.failure;
                let last = a.leg + 1 == a.job.legs.len();
                // The run ends after this tick's physics, so its record holds the final tick.
                let (outcome, failure) = match failure {
                    Some(f) => (f.code(), Some(f.to_string())),
                    None if a.stop => ("stopped", Some("stopped between legs".into())),
                    None if last => ("ok", None),
                    None => return self.next_then(a, estimate, distance, reading),
                };
                self.ending = Some(Ending {
                    job: a.job,
                    leg: a.leg,
                    estimate,
                    distance,
                    outcome,
                    failure,
                });
            }
        }
        self.target
    }

    /// Runs the loop on this thread until shutdown (see the module docs).
    pub fn run(mut self, shared: Arc<Shared>, cfg: LoopConfig) {
        let granted = cfg.realtime.then(|| make_realtime(cfg.cpu));
        shared
            .metrics
            .realtime
            .store(u64::from(granted.is_some_and(|g| g.fifo)), Relaxed);
        // The loop's core polls while the loop runs (given back when it ends).
        let no_halt = match granted.and_then(|g| g.core) {
            Some(core) if cfg.no_halt => match NoHalt::request(core) {
                Ok(held) => {
                    tracing::info!("control loop: core {core} polls instead of halting between ticks");
                    Some(held)
                }
                Err(e) => {
                    tracing::warn!("control loop: core {core} may halt between ticks and wake the loop late: {e}");
                    None
                }
            },
            _ => None,
        };
        shared.metrics.no_halt.store(u64::from(no_halt.is_some()), Relaxed);
        let hm = &shared.metrics.haptic;
        hm.tip_z_m.store(f64::NAN.to_bits(), Relaxed);
        let haptic = if cfg.haptic {
            hm.enabled.store(true, Relaxed);
            hm.link.store(LINK_DOWN, Relaxed);
            match ServerLink::open() {
                Ok(h) => {
                    self.report_ready(Ok(()));
                    Some(h)
                }
                Err(e) => {
                    // The server refuses to start (serve::run waits for this answer).
                    hm.fault.store(2, Relaxed);
                    self.report_ready(Err(e.to_string()));
                    None
                }
            }
        } else {
            self.report_ready(Ok(()));
            None
        };
        let down_after = crate::serve::haptic::down_after_ns(cfg.haptic_timeout_ms, 1.0 / cfg.rate_hz);
        let mut handle: Option<HapticState> = None;
        let (mut last_taken, mut last_latency, mut link_up) = (0u64, 0u64, false);
        let period = Duration::from_secs_f64(1.0 / cfg.rate_hz);
        let sleeper = spin_sleep::SpinSleeper::default();
        let mut reading = self.afm.read();
        let mut deadline = Instant::now() + period;
        let mut tick: u64 = 0;
        let mut instrument_failed = false;
        // However the thread ends (even by a panic), the recorder and the shutdown must learn it.
        let _finished = Finished(&shared);
        loop {
            let now = Instant::now();
            if deadline > now {
                sleeper.sleep(deadline - now);
            }
            let woke = Instant::now();
            let m = &shared.metrics;
            m.period_error
                .record(woke.saturating_duration_since(deadline).as_secs_f64());

            // Control: the handle, the link's watchdog, commands and the strategy, the hand.
            if let Some(h) = &haptic {
                let now_ns = monotonic_ns();
                if let (Some(s), _) = h.newest() {
                    // A sample stamped in the future (another clock, a bad bridge) is not
                    // believed either: it would look fresh for ever.
                    if believable(&s) && s.time_ns <= now_ns + 1_000_000 {
                        hm.sample(&s, now_ns);
                        if s.latency_ns != 0 && s.latency_ns != last_latency {
                            hm.latency.record(s.latency_ns as f64 * 1e-9);
                            last_latency = s.latency_ns;
                        }
                        // A new bridge (another pid) starts over with the settle and the ramp.
                        if handle.is_some_and(|old| old.pid != s.pid) && link_up {
                            self.bilateral.link_lost();
                        }
                        handle = Some(s);
                        last_taken = s.time_ns.min(now_ns);
                    } else {
                        hm.rejected_samples.fetch_add(1, Relaxed);
                    }
                }
                // The age since the handle was read (one clock for both processes).
                let age = now_ns.saturating_sub(last_taken);
                let up = handle.is_some() && age < down_after;
                if up != link_up {
                    // Logged by the haptic monitor thread, not here: no I/O in the loop.
                    if !up {
                        hm.last_down_age_ns.store(age, Relaxed);
                        hm.link_downs.fetch_add(1, Relaxed);
                    } else {
                        hm.link_ups.fetch_add(1, Relaxed);
                    }
                    hm.link.store(if up { LINK_UP } else { LINK_DOWN }, Relaxed);
                    link_up = up;
                }
            }
            let mut target = self.control(&shared, &reading);
            let hand = self.bilateral.tick(&HapticInput {
                handle: if link_up { handle } else { None },
                stage: reading.stage,
                volts: reading.volts,
                pushing: self.active.is_some(),
            });
            if let Some(t) = hand.target
                && self.active.is_none()
            {
                self.target = t;
                target = t;
            }
            hm.phase.store(phase_index(self.bilateral.phase().name()), Relaxed);
            let t_control = Instant::now();
            m.control.record((t_control - woke).as_secs_f64());

            // Physics.
            match self.afm.step(target) {
                Ok(r) => {
                    reading = r;
                    if let Some(u) = self.afm.take_fault() {
                        // The guard dropped a push model that left physics: the push fails with
                        // `unphysical` and retracts (logged by the run's end, off the loop).
                        if let Some(a) = &mut self.active {
                            a.strategy.unphysical(u, reading.t);
                        }
                    }
                }
                Err(e) => {
                    // The push model failed; the instrument dropped the contact, so the tip is
                    // free. A running push is stopped and retracts like any other failure.
                    if !instrument_failed {
                        tracing::error!("instrument step failed: {e}; stopping the push and retracting");
                    }
                    instrument_failed = true;
                    reading = self.afm.read();
                    if let Some(a) = &mut self.active {
                        a.stop = true;
                        a.strategy.abort("the push simulation failed", reading.t);
                    } else {
                        self.target = reading.stage;
                    }
                }
            }
            let t_physics = Instant::now();
            m.physics.record((t_physics - t_control).as_secs_f64());

            // Publish.
            if let Some(h) = &haptic {
                h.publish(ForceFeedback {
                    seq: tick,
                    time_ns: monotonic_ns(),
                    ..hand.feedback
                });
            }
            hm.tip_force_n.store(hand.feedback.tip_force.to_bits(), Relaxed);
            hm.tip_z_m.store(hand.feedback.tip_z.to_bits(), Relaxed);
            if haptic.is_some() {
                hm.fault.store(u64::from(self.bilateral.fault().is_some()), Relaxed);
            }
            let phase_name = match &self.active {
                Some(a) => a.strategy.phase.name(),
                None => "idle",
            };
            if let Some(a) = &self.active {
                let row = RecordMsg::Row {
                    leg: a.leg as u32 + 1,
                    t: reading.t,
                    phase: phase_name,
                    stage: reading.stage,
                    volts: reading.volts,
                    estimate: a.strategy.summary.estimated_distance,
                };
                if shared.records.push(row).is_err() {
                    m.dropped_rows.fetch_add(1, Relaxed);
                }
            }
            if let Some(e) = self.ending.take() {
                let row = RecordMsg::Row {
                    leg: e.leg as u32 + 1,
                    t: reading.t,
                    phase: "done",
                    stage: reading.stage,
                    volts: reading.volts,
                    estimate: e.distance,
                };
                if shared.records.push(row).is_err() {
                    m.dropped_rows.fetch_add(1, Relaxed);
                }
                self.finish(&shared, e);
            }
            if let Ok(mut s) = shared.snapshot.try_lock() {
                s.t = reading.t;
                s.stage = reading.stage;
                s.volts = reading.volts;
                s.phase = phase_name;
                s.estimate = self.active.as_ref().map(|a| {
                    [
                        a.strategy.summary.estimated_particle.0,
                        a.strategy.summary.estimated_particle.1,
                    ]
                });
                s.tick = tick;
                for (slot, p) in s.particles.iter_mut().zip(self.afm.particles()) {
                    *slot = (p.id, p.x, p.y, p.radius);
                }
            }
            m.publish.record(t_physics.elapsed().as_secs_f64());
            m.ticks.fetch_add(1, Relaxed);
            tick += 1;

            deadline += period;
            let done = Instant::now();
            if done > deadline {
                m.overruns.fetch_add(1, Relaxed);
                // Keep the absolute schedule, but never try to catch up more than one tick.
                if done > deadline + period {
                    deadline = done + period;
                }
            }
            // On shutdown, the push ends and the hand's tip is parked before the loop does.
            if self.shutting_down && self.active.is_none() && self.bilateral.phase() == HapticPhase::Off {
                break;
            }
        }
        if let Some(h) = &haptic {
            h.publish(ForceFeedback {
                seq: tick,
                time_ns: monotonic_ns(),
                state_seq: u64::MAX,
                tip_z: f64::NAN,
                active: 0,
                ..ForceFeedback::default()
            });
        }
        hm.link.store(LINK_DOWN, Relaxed);
        if let Ok(mut s) = shared.snapshot.lock() {
            s.phase = "stopped";
            s.stage = reading.stage;
        }
        tracing::info!(
            "control loop ended after {tick} ticks; tip at z = {:.3} µm",
            reading.stage[2] * 1e6
        );
        // The loop's core may rest again.
        drop(no_halt);
        shared.metrics.no_halt.store(0, Relaxed);
    }
}
