//! Haptic z-control (Sec 5, Fig 8: "real-time bilateral force feedback control"): the operator's
//! 1-DOF handle sets the tip's height and the hand feels the tip-sample force, scaled.
//!
//! The law, each control tick (SI; `x` the handle position, positive up; `z` the stage height):
//!
//! ```text
//! position:  z_des = z_a + g_p (x − x_a)                       (g_p = 1e-5: 1 mm → 10 nm)
//!            z_ref ← clamp(z_des, z_lo, z_c + h_top), moved at most v_max·T per tick
//! force:     F_tip = k_z ζ_z,  ζ_z = (V − V₀)/G                (Eqs 11-12: the measured deflection,
//!                                                               with the sensor's noise)
//!            F_hand = clamp(r · g_f · (F_tip·[gate open] + F_lim), ±F_dev)
//!                                                  (g_f: the scene's pull-off → 1 N, limited to
//!                                                   the device's renderable region: `coupling`)
//! local model sent with it (rendered by the bridge at its rate between ticks):
//!            dF_hand/dx = −r · g_f · k_z · g_p   while the gate is open (the tip touched,
//!                                                |ζ_z| > ζ_c, within the last 20 ms) or the
//!                                                coupling spring acted (50 ms), else 0; with it
//!                                                the coupling's damper B_c
//! ```
//!
//! `(x_a, z_a)` is the anchor, taken at the engagement and at every clutch release, so the tip
//! never jumps when the hand is re-centred; `z_c` the height at which the surface was detected
//! (the automatic approach below); `ζ_max` the deepest the lever may be pressed (80 % of the
//! deflection at the strategy's safety limit): once `ζ_z ≥ ζ_max` the tip goes no lower (it backs
//! off by the excess), and a hard floor `z_c − ζ_max − 20 nm` backs that up; `F_lim = k_z (z_ref
//! − z_des)` is the coupling spring between the hand and the set-point: a virtual wall
//! continuing the contact's stiffness where a limit holds the tip, so the hand feels the limit
//! instead of a tip that stopped following, and the lag of a set-point moved at its speed limit;
//! `r` the engagement ramp.
//!
//! Engagement, as CHAI3D and OpenHaptics do it: on `engage` the tip approaches the surface at the
//! strategy's approach speed until the reading leaves the baseline (the substrate threshold),
//! rises to `park_gap` above it, and waits until the force the hand would get has stayed below
//! 0.2 N for 3 ticks; then `r` ramps 0 → 1 over 1 s. The same settle and ramp follow a clutch
//! release and a new bridge after a lost link. While a push runs, the strategy owns z and the
//! handle only feels the force; after it, the tip parks again. A lost link (no handle sample for
//! 5 ms, decided by the caller) freezes z and retracts the tip to the parking height.
//!
//! The force is rendered through a virtual coupling sized from the device's renderable region
//! (the contact is never felt stiffer than the device renders passively; a lagging set-point is
//! felt as a spring; the sensor's noise is not rendered): [`coupling`], with the passivity
//! argument. The port's energy is also watched and damped at the bridge, where the force
//! actually rendered is known (`nanopush_haptic::passivity`); a damper held at its cap lowers
//! the force scale (energy bounding).

use nanopush_proto::haptic::{FORCE_CLUTCHED, FORCE_ENGAGED, FORCE_PUSHING, ForceFeedback, HapticState};

pub mod coupling;
pub mod linear_loop;
mod params;
pub use coupling::Coupling;
pub use params::BilateralParams;

pub use nanopush_proto::haptic::{BUTTON_CLUTCH, BUTTON_ENGAGE};
/// Hand force below which the forces may engage (N).
pub const ENGAGE_FORCE: f64 = 0.2;
/// Ticks the force must stay below [`ENGAGE_FORCE`].
pub const ENGAGE_TICKS: u32 = 3;
/// Duration of the force ramp (s).
pub const RAMP: f64 = 1.0;
/// The hard floor below the detected surface beyond the deflection limit (m): a backstop for a
/// reading that never reaches the limit.
pub const FLOOR_MARGIN: f64 = 20e-9;
/// Ticks within the sensor's noise after which the tip force is no longer rendered (the noise
/// gate closes): 20 ms.
pub const GATE_TICKS: u32 = 20;
/// Ticks the coupling spring's stiffness stays in the local model after it last acted.
pub const COUPLED_HOLD: u32 = 50;
/// Half-width of the handle range a local model is sent for (m).
pub const MODEL_HALF_RANGE: f64 = 0.5e-3;

