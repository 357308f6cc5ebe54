//! One device cycle of the bridge, free of I/O timing so it runs in tests and benchmarks as it
//! runs in the process: read the handle → take the server's newest force → render the local model
//! → passivity controller → clamp → write the force → publish the handle's state.
//!
//! Safety, in the order it acts:
//! - a device sample that is not finite or lies outside the travel (plus a margin) is dropped and
//!   counted, never published, and the force is zero for that cycle;
//! - a server whose newest force sample is older than `stale_ns` ([`STALE_NS`], 4 ms) is silent: the force is
//!   zero until it speaks again, and the passivity history starts anew;
//! - the local model's stiffness is capped at the device's renderable stiffness;
//! - the passivity controller removes energy the loop generates;
//! - the force is clamped to the device's limit last ([`clamp_force`]), whatever the server sent.

use nanopush_proto::haptic::{
    DeviceFaults, FORCE_ENGAGED, ForceFeedback, HapticState, STALE_NS, STATE_DEVICE_LOST, STATE_SERVER_SILENT,
};

use crate::device::{Device, DeviceError, DeviceSample, DeviceSpec, LinkView, clamp_force};
use crate::passivity::{Passivity, PassivityOutput};

/// The two directions of the link, as the bridge sees them.
pub trait Link {
    /// Publishes the handle's state.
    fn publish(&mut self, state: &HapticState);
    /// The newest force sample that arrived since the last call, if any.
    fn newest(&mut self) -> Option<ForceFeedback>;
}

/// Bridge settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BridgeConfig {
    /// Device cycle rate (Hz), in [500, 4000].
    pub rate_hz: f64,
    /// Render the server's local linear model at the device rate (else hold its force).
    pub local_model: bool,
    /// Run the passivity controller (the observer always runs).
    pub passivity: bool,
    /// `DEVICE_*` code published in each state.
    pub device_code: u32,
    /// A server whose newest sample is older than this is silent (ns).
    pub stale_ns: u64,
}

impl Default for BridgeConfig {
    fn default() -> BridgeConfig {
        BridgeConfig {
            rate_hz: 1000.0,
            local_model: true,
            passivity: true,
            device_code: 0,
            stale_ns: STALE_NS,
        }
    }
}

/// A gap between two force writes longer than this many periods, and at least
/// [`RESUME_AFTER_MIN_NS`] (a stopped process, a long stall: by then a serial device's 10 ms
/// watchdog has zeroed its force), ends with the force ramped in from zero over
/// [`RESUME_RAMP_S`]: the device never gets the force from before the pause at once. One late
/// answer (up to the 2 ms answer wait, rounded up to the next ms) is not a pause. A shorter
/// stall is not one either: the device still holds the force it was given, and dropping it to
/// zero to ramp it in again would be a dip the hand feels — and an active one, the force pushing
/// back a handle the hand pressed in meanwhile (a virtual machine's 5-6 ms pauses in contact
/// would hand the hand up to 2 mJ). A watchdog that tripped sooner says so, and ramps too.
pub const RESUME_AFTER_PERIODS: u64 = 3;
/// The least gap between two force writes that counts as a pause (ns): the serial device's
/// watchdog period.
pub const RESUME_AFTER_MIN_NS: u64 = 10_000_000;
/// How long the force takes to ramp in after a pause or a new device (s).
pub const RESUME_RAMP_S: f64 = 0.02;
/// Samples whose send times are kept for the latency measurement.
const LATENCY_RING: usize = 4096;

/// One cycle, for the trace (`--trace`).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct CycleRow {
    /// Time since the bridge started (s).
    pub t: f64,
    /// Handle position (m).
    pub handle: f64,
    /// Force rendered (N).
    pub force: f64,
    /// Tip height above the substrate from the server (m), NaN when unknown.
    pub tip_z: f64,
    /// Tip force from the server (N), NaN when no server.
    pub tip_force: f64,
    /// The link is up.
    pub link: bool,
    /// Passivity damping (N·s/m).
    pub pc_damping: f64,
    /// Observed port energy (J).
    pub port_energy: f64,
    /// The raw port's energy since the force went live (J).
    pub raw_port_energy: f64,
    /// The hand holds the tip in contact (the simulated operator's hold; never for a real
    /// device).
    pub holding: bool,
    /// End-to-end latency measured this cycle (ns), 0 when none.
    pub latency_ns: u64,
}

