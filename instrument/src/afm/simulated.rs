//! The simulated AFM: the hidden truth behind the instrument. It owns the stage, the tip over
//! the substrate and the particles, and answers each control tick with what the real instrument
//! would measure — the deflection reading in volts and the stage position — and nothing else.
//!
//! Free of particles the tip follows the tip-substrate force curve (Fig 3,
//! [`TipSample::track`]). When the tip's sphere touches a particle the Eq 17 pushing model takes
//! over in the frame of the push (Sec 2.5): its `y` axis is the stage's direction of travel at the
//! moment of contact, the contact angle `β` is the one the geometry gives there, and each tick
//! drives the model with the stage's travel along that axis and the tip base's height over the
//! substrate under the particle (so tilt and roughness change `β` as the particle moves, Fig 15).
//! The contact ends when the tip lets go of the particle (JKR pull-off, meniscus rupture, or a
//! gap that opened by more than [`RELEASE_GAP`]).
//!
//! Simplifications, stated: the push is one-dimensional along the direction of travel (the
//! lateral instability of pushing a sphere off-centre is left out); outside a push the stage
//! follows its command exactly (Eq 13 acts inside the push model, where its load matters).

use crate::numerics::integrate::{Method, Options};
use crate::physics::force_curve::{TipSample, TipTrack};
pub use crate::physics::pushing::RELEASE_GAP;
use crate::physics::pushing::{Advance, Drive, PushModel, PushParams, Simulation, SimulationError};
use crate::physics::sensor::Readout;
use crate::physics::topography::Topography;

/// Contact angles the pushing model accepts (rad): the tip must meet the particle above its
/// equator and below its top.
const BETA_RANGE: (f64, f64) = (1.0 * std::f64::consts::PI / 180.0, 85.0 * std::f64::consts::PI / 180.0);

/// A particle lying on the substrate (SI).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Particle {
    /// Identifier (from the scene).
    pub id: u32,
    /// Centre x (m).
    pub x: f64,
    /// Centre y (m).
    pub y: f64,
    /// Radius (m).
    pub radius: f64,
}

/// What the instrument measures at the end of a tick.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Reading {
    /// Time (s).
    pub t: f64,
    /// Deflection reading (V): the only force measurement (Sec 4).
    pub volts: f64,
    /// Stage position: tip apex x, y and the height of the undeflected apex (m), from the
    /// closed-loop stage's own sensors.
    pub stage: [f64; 3],
}

/// Hidden state, for traces and tests only: the controller never sees it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Truth {
    /// Deflection `ζ_z` (m).
    pub zeta_z: f64,
    /// The particle being pushed, if any.
    pub pushing: Option<u32>,
    /// Friction phase of the push (`stick`, `slip`, `roll`) or `free`.
    pub phase: &'static str,
    /// Tip touching the substrate.
    pub on_substrate: bool,
}

/// Why the simulated instrument could not go on.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum AfmError {
    /// A command was not finite.
    #[error("stage command {0:?} is not finite")]
    NotFinite([f64; 3]),
    /// The pushing model failed.
    #[error("push simulation of particle {id} failed at t = {t:.6} s: {cause} ({fields})", fields = crate::physics::pushing::MODEL_FIELDS)]
    Push {
        /// Particle.
        id: u32,
        /// Time (s).
        t: f64,
        /// Why (in the message, not a `source`: printed once).
        cause: SimulationError,
    },
}

/// A solver-health guard that tripped: the push model's state left physics. The instrument
/// then drops the push model and leaves the particle where it last was physical.
///
/// The bounds, checked every tick of a push:
/// - every state of the model finite;
/// - the particle's centre inside the stage's travel widened by a margin of
///   `max(10 Rₐ, 1 µm)` on each side;
/// - the particle's displacement in one tick at most the stage's travel in that tick plus
///   `Rₐ + Rₜ` (a pushed particle moves with the tip: it cannot outrun it by more than the
///   contact's size in one tick, whatever the elastic release); the stage's travel is the
///   commanded one or, when larger, three ticks at the scene's fastest stage speed (a dynamic
///   stage, Eq 13, lags its command and catches up after it stops);
/// - the deflection `ζ_z` finite.
///
/// The readout's own limit (the ADC saturating at its full scale) is the strategy's to act on.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Unphysical {
    /// What was out of bounds.
    pub what: &'static str,
    /// Its value (SI; NaN for a non-finite state).
    pub value: f64,
    /// The bound (SI).
    pub limit: f64,
}

