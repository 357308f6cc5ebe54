//! The control loop: a dedicated OS thread stepping the instrument at 1 kHz (up to 10 kHz) on an
//! absolute-deadline schedule — sleep until shortly before the deadline, then spin
//! (spin_sleep) — with SCHED_FIFO, CPU affinity and a core that polls instead of halting when the
//! system grants them (logged fallback when not: [`realtime`],
//! [`no_halt`]). Tokio's timer rounds to the millisecond, which is why this is not
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
//! Haptic z-control ([`nanopush_instrument::control::bilateral`]) runs in the control phase: the newest handle
//! sample (rejected and counted if not believable), the link's watchdog (down after 4.5 ms
//! without a sample: logged as "haptic link down", the tip retracts to its parking height), the
//! law's stage target while the hand owns z (outside pushes), and the force with its local model
//! published every tick.

mod messages;
pub mod no_halt;
pub mod realtime;
mod shared;
#[cfg(test)]
mod tests;

use std::sync::Arc;
use std::sync::atomic::Ordering::Relaxed;
use std::time::{Duration, Instant};

use nanopush_proto::haptic::{ForceFeedback, HapticState, STATE_DEVICE_LOST, monotonic_ns};

use crate::haptic::HapticCommand;
use crate::haptic::link::{LINK_DOWN, LINK_UP, ServerLink, believable, down_after_ns};
use crate::haptic::metrics::phase_index;
pub use messages::{LoopCommand, LoopEvent, PUSHED, PushJob, RecordMsg, StopReason};
use nanopush_instrument::afm::{Afm, Reading};
use nanopush_instrument::control::Strategy;
use nanopush_instrument::control::bilateral::{
    Bilateral, BilateralParams, Input as HapticInput, Output as HapticOutput, Phase as HapticPhase,
};
use no_halt::NoHalt;
use realtime::make_realtime;
pub use shared::{LoopConfig, QueueFull, Shared, Snapshot};

