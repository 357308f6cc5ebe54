//! The manipulation strategy of Sec 2.1 as an explicit state machine (Fig 2):
//!
//! - travel at the start height to the point the push starts from;
//! - A → B *auto-parking*: approach in z until the deflection detects the substrate (its height
//!   is not known beforehand), then retract to the parking height that gives the contact angle
//!   `β` on the particle; a tip the substrate still holds there rises on until it lets go, then
//!   comes back down ([`pull_off`]);
//! - B → C *auto particle contact detection*: move in steps `Δ` at speed `V` until the reading
//!   reaches `ζ_set`, then stop;
//! - C → D *push* the requested distance at constant `V` under force control (Sec 3: the
//!   Eq 19 feedback [`Hxy`], optionally with the tip height regulated on `ζ_z`);
//! - D → E *retract* to the start height.
//!
//! Every phase has a time-out and every failure a typed reason; a failed run always ends with
//! the tip retracted. A reading on the readout's rail is an emergency, except on the pull side
//! while the tip moves up away from a contact, within the rise its pull-off needs
//! ([`pull_off`] states the rule). The strategy sees only what the instrument measures ([`Reading`]: stage
//! position, deflection in volts), never the simulator's state.

use super::pull_off::{self, Motion, Saturation};
use super::{Control, Failure, PushTask, SearchStep, StrategyParams, Summary};
use crate::afm::Reading;
use crate::control::estimator::{ContactSide, Hxy};

/// How far the tip backs off along the line of centres before it lifts (m).
pub const BACK_OFF: f64 = 100e-9;

/// How long the stage stays stopped at the end of a push before the retraction (s).
pub const HOLD: f64 = 0.05;

/// Samples after `t*` averaged into the z loop's reference.
const Z_REFERENCE_SAMPLES: u32 = 20;

/// The phases of Fig 2.
#[derive(Debug, Clone, PartialEq)]
pub enum Phase {
    /// Travel at the start height to the search start.
    Travel,
    /// A → B: z approach until the substrate is detected.
    Park,
    /// B: retract to the parking height above the detected substrate.
    ToParkingHeight {
        /// Target stage z (m).
        z: f64,
    },
    /// B: the substrate still holds the tip at the parking height: rise until it lets go (the
    /// reading back within the substrate threshold), then back down to the parking height.
    LetGo {
        /// The parking height's stage z (m).
        park_z: f64,
    },
    /// B → C: steps `Δ` at `V` until the set point.
    ContactSearch {
        /// Steps begun (1-based).
        step: u32,
        /// Travel within the current step (m).
        in_step: f64,
        /// Dwell ticks left after the step.
        dwell: u32,
    },
    /// C → D: push under force control.
    Push {
        /// Stage position when the push began (contact stop).
        from: [f64; 3],
    },
    /// D: the stage stopped at the end of the push; let the particle settle.
    Hold {
        /// Ticks left.
        ticks: u32,
    },
    /// D → E, first part: back away from the particle along the line of centres, so the
    /// adhesion (meniscus, JKR) pulls through the particle's centre and cannot roll it back.
    BackOff {
        /// Stage target (m).
        goal: [f64; 3],
    },
    /// D → E (or after a failure): retract to the start height.
    Retract,
    /// E: finished.
    Done,
}

impl Phase {
    /// Name for traces.
    pub fn name(&self) -> &'static str {
        match self {
            Phase::Travel => "travel",
            Phase::Park => "park",
            Phase::ToParkingHeight { .. } => "to_parking_height",
            Phase::LetGo { .. } => "let_go",
            Phase::ContactSearch { .. } => "contact_search",
            Phase::Push { .. } => "push",
            Phase::Hold { .. } => "hold",
            Phase::BackOff { .. } => "back_off",
            Phase::Retract => "retract",
            Phase::Done => "done",
        }
    }
}

