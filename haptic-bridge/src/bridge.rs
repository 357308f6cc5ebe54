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
/// back a handle the hand pressed in meanwhile (issue 25: a virtual machine's 5-6 ms pauses in
/// contact handed the hand up to 2 mJ). A watchdog that tripped sooner says so, and ramps too.
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
mod tests {
    use super::*;
    use crate::operator::Script;
    use crate::sim::SimDevice;

    /// A link in memory: what the bridge published, and a queue of force samples to hand it.
    #[derive(Default)]
    struct Loop {
        published: Vec<HapticState>,
        next: Option<ForceFeedback>,
    }

    impl Link for Loop {
        fn publish(&mut self, s: &HapticState) {
            self.published.push(*s);
        }
        fn newest(&mut self) -> Option<ForceFeedback> {
            self.next.take()
        }
    }

    fn live(force: f64, now_ns: u64) -> ForceFeedback {
        ForceFeedback {
            time_ns: now_ns,
            force,
            active: 1,
            half_range: 1.0,
            state_seq: u64::MAX,
            ..Default::default()
        }
    }

    /// docs/haptics.md, "Passivity": the damping is "capped at 80 % of the damping the device renders
    /// (`m/T`)" and never applied "at `|v| < 0.1 mm/s`": the bridge's controller for the
    /// simulated handle at 1, 2 and 4 kHz.
    #[test]
    fn the_bridges_passivity_cap_is_80_percent_of_m_over_t_and_its_speed_guard_0_1_mm_per_s() {
        for rate in [1000.0, 2000.0, 4000.0] {
            let period = 1.0 / rate;
            let cfg = BridgeConfig {
                rate_hz: rate,
                ..BridgeConfig::default()
            };
            let b = Bridge::new(SimDevice::new(Script::Hold, period), cfg, 0);
            let m_over_t = crate::sim::Handle::default().mass / period;
            assert!((b.spec.max_damping - m_over_t).abs() <= 1e-12 * m_over_t);
            assert!((b.pc.alpha_max - 0.8 * m_over_t).abs() <= 1e-12 * m_over_t);
            assert_eq!(b.pc.v_min, 1e-4);
            assert!(b.pc.enabled);
        }
    }

    /// A device whose answers take as long as its test says, and whose watchdog trips on demand.
    struct Slow {
        sim: SimDevice,
        trips: u64,
    }

    impl Device for Slow {
        fn spec(&self) -> DeviceSpec {
            self.sim.spec()
        }
        fn read(&mut self, dt: f64) -> Result<DeviceSample, DeviceError> {
            self.sim.read(dt)
        }
        fn write_force(&mut self, force: f64) -> Result<(), DeviceError> {
            self.sim.write_force(force)
        }
        fn faults(&self) -> DeviceFaults {
            DeviceFaults {
                watchdog_trips: self.trips,
                ..DeviceFaults::default()
            }
        }
    }

    /// Review of issue 28: a read that waited 2 ms for a late answer made the server's newest
    /// sample, published meanwhile, look stamped in the future: the force was zeroed and the
    /// server blamed. The server is judged after the read now.
    #[test]
    fn a_late_answer_neither_zeroes_the_force_nor_blames_the_server() {
        let sim = SimDevice::new(Script::Hold, 1e-3);
        let mut b = Bridge::new(Slow { sim, trips: 0 }, BridgeConfig::default(), 0);
        let mut link = Loop::default();
        let ms = 1_000_000;
        link.next = Some(live(0.5, ms));
        assert_eq!(b.cycle(ms, &mut link).force, 0.5);
        // The next cycle starts at 2 ms; its read returns at 4.2 ms; the server's sample of 4 ms
        // arrived during the read.
        link.next = Some(live(0.5, 4 * ms));
        let row = b.cycle_timed(2 * ms, || 4 * ms + 200_000, &mut link);
        assert!(row.link, "the server is heard");
        assert_eq!(row.force, 0.5, "no zero, no ramp: a late answer is not a pause");
        // At 2 kHz a late answer is a 3.2 ms gap between writes: still not a pause.
        let mut b = Bridge::new(
            SimDevice::new(Script::Hold, 5e-4),
            BridgeConfig {
                rate_hz: 2000.0,
                ..BridgeConfig::default()
            },
            0,
        );
        link.next = Some(live(0.5, ms));
        b.cycle(ms, &mut link);
        link.next = Some(live(0.5, 4 * ms));
        assert_eq!(b.cycle_timed(ms + 500_000, || 4 * ms + 200_000, &mut link).force, 0.5);
    }