impl Unphysical {
    /// Checks one tick of a push: the particle moved from `before` to `after` (m) while the
    /// stage travelled `stage_travel` (m) in the plane; `states` is the model's state, `zeta_z`
    /// the deflection; `radii` the particle's and the tip's; `range` the stage's travel.
    pub fn check(
        states: &[f64],
        zeta_z: f64,
        before: (f64, f64),
        after: (f64, f64),
        stage_travel: f64,
        radii: (f64, f64),
        range: f64,
    ) -> Option<Unphysical> {
        if let Some(v) = states.iter().chain([&zeta_z]).find(|v| !v.is_finite()) {
            return Some(Unphysical {
                what: "push model state",
                value: *v,
                limit: f64::MAX,
            });
        }
        let margin = (10.0 * radii.0).max(1e-6);
        for (what, v) in [("particle x (m)", after.0), ("particle y (m)", after.1)] {
            if v < -margin || v > range + margin {
                return Some(Unphysical {
                    what,
                    value: v,
                    limit: if v < 0.0 { -margin } else { range + margin },
                });
            }
        }
        let moved = (after.0 - before.0).hypot(after.1 - before.1);
        let limit = stage_travel + radii.0 + radii.1;
        (moved > limit).then_some(Unphysical {
            what: "particle displacement in one tick (m)",
            value: moved,
            limit,
        })
    }
}

/// A push in progress: the Eq 17 model in the frame of the push.
#[derive(Debug, Clone)]
struct Contact {
    sim: Simulation,
    index: usize,
    /// Unit push direction in the plane.
    dir: (f64, f64),
    /// Stage xy at the moment of contact.
    stage0: (f64, f64),
    /// Stage z at contact.
    z0: f64,
    /// Particle centre at contact.
    particle0: (f64, f64),
    /// Substrate height under the particle at contact.
    zs0: f64,
}

/// The simulated instrument.
#[derive(Debug, Clone)]
pub struct Afm {
    tip: TipSample,
    readout: Readout,
    topography: Topography,
    particles: Vec<Particle>,
    params: Vec<PushParams>,
    method: Method,
    options: Options,
    stage: [f64; 3],
    range: f64,
    t: f64,
    tick: f64,
    free: TipTrack,
    zeta_z: f64,
    contact: Option<Contact>,
    r_t: f64,
    fault: Option<Unphysical>,
    speed_bound: f64,
}