/// The state machine.
#[derive(Debug, Clone)]
pub struct Strategy {
    /// Settings.
    pub params: StrategyParams,
    /// The push.
    pub task: PushTask,
    /// Phase now.
    pub phase: Phase,
    phase_start: f64,
    target: [f64; 3],
    hxy: Hxy,
    /// Result so far.
    pub summary: Summary,
    dwell_sum: f64,
    lost_count: u32,
    moving_contact: u32,
    z_hold: (f64, u32),
    retract_z: f64,
    pause_left: Option<u32>,
    /// The tip let go of the substrate above the parking height and is coming back down.
    let_go: bool,
}

impl Strategy {
    /// A strategy for `task`, starting from the stage position of `first` (the tip at the start
    /// height), with the Eq 19 estimator `hxy` from the pushing model.
    pub fn new(params: StrategyParams, task: PushTask, hxy: Hxy, first: &Reading) -> Strategy {
        Strategy {
            params,
            task,
            phase: Phase::Travel,
            phase_start: first.t,
            target: first.stage,
            hxy,
            summary: Summary {
                failure: None,
                substrate_z: None,
                contact_step: None,
                contact_stage: None,
                t_star: None,
                estimated_distance: 0.0,
                push_travel: 0.0,
                search: Vec::new(),
                estimated_particle: task.particle,
            },
            dwell_sum: 0.0,
            lost_count: 0,
            moving_contact: 0,
            z_hold: (0.0, 0),
            retract_z: first.stage[2],
            pause_left: None,
            let_go: false,
        }
    }

    /// Stops the run now: the tip backs off if it may touch the particle, then retracts (at the
    /// travel speed). No effect once retracting.
    pub fn abort(&mut self, reason: &'static str, t: f64) {
        if matches!(self.phase, Phase::BackOff { .. } | Phase::Retract | Phase::Done) {
            return;
        }
        self.fail(Failure::Stopped { reason }, t);
    }

    /// The instrument reports an unphysical state (its guard dropped the push model): the run
    /// fails with `unphysical` and the tip goes straight up.
    pub fn unphysical(&mut self, u: crate::afm::Unphysical, t: f64) {
        let phase = self.phase.name();
        let failure = Failure::Unphysical {
            what: u.what,
            value: u.value,
            limit: u.limit,
            phase,
        };
        if matches!(self.phase, Phase::Retract | Phase::Done) {
            self.summary.failure.get_or_insert(failure);
        } else {
            self.fail(failure, t);
        }
    }

    /// Whether the run is over.
    pub fn done(&self) -> bool {
        self.phase == Phase::Done
    }

    /// What the tip is doing, for a saturated reading ([`pull_off::judge`]).
    fn motion(&self) -> Motion {
        let zs = self.summary.substrate_z;
        match self.phase {
            Phase::Park => Motion::Detecting,
            Phase::ToParkingHeight { z } if !self.let_go && zs.is_some_and(|zs| z > zs) => Motion::RisingOffSubstrate,
            Phase::LetGo { .. } => Motion::RisingOffSubstrate,
            Phase::BackOff { .. } | Phase::Retract => Motion::LeavingParticle,
            _ => Motion::Other,
        }
    }

    fn enter(&mut self, phase: Phase, t: f64) {
        self.phase = phase;
        self.phase_start = t;
    }

    fn fail(&mut self, failure: Failure, t: f64) {
        if self.summary.failure.is_none() {
            self.summary.failure = Some(failure);
        }
        // A tip that may touch the particle backs off first; an emergency goes straight up.
        let touching = matches!(self.phase, Phase::Push { .. } | Phase::Hold { .. })
            && !matches!(failure, Failure::DeflectionLimit { .. } | Failure::Unphysical { .. });
        if touching {
            let goal = self.back_off_goal();
            self.enter(Phase::BackOff { goal }, t);
        } else {
            self.enter(Phase::Retract, t);
        }
    }

    /// 100 nm back along the line of centres from the tip to the particle, `(−cos β, sin β)`
    /// in the push frame.
    fn back_off_goal(&self) -> [f64; 3] {
        let (s, c) = self.task.beta.sin_cos();
        let d = self.task.direction;
        [
            self.target[0] - d.0 * c * BACK_OFF,
            self.target[1] - d.1 * c * BACK_OFF,
            self.target[2] + s * BACK_OFF,
        ]
    }