/// The bridge's state between cycles.
pub struct Bridge<D: Device> {
    /// The device.
    pub device: D,
    spec: DeviceSpec,
    cfg: BridgeConfig,
    pc: Passivity,
    force: Option<ForceFeedback>,
    seq: u64,
    dropped: u64,
    sent: Box<[(u64, u64); LATENCY_RING]>,
    last_latency_seq: u64,
    latency_ns: u64,
    start_ns: u64,
    link_up: bool,
    pid: u32,
    /// Handle position of the previous good sample (m), for the reference work.
    x_prev: Option<f64>,
    /// The environment model in force over the interval that is running.
    ref_prev: Option<ForceFeedback>,
    /// When the previous force was written (monotonic ns), to see the bridge's own pauses.
    last_write_ns: Option<u64>,
    /// The device's watchdog trips counted so far (a new one ramps the force in again).
    trips_seen: u64,
    /// Why the newest sample was dropped (a device error), for the log.
    last_error: Option<String>,
    /// The previous read took at least a period: a late cycle after it is the device's doing.
    read_was_slow: bool,
    /// The force's gain while it ramps in after a pause or a new device, 0 → 1.
    resume_gain: f64,
    /// The bridge's own faults, and the device counters of devices it has let go.
    faults: DeviceFaults,
    /// The device was lost (a cable fault), and why, until it is replaced.
    lost: Option<String>,
}

impl<D: Device> Bridge<D> {
    /// A bridge over `device`, started at `start_ns` (monotonic ns).
    pub fn new(device: D, cfg: BridgeConfig, start_ns: u64) -> Bridge<D> {
        let spec = device.spec();
        let mut pc = Passivity::new(0.8 * spec.max_damping, 1e-4);
        pc.enabled = cfg.passivity;
        Bridge {
            device,
            spec,
            cfg,
            pc,
            force: None,
            seq: 0,
            dropped: 0,
            sent: Box::new([(u64::MAX, 0); LATENCY_RING]),
            last_latency_seq: u64::MAX,
            latency_ns: 0,
            start_ns,
            link_up: false,
            pid: std::process::id(),
            x_prev: None,
            ref_prev: None,
            last_write_ns: None,
            trips_seen: 0,
            last_error: None,
            read_was_slow: false,
            resume_gain: 1.0,
            faults: DeviceFaults::default(),
            lost: None,
        }
    }

    /// Every fault so far: the bridge's own (overruns, losses, reopens) and the device's, those
    /// of devices it let go included.
    pub fn faults(&self) -> DeviceFaults {
        self.faults + self.device.faults()
    }

    /// A device cycle started more than a period late. When the previous read itself took a
    /// period or more (the device answered late or slowly), the lateness is the device's, counted
    /// there, not the bridge's.
    pub fn count_overrun(&mut self) {
        if !self.read_was_slow {
            self.faults.overruns += 1;
        }
    }

    /// Why the newest device sample was dropped (the device's error), if it was.
    pub fn last_error(&self) -> Option<&str> {
        self.last_error.as_deref()
    }

    /// Why the device was lost, while it is (a cable fault: hang-up, I/O error, vanished path).
    pub fn lost(&self) -> Option<&str> {
        self.lost.as_deref()
    }

    /// Takes a reopened device in place of the lost one: its limits, a new passivity history,
    /// and the force ramped in from zero. The lost device's counters are kept.
    pub fn replace_device(&mut self, device: D) {
        let gone = std::mem::replace(&mut self.device, device);
        self.faults = self.faults + gone.faults();
        self.faults.reopens += 1;
        self.spec = self.device.spec();
        self.pc = Passivity::new(0.8 * self.spec.max_damping, 1e-4);
        self.pc.enabled = self.cfg.passivity;
        self.start_passivity_anew();
        self.lost = None;
        self.last_write_ns = None;
        self.trips_seen = 0;
        self.resume_gain = 0.0;
    }

    /// The device's limits.
    pub fn spec(&self) -> DeviceSpec {
        self.spec
    }

    /// Samples dropped so far.
    pub fn dropped(&self) -> u64 {
        self.dropped
    }

    /// The newest force sample from a server, if any.
    pub fn last_force(&self) -> Option<ForceFeedback> {
        self.force
    }