    /// Review of issue 28: after the device's watchdog zeroed its force (it heard nothing valid
    /// for 10 ms while the bridge ran on), the force came back as a step. It ramps in now.
    #[test]
    fn after_the_devices_watchdog_tripped_the_force_ramps_in() {
        let sim = SimDevice::new(Script::Hold, 1e-3);
        let mut b = Bridge::new(Slow { sim, trips: 0 }, BridgeConfig::default(), 0);
        let mut link = Loop::default();
        let ms = 1_000_000;
        let mut t = ms;
        link.next = Some(live(0.5, t));
        assert_eq!(b.cycle(t, &mut link).force, 0.5);
        b.device.trips = 1;
        t += ms;
        link.next = Some(live(0.5, t));
        assert_eq!(b.cycle(t, &mut link).force, 0.0, "from zero after the trip");
        t += ms;
        link.next = Some(live(0.5, t));
        let f = b.cycle(t, &mut link).force;
        assert!(f > 0.0 && f < 0.05, "ramping: {f}");
    }

    /// Issue 28, "a stale force after a host pause": after the bridge was stopped for 50 ms, its
    /// first packet carried the force from before (505 mN) and the hand felt a kick. Now a pause
    /// of more than 3 periods and 10 ms ramps the force in from zero over 20 ms, on a device that
    /// may have dropped its force meanwhile (a watchdog: `Slow` stands for one).
    #[test]
    fn after_a_pause_the_force_ramps_in_from_zero_not_at_the_old_force() {
        let sim = SimDevice::new(Script::Hold, 1e-3);
        let mut b = Bridge::new(Slow { sim, trips: 0 }, BridgeConfig::default(), 0);
        let mut link = Loop::default();
        let ms = 1_000_000;
        let mut t = 0;
        for _ in 0..5 {
            t += ms;
            link.next = Some(live(0.5, t));
            assert_eq!(b.cycle(t, &mut link).force, 0.5, "steady before the pause");
        }
        // The bridge is stopped 50 ms; the server's newest force is fresh when it resumes.
        t += 50 * ms;
        let mut forces = Vec::new();
        for _ in 0..25 {
            link.next = Some(live(0.5, t));
            forces.push(b.cycle(t, &mut link).force);
            t += ms;
        }
        assert!(
            forces[0] <= 0.5 * 0.05 + 1e-12,
            "first force after the pause: {}",
            forces[0]
        );
        assert!(forces.windows(2).all(|w| w[1] >= w[0]), "it only grows: {forces:?}");
        assert_eq!(forces[20], 0.5, "ramped in over 20 ms: {forces:?}");
        // A pause of 3 periods or less is a late cycle, not a pause: no ramp.
        t += 2 * ms;
        link.next = Some(live(0.5, t));
        assert_eq!(b.cycle(t, &mut link).force, 0.5);
        // Issue 25: nor is a stall shorter than a serial device's 10 ms watchdog (the device still
        // holds its force: dropping it would be an active dip); one of 10 ms and more is.
        t += 9_900_000;
        link.next = Some(live(0.5, t));
        assert_eq!(b.cycle(t, &mut link).force, 0.5, "a 9.9 ms stall");
        t += 10_100_000;
        link.next = Some(live(0.5, t));
        assert!(b.cycle(t, &mut link).force < 0.05, "a 10.1 ms stall");
    }

    /// Issue 25: the simulated device holds its force through any pause (its motor holds it, its
    /// handle stands still): after 50 ms the bridge resumes at the force of the moment, without
    /// the dip and ramp that pushed a loose hand's handle back (−0.36 mJ and a 44 % tip swing
    /// after a 12.7 ms stall in the grid's loose grip at 10 nm/mm and 10 N).
    #[test]
    fn a_device_that_holds_its_force_resumes_without_a_ramp() {
        let mut b = Bridge::new(SimDevice::new(Script::Hold, 1e-3), BridgeConfig::default(), 0);
        let mut link = Loop::default();
        let ms = 1_000_000;
        link.next = Some(live(0.5, ms));
        assert_eq!(b.cycle(ms, &mut link).force, 0.5);
        link.next = Some(live(0.5, 51 * ms));
        assert_eq!(b.cycle(51 * ms, &mut link).force, 0.5);
    }