    /// Moves the target toward `goal` by at most `speed·tick`; true when it got there.
    fn move_toward(&mut self, goal: [f64; 3], speed: f64) -> bool {
        let max = speed * self.params.tick;
        let d: [f64; 3] = std::array::from_fn(|i| goal[i] - self.target[i]);
        let len = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
        if len <= max {
            self.target = goal;
            true
        } else {
            for (t, di) in self.target.iter_mut().zip(d) {
                *t += di * max / len;
            }
            false
        }
    }

    /// One control tick: takes the newest reading, returns the stage target for the end of the
    /// next tick. The guards come first (the safety limit, a saturated reading, the phase's
    /// time-out), then the phase's own step.
    pub fn tick(&mut self, r: &Reading) -> [f64; 3] {
        let sig = self.params.signal(r.volts);
        self.guard_safety_limit(r);
        self.guard_saturation(r, sig);
        self.guard_timeout(r);
        match self.phase.clone() {
            Phase::Travel => self.travel(r),
            Phase::Park => self.park(r, sig),
            Phase::ToParkingHeight { z } => self.rise_to_parking_height(r, sig, z),
            Phase::LetGo { park_z } => self.rise_until_let_go(r, sig, park_z),
            Phase::ContactSearch { step, in_step, dwell } => {
                self.contact_search(r, self.params.contact_signal(r.volts), step, in_step, dwell)
            }
            Phase::Push { from } => self.push(r, sig, from),
            Phase::Hold { ticks } => self.hold(r, ticks),
            Phase::BackOff { goal } => {
                if self.move_toward(goal, self.params.approach_speed) {
                    self.enter(Phase::Retract, r.t);
                }
            }
            Phase::Retract => self.retract(r, sig),
            Phase::Done => {}
        }
        self.target
    }

    /// Safety first, in every phase that can touch something: a reading past the safety limit
    /// fails the run.
    /// A contact read on the pull side has its limit there, for the phases that touch the
    /// particle; the tip's adhesion to the substrate reads on that side too while it parks, and
    /// is ridden out by the saturation guard's rule instead.
    fn guard_safety_limit(&mut self, r: &Reading) {
        let p = self.params;
        let limit = p.contact_signal(p.safety_limit);
        let guarded = match p.contact_side {
            ContactSide::Push => !matches!(self.phase, Phase::Retract | Phase::BackOff { .. } | Phase::Done),
            ContactSide::Pull => matches!(
                self.phase,
                Phase::ContactSearch { .. } | Phase::Push { .. } | Phase::Hold { .. }
            ),
        };
        if p.contact_signal(r.volts) > limit && guarded {
            let phase = self.phase.name();
            self.fail(
                Failure::DeflectionLimit {
                    volts: r.volts,
                    limit: p.safety_limit,
                    phase,
                },
                r.t,
            );
        }
    }

    /// A saturated reading says nothing of the force but that it is beyond the readout's range:
    /// an emergency, but on the pull side while the tip rises off a contact (`pull_off`'s rule).
    fn guard_saturation(&mut self, r: &Reading, sig: f64) {
        let p = self.params;
        let saturated = r.volts.abs() >= p.full_scale;
        if !saturated || self.phase == Phase::Done {
            return;
        }
        let phase = self.phase.name();
        let rise = self.summary.substrate_z.map_or(0.0, |zs| r.stage[2] - zs);
        let failure = match pull_off::judge(sig, self.motion(), rise, p.pull_off_rise) {
            Saturation::RideOut => None,
            Saturation::Emergency => Some(Failure::DeflectionLimit {
                volts: r.volts,
                limit: p.full_scale.copysign(r.volts),
                phase,
            }),
            Saturation::HeldTooLong => Some(Failure::StillHeld {
                rise_nm: rise * 1e9,
                bound_nm: p.pull_off_rise * 1e9,
                phase,
            }),
        };
        match failure {
            // Already going straight up: said, not restarted.
            Some(f) if self.phase == Phase::Retract => {
                self.summary.failure.get_or_insert(f);
            }
            Some(f) => self.fail(f, r.t),
            None => {}
        }
    }