    fn believable(&self, s: &DeviceSample) -> bool {
        let [lo, hi] = self.spec.travel;
        let margin = crate::serial::travel_margin(self.spec.travel);
        s.position.is_finite() && s.velocity.is_finite() && s.position >= lo - margin && s.position <= hi + margin
    }

    /// One device cycle at monotonic time `now_ns`, with no time passing in it (tests, the
    /// simulated device): [`Bridge::cycle_timed`] on a clock that stands still.
    pub fn cycle(&mut self, now_ns: u64, link: &mut impl Link) -> CycleRow {
        self.cycle_timed(now_ns, || now_ns, link)
    }

    /// One device cycle started at monotonic time `start_ns`: read the handle, then, at `clock()`
    /// after the read (a serial device's read waits for its answer), take the server's newest
    /// force, judge the server, render (local model, passivity, clamp), write the force, and
    /// publish the handle's state. Allocation-free: it runs in the device loop.
    pub fn cycle_timed(&mut self, start_ns: u64, clock: impl Fn() -> u64, link: &mut impl Link) -> CycleRow {
        let dt = 1.0 / self.cfg.rate_hz;
        let sample = self.read_sample(dt);
        // The server's newest sample first, then the clock: a sample taken after the clock could
        // look stamped in the future if the thread is preempted between the two.
        let newest = link.newest();
        let now_ns = clock().max(start_ns);
        self.read_was_slow = now_ns - start_ns >= (dt * 1e9) as u64;
        let t = now_ns.saturating_sub(self.start_ns) as f64 * 1e-9;
        self.ramp_after_pause(now_ns, dt);
        self.take_newest(now_ns, newest);
        let live = self.judge_server(now_ns);
        let mut row = CycleRow {
            t,
            tip_z: self.force.map_or(f64::NAN, |f| f.tip_z),
            tip_force: self.force.map_or(f64::NAN, |f| f.tip_force),
            link: self.link_up,
            ..CycleRow::default()
        };
        let Some(s) = sample else {
            self.start_passivity_anew();
            let _ = self.device.write_force(0.0);
            row.handle = f64::NAN;
            return row;
        };
        let out = self.render(live, &s, dt);
        // A pause between the clock above and the write (the process stopped there) is a pause
        // too: seen at the write, the force starts from zero.
        if clock().saturating_sub(now_ns) > RESUME_AFTER_MIN_NS && self.device.may_drop_force_when_paused() {
            self.resume_gain = 0.0;
        }
        let force = clamp_force(out.force * self.resume_gain, self.spec.max_force);
        if self.device.write_force(force).is_err() {
            self.dropped += 1;
        }
        self.device.observe(&LinkView {
            t,
            up: self.link_up,
            engaged: live.is_some_and(|f| f.flags & FORCE_ENGAGED != 0 && f.gain >= 1.0),
            tip_z: row.tip_z,
        });
        self.publish(now_ns, &s, force, &out, link);
        row.handle = s.position;
        row.force = force;
        row.pc_damping = out.damping;
        row.port_energy = out.energy;
        row.raw_port_energy = out.raw_energy;
        row.holding = self.device.holding();
        row.latency_ns = self.latency_ns;
        row
    }

    /// The handle's sample, if it can be believed. A sample that cannot, or a device that failed
    /// to answer, is dropped and counted; nothing is published for it (the server's watchdog sees
    /// the silence).
    fn read_sample(&mut self, dt: f64) -> Option<DeviceSample> {
        match self.device.read(dt) {
            Ok(s) if self.believable(&s) => Some(s),
            Err(DeviceError::Lost { why, .. }) => {
                if self.lost.is_none() {
                    self.faults.losses += 1;
                }
                self.lost = Some(why);
                self.dropped += 1;
                None
            }
            Err(e) => {
                self.last_error = Some(e.to_string());
                self.dropped += 1;
                None
            }
            Ok(s) => {
                self.last_error = Some(format!(
                    "a sample outside the travel or not finite: position {} m, velocity {} m/s",
                    s.position, s.velocity
                ));
                self.dropped += 1;
                None
            }
        }
    }