impl Afm {
    /// An instrument with its tip at `stage` (m), one tick of `tick` seconds, particles with the
    /// pushing parameters of each (same order), a stage range `[0, range]` in x and y.
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        tip: TipSample,
        readout: Readout,
        topography: Topography,
        particles: Vec<(Particle, PushParams)>,
        stage: [f64; 3],
        range: f64,
        tick: f64,
    ) -> Afm {
        let (particles, params) = particles.into_iter().unzip();
        let mut afm = Afm {
            r_t: tip.r_t,
            tip,
            readout,
            topography,
            particles,
            params,
            method: Method::Rodas4,
            options: Options::with_rtol(1e-6),
            stage,
            range,
            t: 0.0,
            tick,
            free: TipTrack::far(1.0),
            zeta_z: 0.0,
            contact: None,
            fault: None,
            speed_bound: 0.0,
        };
        let d = afm.piezo_distance();
        afm.free = TipTrack::far(d);
        afm.zeta_z = afm.tip.track(&mut afm.free, d).deflection;
        afm
    }

    /// The particles where they are now.
    pub fn particles(&self) -> &[Particle] {
        &self.particles
    }

    /// The substrate's topography.
    pub fn topography(&self) -> &Topography {
        &self.topography
    }

    /// The stage's travel: `[0, range]` in x and y (m).
    pub fn range(&self) -> f64 {
        self.range
    }

    /// The tick (s).
    pub fn tick(&self) -> f64 {
        self.tick
    }

    /// The stage position now (m).
    pub fn stage(&self) -> [f64; 3] {
        self.stage
    }

    /// Time now (s).
    pub fn time(&self) -> f64 {
        self.t
    }

    /// The fastest the stage is ever commanded to move (m/s), for the guard's displacement bound
    /// (see [`Unphysical`]).
    pub fn set_speed_bound(&mut self, speed: f64) {
        self.speed_bound = speed;
    }

    /// The fastest the stage is ever commanded to move (m/s), as set.
    pub fn speed_bound(&self) -> f64 {
        self.speed_bound
    }

    /// The guard that tripped since the last call, if any (see [`Unphysical`]): the caller
    /// ends the push with it.
    pub fn take_fault(&mut self) -> Option<Unphysical> {
        self.fault.take()
    }

    /// The hidden state now.
    pub fn truth(&self) -> Truth {
        Truth {
            zeta_z: self.zeta_z,
            pushing: self.contact.as_ref().map(|c| self.particles[c.index].id),
            phase: self.contact.as_ref().map_or("free", |c| c.sim.phase().as_str()),
            on_substrate: self.contact.is_none() && self.free.in_contact(),
        }
    }

    /// A reading of the instrument now (noise drawn anew).
    pub fn read(&mut self) -> Reading {
        Reading {
            t: self.t,
            volts: self.readout.read(self.t, self.zeta_z),
            stage: self.stage,
        }
    }

    fn piezo_distance(&self) -> f64 {
        self.stage[2] - self.topography.height(self.stage[0], self.stage[1])
    }

    /// Advances one tick with the stage moving in a straight line to `target` (m), clamped to
    /// the stage's range, and returns the reading at the end of the tick.
    pub fn step(&mut self, target: [f64; 3]) -> Result<Reading, AfmError> {
        if target.iter().any(|v| !v.is_finite()) {
            return Err(AfmError::NotFinite(target));
        }
        let target = [
            target[0].clamp(0.0, self.range),
            target[1].clamp(0.0, self.range),
            target[2],
        ];
        let t1 = self.t + self.tick;
        if self.contact.is_none() {
            self.find_contact(target);
        }
        match self.contact.take() {
            Some(c) => self.step_contact(c, target, t1)?,
            None => {
                self.stage = target;
                self.t = t1;
                let d = self.piezo_distance();
                self.zeta_z = self.tip.track(&mut self.free, d).deflection;
            }
        }
        Ok(self.read())
    }

    /// Whether the tip's sphere meets a particle on the way to `target`; if so, starts the push
    /// model at the first touch (found by bisection along the path) with the contact angle the
    /// geometry gives there.
    fn find_contact(&mut self, target: [f64; 3]) {
        let from = self.stage;
        let at = |s: f64| -> [f64; 3] { std::array::from_fn(|i| from[i] + s * (target[i] - from[i])) };
        let mut best: Option<(f64, usize)> = None;
        for (i, p) in self.particles.iter().enumerate() {
            let gap = |q: [f64; 3]| self.sphere_gap(q, p);
            if gap(target) > 0.0 {
                continue;
            }
            let (mut lo, mut hi) = (0.0, 1.0);
            if gap(from) <= 0.0 {
                hi = 0.0;
            } else {
                for _ in 0..60 {
                    let mid = 0.5 * (lo + hi);
                    if gap(at(mid)) > 0.0 {
                        lo = mid;
                    } else {
                        hi = mid;
                    }
                }
            }
            if best.is_none_or(|(s, _)| hi < s) {
                best = Some((hi, i));
            }
        }
        let Some((s, index)) = best else { return };
        let touch = at(s);
        let p = self.particles[index];
        // Direction of travel in the plane; a purely vertical move meets the particle from above
        // (the push frame then points from the tip to the particle centre).
        let (mut dx, mut dy) = (target[0] - from[0], target[1] - from[1]);
        let mut len = dx.hypot(dy);
        if len < 1e-15 {
            (dx, dy) = (p.x - touch[0], p.y - touch[1]);
            len = dx.hypot(dy).max(1e-15);
        }
        let dir = (dx / len, dy / len);
        let zs = self.topography.height(p.x, p.y);
        let rise = (touch[2] + self.r_t) - (zs + p.radius);
        let beta = (rise / (self.r_t + p.radius))
            .clamp(-1.0, 1.0)
            .asin()
            .clamp(BETA_RANGE.0, BETA_RANGE.1);
        let mut params = self.params[index];
        params.beta = beta;
        let mut model = PushModel::new(params);
        model.drive = Drive {
            t0: self.t,
            y0: 0.0,
            vy: 0.0,
            z0: 0.0,
            vz: 0.0,
        };
        let mut sim = Simulation::new(model, self.method, self.options);
        sim.t = self.t;
        self.contact = Some(Contact {
            sim,
            index,
            dir,
            stage0: (touch[0], touch[1]),
            z0: touch[2],
            particle0: (p.x, p.y),
            zs0: zs,
        });
    }

    /// Gap between the tip's sphere (undeflected) at stage position `q` and particle `p` (m).
    fn sphere_gap(&self, q: [f64; 3], p: &Particle) -> f64 {
        let zs = self.topography.height(p.x, p.y);
        let dz = (q[2] + self.r_t) - (zs + p.radius);
        ((q[0] - p.x).powi(2) + (q[1] - p.y).powi(2) + dz * dz).sqrt() - (self.r_t + p.radius)
    }

    fn step_contact(&mut self, mut c: Contact, target: [f64; 3], t1: f64) -> Result<(), AfmError> {
        let travel = (target[0] - c.stage0.0) * c.dir.0 + (target[1] - c.stage0.1) * c.dir.1;
        let y_now = c.sim.x[c.sim.model.layout.particle_y.pos];
        let (px, py) = (c.particle0.0 + c.dir.0 * y_now, c.particle0.1 + c.dir.1 * y_now);
        let lift = (target[2] - c.z0) - (self.topography.height(px, py) - c.zs0);
        let drive = c.sim.model.drive.ramp_to(self.t, t1, travel, lift);
        c.sim.set_drive(drive);
        let id = self.particles[c.index].id;
        let advance = c
            .sim
            .advance_or_release(t1)
            .map_err(|cause| AfmError::Push { id, t: self.t, cause })?;
        let n = c.sim.model.len();
        let probe = c.sim.model.probe(c.sim.t, &c.sim.x[..n], &c.sim.mode);
        // The particle stays where the push model leaves it (at a pull-off: where the balance
        // vanished).
        let y = c.sim.x[c.sim.model.layout.particle_y.pos];
        let after = (c.particle0.0 + c.dir.0 * y, c.particle0.1 + c.dir.1 * y);
        let p = self.particles[c.index];
        let stage_travel = self.guard_travel(target);
        let states = &c.sim.x[..n];
        if let Some(u) = Unphysical::check(
            states,
            probe.zeta_z,
            (p.x, p.y),
            after,
            stage_travel,
            (p.radius, self.r_t),
            self.range,
        ) {
            // The model left physics: drop it; the particle stays where it last was physical.
            self.fault = Some(u);
            self.release(target, t1);
            return Ok(());
        }
        let p = &mut self.particles[c.index];
        (p.x, p.y) = after;
        self.stage = target;
        self.t = t1;
        self.zeta_z = probe.zeta_z;
        if advance == Advance::Released {
            self.release(target, t1);
        } else {
            self.contact = Some(c);
        }
        Ok(())
    }

    /// The stage's travel the guard allows for in a tick to `target` (m): the commanded one or,
    /// when larger, three ticks at the fastest stage speed (see [`Unphysical`]).
    fn guard_travel(&self, target: [f64; 3]) -> f64 {
        (target[0] - self.stage[0])
            .hypot(target[1] - self.stage[1])
            .max(3.0 * self.speed_bound * self.tick)
    }

    /// Ends a push: the particle stays where it is, the tip is free at `target`.
    fn release(&mut self, target: [f64; 3], t1: f64) {
        self.contact = None;
        self.stage = target;
        self.t = t1;
        let d = self.piezo_distance();
        self.free = TipTrack::far(d.max(self.tip.a0 * 10.0));
        self.zeta_z = self.tip.track(&mut self.free, d).deflection;
    }
}