    /// Issue 28: a reopened device starts with the force ramped in, its limits taken anew, and
    /// the lost device's counters kept (one reopen counted).
    #[test]
    fn a_replaced_device_ramps_in_and_the_counters_carry_over() {
        let mut b = Bridge::new(SimDevice::new(Script::Hold, 1e-3), BridgeConfig::default(), 0);
        let mut link = Loop::default();
        let ms = 1_000_000;
        b.count_overrun();
        b.faults.losses += 1;
        b.replace_device(SimDevice::new(Script::Hold, 1e-3));
        let f = b.faults();
        assert_eq!((f.overruns, f.losses, f.reopens), (1, 1, 1));
        assert!(b.lost().is_none());
        link.next = Some(live(1.0, ms));
        let first = b.cycle(ms, &mut link).force;
        assert!(first > 0.0 && first <= 0.05 + 1e-12, "{first}");
        assert_eq!(link.published.last().unwrap().faults, f, "published with every state");
        assert_eq!(link.published.last().unwrap().rate_hz, 1000.0);
    }

    #[test]
    fn the_bridge_clamps_whatever_the_server_sends_and_zeroes_a_silent_server() {
        let mut b = Bridge::new(SimDevice::new(Script::Hold, 1e-3), BridgeConfig::default(), 0);
        let mut link = Loop::default();
        let ms = 1_000_000;
        link.next = Some(live(100.0, ms));
        let row = b.cycle(ms, &mut link);
        assert_eq!(row.force, 2.5, "clamped to the device's limit");
        assert!(row.link);
        // The server falls silent: the same sample ages; zero force once it is 5 ms old.
        let mut t = ms;
        let mut silent_at = None;
        for _ in 0..10 {
            t += ms;
            let row = b.cycle(t, &mut link);
            if row.force == 0.0 && silent_at.is_none() {
                silent_at = Some(t - ms);
                assert!(!row.link);
                assert_eq!(
                    link.published.last().unwrap().flags & STATE_SERVER_SILENT,
                    STATE_SERVER_SILENT
                );
            }
        }
        // Zero force within 5 ms of the last sample (cycles at 1 kHz).
        assert!(silent_at.unwrap() <= 5 * ms, "{silent_at:?}");
        // It comes back: the force is live again.
        link.next = Some(live(0.5, t + ms));
        let row = b.cycle(t + ms, &mut link);
        assert!(row.link && (row.force - 0.5).abs() < 0.1, "{row:?}");
        // Non-finite forces render nothing.
        link.next = Some(live(f64::NAN, t + 2 * ms));
        assert_eq!(b.cycle(t + 2 * ms, &mut link).force, 0.0);
    }

    /// A device that reports garbage every other cycle.
    struct Glitchy(u32);

    impl Device for Glitchy {
        fn spec(&self) -> DeviceSpec {
            SimDevice::new(Script::Hold, 1e-3).spec()
        }
        fn read(&mut self, _dt: f64) -> Result<DeviceSample, crate::device::DeviceError> {
            self.0 += 1;
            Ok(DeviceSample {
                position: match self.0 % 3 {
                    0 => f64::NAN,
                    1 => 1.0, // a metre: outside the travel
                    _ => 0.001,
                },
                velocity: 0.0,
                buttons: 0,
            })
        }
        fn write_force(&mut self, _f: f64) -> Result<(), crate::device::DeviceError> {
            Ok(())
        }
    }