/// A push in progress.
struct Active {
    job: Box<PushJob>,
    leg: usize,
    strategy: Strategy,
    /// A stop was asked for, with its words (`stopped: …`).
    stop: Option<&'static str>,
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

/// The haptic link as the loop sees it: the newest handle sample and the watchdog's verdict.
struct HandleLink {
    link: ServerLink,
    /// The link is down this long after the last sample was taken (ns).
    down_after: u64,
    handle: Option<HapticState>,
    last_taken: u64,
    last_latency: u64,
    up: bool,
}

/// Everything the loop owns.
pub struct ControlLoop {
    afm: Afm,
    bilateral: Bilateral,
    target: [f64; 3],
    active: Option<Active>,
    ending: Option<Ending>,
    shutting_down: bool,
    /// Told once the haptic link is open (or could not be).
    ready: Option<std::sync::mpsc::SyncSender<Result<(), String>>>,
    /// The instrument's latest reading (from [`ControlLoop::start`] on).
    reading: Reading,
    /// Ticks so far.
    tick: u64,
    /// The instrument's step failed once (logged once).
    instrument_failed: bool,
}

/// What the loop holds while it runs, from [`ControlLoop::start`] to [`ControlLoop::end`]. Made
/// on the loop's own thread: the iceoryx2 ports may not move between threads.
pub struct Running {
    /// The haptic link, when the loop has one.
    haptic: Option<HandleLink>,
    /// The loop's core polls instead of halting while this is held.
    _no_halt: Option<NoHalt>,
}

impl ControlLoop {
    /// A loop over `afm` with the scene's strategy settings and the haptic z-control's.
    pub fn new(afm: Afm, haptic: BilateralParams) -> ControlLoop {
        let target = afm.stage();
        // Read for real by `start` (a reading draws the sensor's noise, so only once).
        let reading = Reading {
            t: 0.0,
            volts: 0.0,
            stage: target,
        };
        ControlLoop {
            afm,
            bilateral: Bilateral::new(haptic),
            target,
            active: None,
            ending: None,
            shutting_down: false,
            ready: None,
            reading,
            tick: 0,
            instrument_failed: false,
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
        match job
            .prepared
            .request(job.particle, estimate, job.legs[leg].to, None, job.slope)
        {
            Some(request) => {
                let task = job.prepared.task(&request, job.params.tick);
                let strategy = Strategy::new(job.params, task, job.prepared.hxy(), reading);
                self.active = Some(Active {
                    job,
                    leg,
                    strategy,
                    stop: None,
                });
            }
            None => {
                self.ending = Some(Ending {
                    job,
                    leg,
                    estimate,
                    distance,
                    outcome: PUSHED,
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
        // A push whose legs ran stays busy until the scan after it has judged the move.
        if e.outcome != PUSHED {
            shared.busy.store(false, Relaxed);
        }
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
                LoopCommand::Stop(why) => {
                    if let Some(a) = &mut self.active {
                        a.stop = Some(why.words());
                        a.strategy.abort(why.words(), reading.t);
                    }
                }
                LoopCommand::Shutdown => {
                    self.shutting_down = true;
                    self.bilateral.release();
                    if let Some(a) = &mut self.active {
                        a.stop = Some("server shutting down");
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
                    // Every leg ran (a stop that came during the last retraction changed nothing
                    // of the push): judged, and a stop since keeps a correction from starting.
                    None if last => (PUSHED, None),
                    None if a.stop.is_some() => (
                        "stopped",
                        Some(format!("stopped: {} (between legs)", a.stop.unwrap_or_default())),
                    ),
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

    /// Runs the loop on this thread until shutdown (see the module docs): [`ControlLoop::start`],
    /// then a [`ControlLoop::tick`] at each deadline of an absolute schedule, then
    /// [`ControlLoop::end`].
    pub fn run(mut self, shared: Arc<Shared>, cfg: LoopConfig) {
        let mut running = self.start(&shared, &cfg);
        let period = Duration::from_secs_f64(1.0 / cfg.rate_hz);
        let sleeper = spin_sleep::SpinSleeper::default();
        let mut deadline = Instant::now() + period;
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
            let go_on = self.tick(&shared, &mut running, woke);
            deadline += period;
            let done = Instant::now();
            if done > deadline {
                m.overruns.fetch_add(1, Relaxed);
                // Keep the absolute schedule, but never try to catch up more than one tick.
                if done > deadline + period {
                    deadline = done + period;
                }
            }
            if !go_on {
                break;
            }
        }
        self.end(&shared, running);
    }

    /// What the loop asks of the system and the haptic link before its first tick: SCHED_FIFO
    /// and a pinned core (when `cfg.realtime`), a core that polls (when `cfg.no_halt`), the
    /// iceoryx2 link (when `cfg.haptic`; the answer goes to [`ControlLoop::with_ready`]'s
    /// channel).
    pub fn start(&mut self, shared: &Shared, cfg: &LoopConfig) -> Running {
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
        let link = if cfg.haptic {
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
        let haptic = link.map(|link| HandleLink {
            link,
            down_after: down_after_ns(cfg.haptic_timeout, 1.0 / cfg.rate_hz),
            handle: None,
            last_taken: 0,
            last_latency: 0,
            up: false,
        });
        self.reading = self.afm.read();
        Running {
            haptic,
            _no_halt: no_halt,
        }
    }

    /// One tick, woken at `woke`: control, physics, publish, each timed. Returns whether the
    /// loop goes on (false once a shutdown has ended the push and parked the hand's tip).
    pub fn tick(&mut self, shared: &Shared, running: &mut Running, woke: Instant) -> bool {
        let m = &shared.metrics;
        let (target, hand) = self.control_phase(shared, running.haptic.as_mut());
        let t_control = Instant::now();
        m.control.record((t_control - woke).as_secs_f64());

        self.physics_phase(target);
        let t_physics = Instant::now();
        m.physics.record((t_physics - t_control).as_secs_f64());

        self.publish_phase(shared, running.haptic.as_ref(), &hand);
        m.publish.record(t_physics.elapsed().as_secs_f64());
        m.ticks.fetch_add(1, Relaxed);
        self.tick += 1;
        // On shutdown, the push ends and the hand's tip is parked before the loop does.
        !(self.shutting_down && self.active.is_none() && self.bilateral.phase() == HapticPhase::Off)
    }

    /// The control phase: the handle and the link's watchdog, commands and the strategy, then
    /// the hand. Returns the stage target and the haptic law's output.
    fn control_phase(&mut self, shared: &Shared, link: Option<&mut HandleLink>) -> ([f64; 3], HapticOutput) {
        let handle = link.and_then(|h| self.take_handle(shared, h));
        let reading = self.reading;
        let mut target = self.control(shared, &reading);
        let hand = self.bilateral.tick(&HapticInput {
            handle,
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
        shared
            .metrics
            .haptic
            .phase
            .store(phase_index(self.bilateral.phase().name()), Relaxed);
        (target, hand)
    }

    /// Takes the newest handle sample (rejected and counted if not believable) and runs the
    /// link's watchdog. Returns the handle while the link is up.
    fn take_handle(&mut self, shared: &Shared, h: &mut HandleLink) -> Option<HapticState> {
        let hm = &shared.metrics.haptic;
        let now_ns = monotonic_ns();
        if let (Some(s), _) = h.link.newest() {
            // A bridge that lost its device says so: its faults are shown, but it carries no
            // handle sample (the link goes down by the sample's age as for a silent bridge).
            if s.flags & STATE_DEVICE_LOST != 0 {
                hm.note_device(&s);
            // A sample stamped in the future (another clock, a bad bridge) is not
            // believed either: it would look fresh for ever.
            } else if believable(&s) && s.time_ns <= now_ns + 1_000_000 {
                hm.sample(&s, now_ns);
                if s.latency_ns != 0 && s.latency_ns != h.last_latency {
                    hm.latency.record(s.latency_ns as f64 * 1e-9);
                    h.last_latency = s.latency_ns;
                }
                // A new bridge (another pid) starts over with the settle and the ramp.
                if h.handle.is_some_and(|old| old.pid != s.pid) && h.up {
                    self.bilateral.link_lost();
                }
                h.handle = Some(s);
                h.last_taken = s.time_ns.min(now_ns);
            } else {
                hm.rejected_samples.fetch_add(1, Relaxed);
            }
        }
        // The age since the handle was read (one clock for both processes).
        let age = now_ns.saturating_sub(h.last_taken);
        let up = h.handle.is_some() && age < h.down_after;
        if up != h.up {
            // Logged by the haptic monitor thread, not here: no I/O in the loop.
            if !up {
                hm.last_down_age_ns.store(age, Relaxed);
                hm.link_downs.fetch_add(1, Relaxed);
            } else {
                hm.link_ups.fetch_add(1, Relaxed);
            }
            hm.link.store(if up { LINK_UP } else { LINK_DOWN }, Relaxed);
            h.up = up;
        }
        if h.up { h.handle } else { None }
    }

    /// The physics phase: the instrument one tick towards `target`. A push model that left
    /// physics, or a failed step, ends the running push with a retraction.
    fn physics_phase(&mut self, target: [f64; 3]) {
        match self.afm.step(target) {
            Ok(r) => {
                self.reading = r;
                if let Some(u) = self.afm.take_fault() {
                    // The guard dropped a push model that left physics: the push fails with
                    // `unphysical` and retracts (logged by the run's end, off the loop).
                    if let Some(a) = &mut self.active {
                        a.strategy.unphysical(u, self.reading.t);
                    }
                }
            }
            Err(e) => {
                // The push model failed; the instrument dropped the contact, so the tip is
                // free. A running push is stopped and retracts like any other failure.
                if !self.instrument_failed {
                    tracing::error!("instrument step failed: {e}; stopping the push and retracting");
                }
                self.instrument_failed = true;
                self.reading = self.afm.read();
                if let Some(a) = &mut self.active {
                    a.stop = Some("the push simulation failed");
                    a.strategy.abort("the push simulation failed", self.reading.t);
                } else {
                    self.target = self.reading.stage;
                }
            }
        }
    }

    /// The publish phase: the force to the haptic bridge, the trace rows to the recorder, a
    /// finished run's event, and the telemetry snapshot (skipped if a reader holds it).
    fn publish_phase(&mut self, shared: &Shared, link: Option<&HandleLink>, hand: &HapticOutput) {
        let hm = &shared.metrics.haptic;
        let reading = self.reading;
        if let Some(h) = link {
            h.link.publish(ForceFeedback {
                seq: self.tick,
                time_ns: monotonic_ns(),
                ..hand.feedback
            });
        }
        hm.tip_force_n.store(hand.feedback.tip_force.to_bits(), Relaxed);
        hm.tip_z_m.store(hand.feedback.tip_z.to_bits(), Relaxed);
        hm.note_scales(&self.bilateral.params, self.bilateral.coupling());
        if link.is_some() {
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
                shared.metrics.dropped_rows.fetch_add(1, Relaxed);
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
                shared.metrics.dropped_rows.fetch_add(1, Relaxed);
            }
            self.finish(shared, e);
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
            s.tick = self.tick;
            for (slot, p) in s.particles.iter_mut().zip(self.afm.particles()) {
                *slot = (p.id, p.x, p.y, p.radius);
            }
        }
    }

    /// After the last tick: the haptic force released, the link marked down, the snapshot
    /// `stopped`, and the loop's core given back.
    pub fn end(&mut self, shared: &Shared, running: Running) {
        let hm = &shared.metrics.haptic;
        if let Some(h) = &running.haptic {
            h.link.publish(ForceFeedback {
                seq: self.tick,
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
            s.stage = self.reading.stage;
        }
        tracing::info!(
            "control loop ended after {} ticks; tip at z = {:.3} µm",
            self.tick,
            self.reading.stage[2] * 1e6
        );
        // The loop's core may rest again.
        drop(running);
        shared.metrics.no_halt.store(0, Relaxed);
    }
}