#[cfg(test)]
mod tests {
    use super::Unphysical;
    use crate::scene::Scene;

    const R: (f64, f64) = (1e-6, 30e-9);

    #[test]
    fn the_guard_passes_a_push_and_trips_on_each_bound() {
        let states = [1e-9, 2e-9, 3e-9];
        let ok = Unphysical::check(&states, 1e-9, (50e-6, 50e-6), (50.001e-6, 50e-6), 1e-9, R, 100e-6);
        assert_eq!(ok, None);
        // 38.6 mm in one tick: a contact broken by a far Newton root.
        let jump =
            Unphysical::check(&states, 1e-9, (49.8e-6, 50e-6), (38.648e-3, 50e-6), 1e-9, R, 100e-6).expect("trips");
        assert!(jump.what.starts_with("particle x"), "outside the stage first: {jump:?}");
        // Inside the stage but faster than the tip: more than Rₐ + Rₜ beyond the stage's travel.
        let fast = Unphysical::check(&states, 1e-9, (50e-6, 50e-6), (52e-6, 50e-6), 1e-9, R, 100e-6).expect("trips");
        assert_eq!(fast.what, "particle displacement in one tick (m)");
        assert!((fast.limit - (1e-9 + 1.03e-6)).abs() < 1e-15);
        // The stage's own travel is allowed for.
        assert_eq!(
            Unphysical::check(&states, 1e-9, (50e-6, 50e-6), (52e-6, 50e-6), 1.5e-6, R, 100e-6),
            None
        );
        // A margin of max(10 Rₐ, 1 µm) beyond the stage's range.
        assert_eq!(
            Unphysical::check(&states, 0.0, (0.5e-6, 1e-6), (-9e-6, 1e-6), 10e-6, R, 100e-6),
            None
        );
        let out = Unphysical::check(&states, 0.0, (0.5e-6, 1e-6), (-10.5e-6, 1e-6), 11e-6, R, 100e-6).unwrap();
        assert_eq!(out.what, "particle x (m)");
        assert!((out.limit + 10e-6).abs() < 1e-18, "{out:?}");
        // The margin's 1 µm floor: 10 Rₐ of a 50 nm particle would be 0.5 µm.
        let small = (50e-9, 30e-9);
        assert_eq!(
            Unphysical::check(&states, 0.0, (0.5e-6, 1e-6), (-0.9e-6, 1e-6), 2e-6, small, 100e-6),
            None
        );
        let out = Unphysical::check(&states, 0.0, (0.5e-6, 1e-6), (-1.1e-6, 1e-6), 2e-6, small, 100e-6).unwrap();
        assert_eq!((out.what, out.limit), ("particle x (m)", -1e-6));
        // Non-finite states and deflection.
        let nan = Unphysical::check(&[1.0, f64::NAN], 0.0, (0.0, 0.0), (0.0, 0.0), 0.0, R, 100e-6).unwrap();
        assert_eq!(nan.what, "push model state");
        assert!(Unphysical::check(&states, f64::INFINITY, (0.0, 0.0), (0.0, 0.0), 0.0, R, 100e-6).is_some());
    }