/// Where the haptic z-control is.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Phase {
    /// Not engaged: z is not the hand's; no force.
    Off,
    /// Looking for the surface below the tip.
    Approach,
    /// Rising to the parking height above the surface.
    Park,
    /// Parked; waiting for the force to stay small before engaging.
    Settle {
        /// Consecutive ticks with a small force.
        small: u32,
    },
    /// The hand moves the tip; the force ramps in.
    Ramp {
        /// Ramp 0..1.
        gain: f64,
    },
    /// The hand moves the tip with full force feedback.
    Engaged,
    /// The clutch is in: the tip holds, the hand re-centres, no force.
    Clutched,
    /// A push runs: the strategy owns z; the hand feels the force.
    Pushing,
    /// The link went down: the tip retracts to the parking height.
    LinkLost,
    /// Released: the tip goes back to the parking height, then off.
    Retract,
}

impl Phase {
    /// Name for status and telemetry.
    pub fn name(&self) -> &'static str {
        match self {
            Phase::Off => "off",
            Phase::Approach => "approach",
            Phase::Park => "park",
            Phase::Settle { .. } => "settle",
            Phase::Ramp { .. } => "ramp",
            Phase::Engaged => "engaged",
            Phase::Clutched => "clutched",
            Phase::Pushing => "pushing",
            Phase::LinkLost => "link_lost",
            Phase::Retract => "retract",
        }
    }
}

/// Why an approach ended without a surface.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Fault {
    /// No surface within the search depth.
    NoSurface,
}

/// What the law needs each tick.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Input {
    /// The newest handle sample, `None` while the link is down.
    pub handle: Option<HapticState>,
    /// The stage position now (m).
    pub stage: [f64; 3],
    /// The deflection reading now (V).
    pub volts: f64,
    /// A push runs (the strategy owns z).
    pub pushing: bool,
}

/// What the law decides each tick.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Output {
    /// The stage target while the haptic control owns the tip; `None` otherwise.
    pub target: Option<[f64; 3]>,
    /// The force message for the bridge (without `seq`/`time_ns`).
    pub feedback: ForceFeedback,
}

/// The haptic z-control's state.
#[derive(Debug, Clone, PartialEq)]
pub struct Bilateral {
    /// Settings (the scales may change at run time).
    pub params: BilateralParams,
    phase: Phase,
    /// Stage height at which the surface was detected (m).
    contact_z: Option<f64>,
    /// Where the approach started (m).
    approach_from: f64,
    /// Stage xy held while the hand owns z.
    xy: [f64; 2],
    /// Anchor: handle position and stage height.
    anchor: (f64, f64),
    /// The height commanded (m).
    z_ref: f64,
    /// The last fault.
    fault: Option<Fault>,
    /// The engage button's previous state (edges toggle the engagement).
    button_prev: bool,
    /// The height at which the lever reached its deflection limit, while the hand presses on.
    force_floor: Option<f64>,
    /// Ticks since the coupling spring last acted (the local model's stiffness stays on for
    /// [`COUPLED_HOLD`] ticks after it, so a set-point that lags on and off is felt as one
    /// spring, not as a force switched on and off).
    since_coupled: u32,
    /// Consecutive ticks the deflection has stayed within the sensor's noise (`|ζ| ≤ ζ_c`): the
    /// tip force is rendered until [`GATE_TICKS`] of them (a contact's force crosses zero in a
    /// tick or two without a gap; free space is quiet from then on).
    quiet: u32,
    /// The phase a running push interrupted (the hand gets the tip back after it only if it had
    /// it before).
    before_push: Phase,
    /// The force ramp during a push (0..1).
    push_gain: f64,
    /// The renderable region, the coupling and energy bounding.
    coupling: Coupling,
}

impl Bilateral {
    /// Off, with `params`.
    pub fn new(params: BilateralParams) -> Bilateral {
        Bilateral {
            params,
            phase: Phase::Off,
            contact_z: None,
            approach_from: 0.0,
            xy: [0.0; 2],
            anchor: (0.0, 0.0),
            z_ref: 0.0,
            fault: None,
            button_prev: false,
            force_floor: None,
            since_coupled: u32::MAX,
            quiet: u32::MAX,
            before_push: Phase::Off,
            push_gain: 0.0,
            coupling: Coupling::new(params.tick),
        }
    }

    /// Where it is.
    pub fn phase(&self) -> Phase {
        self.phase
    }

    /// Whether the hand owns (or will own) the tip: engaged in any way but off.
    pub fn engaged(&self) -> bool {
        self.phase != Phase::Off
    }