    /// After a pause of the bridge (a gap between two force writes over [`RESUME_AFTER_PERIODS`]
    /// periods and [`RESUME_AFTER_MIN_NS`]), after the device says its watchdog zeroed the
    /// force, and after a new device, the force ramps in from zero over [`RESUME_RAMP_S`];
    /// otherwise the ramp goes on (at the start there is no force from before to hold: gain 1).
    fn ramp_after_pause(&mut self, now_ns: u64, dt: f64) {
        let pause_ns = (RESUME_AFTER_PERIODS * (dt * 1e9) as u64).max(RESUME_AFTER_MIN_NS);
        // A device that holds its force through a pause (the simulated one) resumes where it is.
        let paused = self.device.may_drop_force_when_paused()
            && self
                .last_write_ns
                .is_some_and(|prev| now_ns.saturating_sub(prev) > pause_ns);
        // The device's watchdog zeroed its force (it heard nothing valid for 10 ms): from zero.
        let trips = self.device.faults().watchdog_trips;
        let tripped = trips > self.trips_seen;
        self.trips_seen = trips;
        if paused || tripped {
            self.resume_gain = 0.0;
        } else {
            self.resume_gain = (self.resume_gain + dt / RESUME_RAMP_S).min(1.0);
        }
        self.last_write_ns = Some(now_ns);
    }

    /// Takes the server's newest force sample, if one arrived, and with it the end-to-end
    /// latency of the handle sample it was computed from.
    fn take_newest(&mut self, now_ns: u64, newest: Option<ForceFeedback>) {
        if let Some(f) = newest {
            if f.state_seq != u64::MAX
                && f.state_seq != self.last_latency_seq
                && let Some(&(seq, sent)) = self.sent.get((f.state_seq % LATENCY_RING as u64) as usize)
                && seq == f.state_seq
            {
                self.latency_ns = now_ns.saturating_sub(sent);
                self.last_latency_seq = f.state_seq;
            }
            self.force = Some(f);
        }
    }

    /// Whether the server is heard (`link_up`: its newest sample is fresh) and its force, if live.
    /// A server is live while its newest sample is fresh; its force is live while it says so.
    /// Stamped in the future (more than a cycle ahead) is not believed: it would stay fresh.
    /// Without a live force the passivity history starts anew.
    fn judge_server(&mut self, now_ns: u64) -> Option<ForceFeedback> {
        let fresh = self
            .force
            .filter(|f| f.time_ns <= now_ns + 1_000_000 && now_ns.saturating_sub(f.time_ns) <= self.cfg.stale_ns);
        let live = fresh.filter(|f| f.active != 0);
        if live.is_none() {
            self.start_passivity_anew();
        }
        self.link_up = fresh.is_some();
        live
    }

    /// Forgets the passivity controller's history, the previous position and the environment
    /// model in force: the next good sample starts a new interval.
    fn start_passivity_anew(&mut self) {
        self.pc.reset();
        self.x_prev = None;
        self.ref_prev = None;
    }

    /// The force for sample `s` before the device's clamp: the environment ([`Self::environment`])
    /// through the passivity controller against the reference work
    /// ([`Self::reference_work`]), or none while no force is live. Starts the next interval at
    /// `s` under `live`.
    fn render(&mut self, live: Option<ForceFeedback>, s: &DeviceSample, dt: f64) -> PassivityOutput {
        let max = self.spec.max_force;
        let env = self.environment(live, s.position) - self.coupling_damper(live, s.velocity);
        let (dx, w_ref) = self.reference_work(s.position);
        self.x_prev = Some(s.position);
        self.ref_prev = live;
        if live.is_some() {
            self.pc.step(env, dx, s.velocity, dt, w_ref, max)
        } else {
            PassivityOutput {
                force: 0.0,
                damping: 0.0,
                energy: 0.0,
                raw_energy: 0.0,
            }
        }
    }

    /// What the device renders at handle position `x`: the server's local model with its
    /// stiffness capped at what the device renders stably (or its force held, without the local
    /// model), clamped; zero without a live force.
    fn environment(&self, live: Option<ForceFeedback>, x: f64) -> f64 {
        match live {
            Some(f) => {
                // A spring the hand presses into (≤ 0), no stiffer than the device renders: a
                // positive stiffness would be an anti-spring, active by construction.
                let capped = ForceFeedback {
                    stiffness: f.stiffness.clamp(-self.spec.max_stiffness, 0.0),
                    ..f
                };
                let x = if self.cfg.local_model { x } else { f.anchor };
                clamp_force(capped.force_at(x), self.spec.max_force)
            }
            None => 0.0,
        }
    }