    /// docs/manipulation.md's guard ("Physics guarded every tick"): the particle may move, in one
    /// tick, the stage's travel plus `Rₐ + Rₜ`, the travel being the command or, when larger, three
    /// ticks at the scene's fastest speed (a dynamic stage lags its command and catches up after it
    /// stops). The paper scene's fastest is its 10 µm/s travel: 30 nm in three 1 ms ticks.
    #[test]
    fn the_guard_allows_the_commanded_travel_or_three_ticks_at_top_speed() {
        let s = Scene::default_scene();
        let st = &s.file.strategy;
        assert_eq!(
            (
                st.travel_speed_um_per_s,
                st.approach_speed_um_per_s,
                s.file.push.speed_um_per_s
            ),
            (10.0, 1.0, 1.0)
        );
        let afm = super::Afm::from_scene(&s, 40e-6, 50e-6, 1e-3);
        let at = afm.stage;
        assert!(
            (afm.guard_travel(at) - 30e-9).abs() < 1e-21,
            "{:e}",
            afm.guard_travel(at)
        );
        let near = [at[0] + 20e-9, at[1], at[2]];
        assert!((afm.guard_travel(near) - 30e-9).abs() < 1e-21);
        let far = [at[0] + 3e-6, at[1] + 4e-6, at[2]];
        assert!((afm.guard_travel(far) - 5e-6).abs() < 1e-18);
    }
}