    /// The renderable region and the coupling in force.
    pub fn coupling(&self) -> &Coupling {
        &self.coupling
    }

    /// The last fault, if any.
    pub fn fault(&self) -> Option<Fault> {
        self.fault
    }

    /// The detected surface height (m).
    pub fn contact_z(&self) -> Option<f64> {
        self.contact_z
    }

    /// Engages: approach, park, settle, ramp. The tip holds its xy at `stage`.
    pub fn engage(&mut self, stage: [f64; 3]) {
        if self.phase != Phase::Off {
            return;
        }
        self.xy = [stage[0], stage[1]];
        self.z_ref = stage[2];
        self.approach_from = stage[2];
        self.fault = None;
        self.force_floor = None;
        self.coupling.reset_bound();
        self.phase = Phase::Approach;
    }

    /// Releases: the tip goes back to the parking height (when a surface is known) and the
    /// handle is let go.
    pub fn release(&mut self) {
        self.phase = match self.phase {
            Phase::Off | Phase::Pushing | Phase::Approach => Phase::Off,
            _ => Phase::Retract,
        };
    }

    /// Re-centres: the anchor moves to the handle's position now, so the tip stays where it is
    /// and the hand has its travel again (the one-shot form of the clutch).
    pub fn recenter(&mut self, handle: f64) {
        self.anchor = (handle, self.z_ref);
    }

    /// New scales (each only when given). While the hand owns the tip the anchor moves to the
    /// handle's position now (the tip does not jump) and the force ramps in again from zero, as
    /// after a clutch: a scale is never applied to the hand in one step.
    pub fn rescale(&mut self, position_gain: Option<f64>, force_gain: Option<f64>, handle: Option<f64>) {
        if let Some(g) = position_gain {
            self.params.position_gain = g;
        }
        if let Some(g) = force_gain {
            self.params.force_gain = g;
        }
        self.coupling.reset_bound();
        if matches!(self.phase, Phase::Ramp { .. } | Phase::Engaged | Phase::Clutched) {
            if let Some(x) = handle.filter(|x| x.is_finite()) {
                self.anchor = (x, self.z_ref);
            }
            if self.phase != Phase::Clutched {
                self.phase = Phase::Ramp { gain: 0.0 };
            }
        }
    }

    /// The link to the hand is lost (or a new bridge replaced it): as when no sample arrives.
    /// A new bridge may hold another device: energy bounding starts over.
    pub fn link_lost(&mut self) {
        self.coupling.reset_bound();
        if matches!(
            self.phase,
            Phase::Settle { .. } | Phase::Ramp { .. } | Phase::Engaged | Phase::Clutched
        ) {
            self.phase = Phase::LinkLost;
        }
    }

    fn deflection(&self, volts: f64) -> f64 {
        (volts - self.params.baseline) / self.params.sensor_gain
    }

    fn park_height(&self) -> Option<f64> {
        self.contact_z.map(|z| z + self.params.park_gap)
    }

    /// Moves `z_ref` toward `to` at most `speed·tick`.
    fn slew(&mut self, to: f64, speed: f64) -> bool {
        let step = speed * self.params.tick;
        let d = (to - self.z_ref).clamp(-step, step);
        self.z_ref += d;
        (to - self.z_ref).abs() < 1e-15
    }