    /// A phase past its time-out fails the run; a back-off that cannot finish lifts anyway, and
    /// a retract that cannot finish stops where it is.
    fn guard_timeout(&mut self, r: &Reading) {
        let p = self.params;
        let overdue = r.t - self.phase_start > p.timeout;
        if !overdue || self.phase == Phase::Done {
            return;
        }
        let phase = self.phase.name();
        if matches!(self.phase, Phase::BackOff { .. }) {
            self.enter(Phase::Retract, r.t);
        } else if self.phase == Phase::Retract {
            if self.summary.failure.is_none() {
                self.summary.failure = Some(Failure::Timeout {
                    phase,
                    timeout_s: p.timeout,
                });
            }
            self.enter(Phase::Done, r.t);
        } else {
            self.fail(
                Failure::Timeout {
                    phase,
                    timeout_s: p.timeout,
                },
                r.t,
            );
        }
    }

    /// Travel at the start height to the search start.
    fn travel(&mut self, r: &Reading) {
        let (x, y) = self.task.search_start();
        if self.move_toward([x, y, self.target[2]], self.params.travel_speed) {
            self.enter(Phase::Park, r.t);
        }
    }

    /// A → B: down in z until the reading detects the substrate, then to the parking height; no
    /// substrate within twice the start height fails the run.
    fn park(&mut self, r: &Reading, sig: f64) {
        let p = self.params;
        if sig.abs() > p.substrate_threshold {
            let zs = r.stage[2];
            self.summary.substrate_z = Some(zs);
            self.retract_z = zs + p.start_height;
            let z = zs + self.task.parking_rise();
            self.enter(Phase::ToParkingHeight { z }, r.t);
        } else if self.retract_z - self.target[2] > 2.0 * p.start_height {
            let range_um = (self.retract_z - self.target[2]) * 1e6;
            self.fail(Failure::NoSubstrate { range_um }, r.t);
        } else {
            self.target[2] -= p.approach_speed * p.tick;
        }
    }

    /// B: up to the parking height `z`; a tip the substrate still holds there rises until it lets
    /// go, and one that snaps back after letting go fails the run.
    fn rise_to_parking_height(&mut self, r: &Reading, sig: f64, z: f64) {
        let p = self.params;
        if !self.move_toward([self.target[0], self.target[1], z], p.approach_speed) {
            return;
        }
        let zs = self.summary.substrate_z.unwrap_or(z);
        let held = sig < -p.substrate_threshold;
        if held && self.let_go {
            self.fail(
                Failure::SnappedBack {
                    height_nm: (z - zs) * 1e9,
                },
                r.t,
            );
        } else if held && z > zs {
            self.enter(Phase::LetGo { park_z: z }, r.t);
        } else {
            self.enter(
                Phase::ContactSearch {
                    step: 1,
                    in_step: 0.0,
                    dwell: 0,
                },
                r.t,
            );
        }
    }

    /// B: rise until the substrate lets go of the tip (the reading back within the threshold),
    /// then back down to the parking height; held past the pull-off's rise fails the run.
    fn rise_until_let_go(&mut self, r: &Reading, sig: f64, park_z: f64) {
        let p = self.params;
        let rise = r.stage[2] - self.summary.substrate_z.unwrap_or(park_z);
        if sig >= -p.substrate_threshold {
            self.let_go = true;
            self.enter(Phase::ToParkingHeight { z: park_z }, r.t);
        } else if rise > p.pull_off_rise {
            self.fail(
                Failure::StillHeld {
                    rise_nm: rise * 1e9,
                    bound_nm: p.pull_off_rise * 1e9,
                    phase: "let_go",
                },
                r.t,
            );
        } else {
            self.target[2] += p.approach_speed * p.tick;
        }
    }

    /// D: the stage held still for its ticks, then the back-off.
    fn hold(&mut self, r: &Reading, ticks: u32) {
        if ticks == 0 {
            let goal = self.back_off_goal();
            self.enter(Phase::BackOff { goal }, r.t);
        } else {
            self.phase = Phase::Hold { ticks: ticks - 1 };
        }
    }