    #[test]
    fn samples_outside_the_travel_or_not_finite_are_dropped_and_counted() {
        let mut b = Bridge::new(Glitchy(0), BridgeConfig::default(), 0);
        let mut link = Loop::default();
        for k in 0..30u64 {
            b.cycle(k * 1_000_000, &mut link);
        }
        assert_eq!(b.dropped(), 20);
        assert_eq!(link.published.len(), 10);
        assert!(link.published.iter().all(|s| s.position == 0.001));
        // The last published sample went out before the last cycle's drop.
        assert_eq!(link.published.last().unwrap().dropped, 19);
        // Sequence numbers count published samples, without gaps.
        assert!(link.published.windows(2).all(|w| w[1].seq == w[0].seq + 1));
    }

    #[test]
    fn latency_is_the_time_from_a_sample_to_the_force_computed_from_it() {
        let mut b = Bridge::new(SimDevice::new(Script::Hold, 1e-3), BridgeConfig::default(), 0);
        let mut link = Loop::default();
        b.cycle(1_000_000, &mut link);
        let seq = link.published[0].seq;
        link.next = Some(ForceFeedback {
            state_seq: seq,
            ..live(0.0, 1_500_000)
        });
        let row = b.cycle(2_000_000, &mut link);
        assert_eq!(row.latency_ns, 1_000_000);
    }

    /// A stiff wall at `x_w` computed by a "server" from the newest published sample (one cycle
    /// late, as the real loop is), sent with its stiffness; the bridge renders it as a held force.
    /// Returns the peak-to-peak handle motion over the last second and the lowest observed energy.
    fn wall(k: f64, passivity: bool, local_model: bool) -> (f64, f64) {
        let dt = 1e-3;
        let script = Script::from_csv("press", "0,0\n2,-0.004\n4,-0.004\n").unwrap();
        let cfg = BridgeConfig {
            passivity,
            local_model,
            ..BridgeConfig::default()
        };
        let mut b = Bridge::new(SimDevice::new(script, dt), cfg, 0);
        b.device.operator.damping = 1.0; // a light grip
        let mut link = Loop::default();
        let x_w = -0.002;
        let (mut lo, mut hi, mut e_min) = (f64::INFINITY, f64::NEG_INFINITY, f64::INFINITY);
        for n in 1..4000u64 {
            let now = n * 1_000_000;
            if let Some(st) = link.published.last() {
                let pen = x_w - st.position;
                link.next = Some(ForceFeedback {
                    seq: n,
                    time_ns: now,
                    state_seq: st.seq,
                    force: if pen > 0.0 { k * pen } else { 0.0 },
                    stiffness: if pen > 0.0 { -k } else { 0.0 },
                    anchor: st.position,
                    half_range: 0.01,
                    gain: 1.0,
                    active: 1,
                    flags: FORCE_ENGAGED,
                    ..Default::default()
                });
            }
            let row = b.cycle(now, &mut link);
            if n > 3000 {
                lo = lo.min(row.handle);
                hi = hi.max(row.handle);
            }
            if n > 10 {
                e_min = e_min.min(row.port_energy);
            }
        }
        (hi - lo, e_min)
    }

    /// The sampled loop makes a stiff wall rendered as a held force buzz: the hand, pressing
    /// slowly, comes to rest against it only with the passivity controller, which keeps the
    /// observed energy above −1 µJ; without it the handle bounces (a limit cycle bounded by the
    /// motor's saturation) and the energy runs away negative.
    #[test]
    fn a_stiff_held_wall_buzzes_without_the_passivity_controller_and_settles_with_it() {
        // 20 kN/m against a light grip (1 N·s/m): ten times the sampled loop's limit
        // `K < 2b/T` ≈ 2 kN/m; the controller holds it up to ~40 kN/m (its damping cap, 40
        // N·s/m, is then reached).
        let k = 20_000.0;
        let (p2p_off, e_off) = wall(k, false, false);
        let (p2p_on, e_on) = wall(k, true, false);
        eprintln!("held wall {k} N/m: without PC p2p {p2p_off:e} m, E_min {e_off:e} J; with {p2p_on:e} m, {e_on:e} J");
        assert!(p2p_off > 2e-4, "without the controller the wall should buzz: {p2p_off}");
        assert!(
            p2p_on < 2e-5,
            "with the controller the hand should rest on the wall: {p2p_on}"
        );
        assert!(e_on > -1e-6, "{e_on}");
        assert!(e_off < -1e-4, "{e_off}");
    }
}