    /// One control tick: the engage button, a push taking z or giving it back, the link's
    /// loss, then the phase's step (`step_phase`), the force's gain (`gain_and_flags`), and the
    /// force and local model sent to the hand.
    pub fn tick(&mut self, input: &Input) -> Output {
        let p = self.params;
        let was = self.phase;
        let zeta = self.deflection(input.volts);
        let tip_force = p.k_z * zeta;
        let max_force = input.handle.map_or(0.0, |h| h.max_force.max(0.0));
        let handle = input.handle;
        self.on_button(input);
        self.on_push(input);
        // The link went down while the hand moved the tip.
        if handle.is_none()
            && matches!(
                self.phase,
                Phase::Ramp { .. } | Phase::Engaged | Phase::Clutched | Phase::Settle { .. }
            )
        {
            self.phase = Phase::LinkLost;
        }

        let limit_force = self.step_phase(input, tip_force, zeta);
        let (gain, flags) = self.gain_and_flags(handle.is_some());
        let touching = zeta.abs() > p.contact_deflection;
        let force_gain = self.coupling.update(&p, handle.as_ref(), gain > 0.0);
        // The tip force beyond the sensor's noise, and the coupling spring (see `coupling`).
        self.quiet = if touching { 0 } else { self.quiet.saturating_add(1) };
        let rendered = if self.quiet < GATE_TICKS { tip_force } else { 0.0 } + limit_force;
        let force = (gain * force_gain * rendered).clamp(-max_force, max_force);
        // A retraction that ends this tick still moves the tip there.
        let owns_z = !matches!(self.phase, Phase::Off | Phase::Pushing) || was == Phase::Retract;
        self.since_coupled = if limit_force != 0.0 {
            0
        } else {
            self.since_coupled.saturating_add(1)
        };
        // The local model's stiffness (and the coupling damper with it) is whole while the tip
        // touches or the coupling spring acts, and fades out over the gate's 20 ms and the
        // coupling's 50 ms after: a contact crossing zero keeps it, free space loses it without a
        // step (and without dragging a hand that flies off at the pull-off).
        let fade = |since: u32, over: u32| 1.0 - f64::from(since.min(over)) / f64::from(over);
        let share = fade(self.quiet, GATE_TICKS).max(fade(self.since_coupled, COUPLED_HOLD));
        let stiffness = if self.phase != Phase::Pushing {
            -gain * force_gain * p.k_z * p.position_gain * share
        } else {
            0.0
        };
        Output {
            target: owns_z.then_some([self.xy[0], self.xy[1], self.z_ref]),
            feedback: ForceFeedback {
                seq: 0,
                time_ns: 0,
                state_seq: handle.map_or(u64::MAX, |h| h.seq),
                force,
                stiffness,
                anchor: handle.map_or(0.0, |h| h.position),
                half_range: MODEL_HALF_RANGE,
                tip_force,
                tip_z: self.contact_z.map_or(f64::NAN, |zc| input.stage[2] - zc),
                gain,
                active: u32::from(gain > 0.0 && handle.is_some()),
                flags,
                damping: if stiffness < 0.0 {
                    gain * self.coupling.damping() * share
                } else {
                    0.0
                },
            },
        }
    }

    /// The engage button toggles the engagement (a rising edge).
    fn on_button(&mut self, input: &Input) {
        let button = input.handle.is_some_and(|h| h.buttons & BUTTON_ENGAGE != 0);
        if button && !self.button_prev {
            if self.phase == Phase::Off {
                self.engage(input.stage);
            } else {
                self.release();
            }
        }
        self.button_prev = button;
    }

    /// A push owns z: the hand only feels (the force ramps in from zero). After it the hand
    /// gets the tip back only if it had it before.
    fn on_push(&mut self, input: &Input) {
        if input.pushing && !matches!(self.phase, Phase::Off | Phase::Pushing) {
            self.before_push = self.phase;
            self.push_gain = 0.0;
            self.phase = Phase::Pushing;
        } else if !input.pushing && self.phase == Phase::Pushing {
            let resume = matches!(
                self.before_push,
                Phase::Approach
                    | Phase::Park
                    | Phase::Settle { .. }
                    | Phase::Ramp { .. }
                    | Phase::Engaged
                    | Phase::Clutched
            );
            self.phase = Phase::Off;
            if resume {
                self.engage(input.stage);
            }
        }
    }