    /// D → E: up to the start height (faster after a failure). Still pulled onto the rail there,
    /// something holds the tip: said.
    fn retract(&mut self, r: &Reading, sig: f64) {
        let p = self.params;
        let goal = [self.target[0], self.target[1], self.retract_z.max(self.target[2])];
        let speed = if self.summary.failure.is_some() {
            p.travel_speed.max(p.approach_speed)
        } else {
            p.approach_speed
        };
        if self.move_toward(goal, speed) {
            if r.volts.abs() >= p.full_scale && sig < 0.0 && self.summary.failure.is_none() {
                let zs = self.summary.substrate_z.unwrap_or(goal[2]);
                self.summary.failure = Some(Failure::StillHeld {
                    rise_nm: (r.stage[2] - zs) * 1e9,
                    bound_nm: (goal[2] - zs) * 1e9,
                    phase: "retract",
                });
            }
            self.enter(Phase::Done, r.t);
        }
    }

    /// B → C; `sig` is the contact signal ([`StrategyParams::contact_signal`]).
    fn contact_search(&mut self, r: &Reading, sig: f64, step: u32, in_step: f64, dwell: u32) {
        let p = self.params;
        let set = p.contact_signal(p.set_point);
        // A fast search can step over the whole stick phase between two samples, and the
        // particle then rolls ahead of the tip below the set point: a deflection held above half
        // the set point for three samples is a contact too. So is, in a push without a
        // lost-particle test, one held past half the model's settled reading where that lies
        // past the baseline, beyond 10σ of it: a particle that rolls on in front of the tip
        // bends the lever that way, and may start to before the reading reaches the set point.
        let settled = self.hxy.settled_signal;
        let rolling = p.lost_threshold == 0.0 && settled < -10.0 * p.noise && sig <= 0.5 * settled;
        self.moving_contact = if sig >= 0.5 * set || rolling {
            self.moving_contact + 1
        } else {
            0
        };
        if sig >= set || self.moving_contact >= 3 {
            // C: stop where we are.
            self.summary.contact_step = Some(step);
            self.summary.contact_stage = Some(r.stage);
            self.summary.search.push(SearchStep { step, volts: r.volts });
            self.target = r.stage;
            // The stop's reading is the push's first sample: the peak may be this one.
            self.hxy.update(r.t, sig, 0.0);
            self.enter(Phase::Push { from: r.stage }, r.t);
            return;
        }
        let travelled = (step - 1) as f64 * p.step + in_step;
        if travelled >= p.search_range {
            self.fail(
                Failure::NoContact {
                    travel_um: travelled * 1e6,
                    steps: step,
                },
                r.t,
            );
            return;
        }
        let d = self.task.direction;
        if in_step < p.step {
            let ds = (p.speed * p.tick).min(p.step - in_step);
            self.target[0] += d.0 * ds;
            self.target[1] += d.1 * ds;
            self.target[2] += self.rise(ds);
            self.phase = Phase::ContactSearch {
                step,
                in_step: in_step + ds,
                dwell: 0,
            };
        } else if dwell < p.dwell_ticks {
            self.dwell_sum += r.volts;
            self.phase = Phase::ContactSearch {
                step,
                in_step,
                dwell: dwell + 1,
            };
        } else {
            let volts = if p.dwell_ticks > 0 {
                self.dwell_sum / p.dwell_ticks as f64
            } else {
                r.volts
            };
            self.dwell_sum = 0.0;
            self.summary.search.push(SearchStep { step, volts });
            self.phase = Phase::ContactSearch {
                step: step + 1,
                in_step: 0.0,
                dwell: 0,
            };
        }
    }

    /// How much the substrate rises under the tip over `ds` (m) of travel along the push when
    /// the tip follows its slope, `Δz = (∇z_s · d) ds` with the slope the scan before the push
    /// measured; 0 when it holds its height.
    fn rise(&self, ds: f64) -> f64 {
        if !self.params.follow_slope {
            return 0.0;
        }
        let (d, g) = (self.task.direction, self.task.slope);
        (g.0 * d.0 + g.1 * d.1) * ds
    }