    /// The virtual coupling's damper the server asks for (`ForceFeedback::damping`), `−B_c·v`
    /// with the measured velocity, capped at what the device renders stably, while the model has
    /// a stiffness (the coupling's spring is engaged); nothing otherwise.
    fn coupling_damper(&self, live: Option<ForceFeedback>, v: f64) -> f64 {
        match live {
            Some(f) if f.stiffness < 0.0 && f.damping.is_finite() && v.is_finite() => {
                f.damping.clamp(0.0, self.spec.max_damping) * v
            }
            _ => 0.0,
        }
    }

    /// The handle's motion since the previous good sample, to `x`, and the passivity observer's
    /// reference: the work the environment as the server modelled it over the interval that just
    /// ended, uncapped, would have done on the handle along that path.
    fn reference_work(&self, x: f64) -> (f64, f64) {
        match (self.x_prev, self.ref_prev) {
            (Some(x0), Some(f)) => {
                let f = ForceFeedback {
                    stiffness: f.stiffness.min(0.0),
                    ..f
                };
                let reference = |x: f64| clamp_force(f.force_at(x), self.spec.max_force);
                (x - x0, 0.5 * (reference(x0) + reference(x)) * (x - x0))
            }
            (Some(x0), None) => (x - x0, 0.0),
            _ => (0.0, 0.0),
        }
    }

    /// Publishes the handle's state for this cycle and keeps its send time for the latency.
    fn publish(&mut self, now_ns: u64, s: &DeviceSample, force: f64, out: &PassivityOutput, link: &mut impl Link) {
        let state = HapticState {
            seq: self.seq,
            time_ns: now_ns,
            position: s.position,
            velocity: s.velocity,
            force,
            max_force: self.spec.max_force,
            pc_damping: out.damping,
            port_energy: out.energy,
            latency_ns: self.latency_ns,
            dropped: self.dropped,
            pid: self.pid,
            buttons: s.buttons,
            flags: if self.link_up { 0 } else { STATE_SERVER_SILENT },
            device: self.cfg.device_code,
            rate_hz: self.cfg.rate_hz,
            faults: self.faults(),
            max_stiffness: self.spec.max_stiffness,
            max_damping: self.spec.max_damping,
            spec_rate_hz: self.spec.spec_rate_hz,
            pc_cap: self.pc.alpha_max,
            raw_port_energy: out.raw_energy,
        };
        self.sent[(self.seq % LATENCY_RING as u64) as usize] = (self.seq, now_ns);
        link.publish(&state);
        self.seq += 1;
    }

    /// Publishes a state that carries no handle sample, only the faults and the rate, flagged
    /// [`STATE_DEVICE_LOST`]: while the device is lost, the server still sees the counters.
    pub fn publish_lost(&mut self, now_ns: u64, link: &mut impl Link) {
        let state = HapticState {
            seq: self.seq,
            time_ns: now_ns,
            position: f64::NAN,
            velocity: f64::NAN,
            max_force: self.spec.max_force,
            pid: self.pid,
            flags: STATE_DEVICE_LOST | if self.link_up { 0 } else { STATE_SERVER_SILENT },
            device: self.cfg.device_code,
            rate_hz: self.cfg.rate_hz,
            faults: self.faults(),
            dropped: self.dropped,
            ..HapticState::default()
        };
        link.publish(&state);
        self.seq += 1;
    }

    /// The device cycle's rate (Hz).
    pub fn rate_hz(&self) -> f64 {
        self.cfg.rate_hz
    }

    /// Runs at `rate_hz` from now on (a reopened device that carries a different rate); the
    /// server's silence is judged within `stale_ns` as before.
    pub fn set_rate(&mut self, rate_hz: f64) {
        // The server's silence is judged at `time-out − period` (within the time-out at this
        // rate): the threshold moves by the change of period.
        let (old, new) = (1e9 / self.cfg.rate_hz, 1e9 / rate_hz);
        self.cfg.stale_ns = (self.cfg.stale_ns as f64 + old - new).max(new) as u64;
        self.cfg.rate_hz = rate_hz;
    }

    /// Zeroes the force and lets the device go.
    pub fn close(&mut self) {
        let _ = self.device.close();
    }
}

#[cfg(test)]
mod tests;