    /// The phase's step this tick (approach, park, settle, retract, or the hand moving the
    /// tip). Returns the virtual wall's force at the handle's range limit (N, tip side).
    fn step_phase(&mut self, input: &Input, tip_force: f64, zeta: f64) -> f64 {
        let p = self.params;
        let handle = input.handle;
        let mut limit_force = 0.0;
        match self.phase {
            Phase::Off | Phase::Pushing => {}
            Phase::Approach => {
                let met = (input.volts - p.baseline).abs() > p.substrate_threshold;
                if met {
                    self.contact_z = Some(input.stage[2]);
                    self.phase = Phase::Park;
                } else if self.approach_from - self.z_ref > p.search_depth {
                    // Nothing within reach: back up to where the approach started, then off.
                    self.fault = Some(Fault::NoSurface);
                    self.phase = Phase::Retract;
                } else {
                    self.slew(f64::NEG_INFINITY, p.approach_speed);
                }
            }
            Phase::Park => {
                let park = self.park_height().unwrap_or(self.approach_from);
                if self.slew(park, p.approach_speed) {
                    self.phase = Phase::Settle { small: 0 };
                }
            }
            Phase::LinkLost | Phase::Retract => {
                // Up to the parking height (where the approach started when no surface was
                // found), never down; then wait for the link, or stop.
                let goal = self.park_height().unwrap_or(self.approach_from);
                let parked = self.slew(self.z_ref.max(goal), p.approach_speed);
                if parked && self.phase == Phase::Retract {
                    self.phase = Phase::Off;
                } else if parked && handle.is_some() {
                    self.phase = Phase::Settle { small: 0 };
                }
            }
            Phase::Settle { small } => {
                // The force the hand would get: the force scale in force (the one asked before a
                // device is known), nothing within the sensor's noise.
                let g = if self.coupling.k_max() > 0.0 {
                    self.coupling.force_gain()
                } else {
                    p.force_gain
                };
                let hand = if zeta.abs() > p.contact_deflection {
                    (g * tip_force).abs()
                } else {
                    0.0
                };
                let small = if hand < ENGAGE_FORCE { small + 1 } else { 0 };
                self.phase = Phase::Settle { small };
                if small >= ENGAGE_TICKS
                    && let Some(h) = handle
                {
                    self.anchor = (h.position, self.z_ref);
                    self.phase = Phase::Ramp { gain: 0.0 };
                }
            }
            Phase::Ramp { .. } | Phase::Engaged | Phase::Clutched => {
                // The link is up here: a lost link moved these phases to LinkLost above.
                if let Some(h) = handle {
                    limit_force = self.follow(&h, zeta);
                }
            }
        }
        limit_force
    }

    /// The force's gain (ramping in after engagement and during a push) and the flags the hand
    /// is told, for the phase now.
    fn gain_and_flags(&mut self, linked: bool) -> (f64, u32) {
        let p = self.params;
        let mut gain = 0.0;
        let mut flags = 0;
        match self.phase {
            Phase::Ramp { gain: g } => {
                gain = g;
                flags |= FORCE_ENGAGED;
            }
            Phase::Engaged => {
                gain = 1.0;
                flags |= FORCE_ENGAGED;
            }
            Phase::Clutched => flags |= FORCE_ENGAGED | FORCE_CLUTCHED,
            Phase::Pushing => {
                if linked {
                    self.push_gain = (self.push_gain + p.tick / RAMP).min(1.0);
                } else {
                    self.push_gain = 0.0;
                }
                gain = self.push_gain;
                flags |= FORCE_PUSHING;
            }
            _ => {}
        }
        (gain, flags)
    }

    /// The hand moves the tip (ramp, engaged, clutch); returns the coupling spring's force
    /// `k_z (z_ref − z_des)` (N, tip side): the wall at a limit, the lag at the speed limit.
    fn follow(&mut self, h: &HapticState, zeta: f64) -> f64 {
        let p = self.params;
        let clutch = h.buttons & BUTTON_CLUTCH != 0;
        if clutch {
            self.phase = Phase::Clutched;
        } else if self.phase == Phase::Clutched {
            // Released: re-anchor where the hand is, ramp the force in again.
            self.anchor = (h.position, self.z_ref);
            self.phase = Phase::Ramp { gain: 0.0 };
        }
        if let Phase::Ramp { gain: g } = self.phase {
            let g = (g + p.tick / RAMP).min(1.0);
            self.phase = if g >= 1.0 {
                Phase::Engaged
            } else {
                Phase::Ramp { gain: g }
            };
        }
        if self.phase == Phase::Clutched {
            return 0.0;
        }
        let z_des = self.anchor.1 + p.position_gain * (h.position - self.anchor.0);
        let (mut lo, hi) = match self.contact_z {
            Some(zc) => (zc - p.max_indent - FLOOR_MARGIN, zc + p.max_height),
            None => (f64::NEG_INFINITY, f64::INFINITY),
        };
        // The force limit: once the lever is bent to the limit, the height where it was reached
        // becomes a floor (backed off by any excess), held until the hand comes back above it.
        if zeta >= p.max_indent {
            let at = self.z_ref + (zeta - p.max_indent);
            self.force_floor = Some(self.force_floor.map_or(at, |f| f.max(at)));
        }
        if let Some(f) = self.force_floor {
            if z_des > f {
                self.force_floor = None;
            } else {
                lo = lo.max(f);
            }
        }
        // When the force floor has risen above the top limit, the floor (up, away from the
        // surface) wins.
        self.slew(z_des.min(hi).max(lo), p.max_speed);
        // The coupling spring: the set-point's lag behind the hand (a limit holding it is a
        // virtual wall continuing the contact's stiffness).
        p.k_z * (self.z_ref - z_des)
    }
}

#[cfg(test)]
mod tests;