    /// C → D; `sig` is the push-side signal: the estimator and the lost-particle test read the
    /// contact signal, the z loop the deflection itself.
    fn push(&mut self, r: &Reading, sig: f64, from: [f64; 3]) {
        let p = self.params;
        let d = self.task.direction;
        let travel = (r.stage[0] - from[0]) * d.0 + (r.stage[1] - from[1]) * d.1;
        let contact = p.contact_signal(r.volts);
        let est = self.hxy.update(r.t, contact, travel);
        if self.summary.t_star.is_none() {
            self.summary.t_star = self.hxy.detector.peak.map(|(t, _)| t);
        }
        self.summary.estimated_distance = est;
        self.summary.push_travel = travel;
        self.summary.estimated_particle = (self.task.particle.0 + d.0 * est, self.task.particle.1 + d.1 * est);
        // Lost: after the separation the deflection must stay off the baseline (a threshold of 0:
        // no test, the particle rolls ahead with no load on the lever).
        if p.lost_threshold > 0.0 && self.hxy.separated() && contact < p.lost_threshold {
            self.lost_count += 1;
            if self.lost_count >= 5 {
                self.fail(
                    Failure::ParticleLost {
                        travel_um: travel * 1e6,
                    },
                    r.t,
                );
                return;
            }
        } else {
            self.lost_count = 0;
        }
        let z_loop = matches!(p.control, Control::Z | Control::Xyz);
        let xy_loop = matches!(p.control, Control::Xy | Control::Xyz);
        // z-only control has no lateral feedback: it stops on stage travel, planned with the
        // model's retraction drag as the xy loop's stop is (without it a z push ended short by
        // the whole drag, 0.544 µm on gold-latex, and no correction could make that up).
        // Past the leg's end by the retraction's drag, but never off the stage.
        let stop = self.hxy.stop_at(self.task.distance).min(self.task.max_travel);
        let finished = if xy_loop { est >= stop } else { travel >= stop };
        let overshoot = self.task.distance + self.hxy.prediction.settle_offset + 2e-6;
        if !self.hxy.separated() && travel > overshoot {
            self.fail(
                Failure::NoSeparation {
                    travel_um: travel * 1e6,
                },
                r.t,
            );
            return;
        }
        if finished {
            // What the particle will have moved once the tip has retracted (the model's drag).
            let end = if xy_loop { est } else { travel } + self.hxy.prediction.retract_shift;
            self.summary.estimated_distance = end;
            self.summary.estimated_particle = (self.task.particle.0 + d.0 * end, self.task.particle.1 + d.1 * end);
            let hold = (HOLD / p.tick).round() as u32;
            self.enter(Phase::Hold { ticks: hold }, r.t);
            return;
        }
        if let Some((at, ticks)) = self.task.pause
            && travel >= at
            && self.pause_left.is_none()
        {
            self.pause_left = Some(ticks);
        }
        if let Some(left) = self.pause_left
            && left > 0
        {
            self.pause_left = Some(left - 1);
            return;
        }
        self.target[0] += d.0 * p.speed * p.tick;
        self.target[1] += d.1 * p.speed * p.tick;
        self.target[2] += self.rise(p.speed * p.tick);
        if z_loop && self.hxy.separated() {
            // Hold the deflection at its level just after t*. The tip meets the particle above
            // its equator: raising it moves the contact up toward the top, which turns more of
            // the push force into the vertical load that bends the lever (ζ_z grows with β, as
            // Eq 18 and Fig 11 show), so a reading below the reference raises the tip. The law
            // is in the deflection itself (raising the tip raises ζ_z on either side).
            // The reference is the mean of the first 20 samples after t*, past the stage's
            // ringing at the separation.
            let (sum, n) = &mut self.z_hold;
            if *n < Z_REFERENCE_SAMPLES {
                *sum += sig;
                *n += 1;
            } else {
                let reference = *sum / *n as f64;
                self.target[2] -= p.z_gain * (sig - reference);
            }
        }
    }
}
