//! The hybrid simulation of a push: the Eq 17 model integrated tick by tick, with the friction,
//! meniscus and contact switches located as events and the mode changed at each.

use crate::numerics::integrate::{
    Events, IntegrateError, Integrator, MAX_EVENTS, Method, Options, Outcome, Problem, Stats,
};
use crate::physics::pushing::layout::MAX_STATES;
use crate::physics::pushing::model::{Drive, FrictionPhase, Mode, PushModel, SwitchKind, Tangential};

/// The model in one mode, as the integrator sees it.
struct InMode<'a> {
    model: &'a PushModel,
    mode: Mode,
    scale: [f64; MAX_STATES],
}

impl Problem for InMode<'_> {
    fn len(&self) -> usize {
        self.model.len()
    }
    fn mass(&self, i: usize) -> f64 {
        self.model.mass_diagonal()[i]
    }
    fn rhs(&self, t: f64, y: &[f64], out: &mut [f64]) {
        self.model.rhs(t, y, &self.mode, out);
    }
    fn jacobian(&self, t: f64, y: &[f64], jac: &mut [f64]) {
        self.model.jacobian(t, y, &self.mode, jac);
    }
    fn time_derivative(&self, t: f64, y: &[f64], out: &mut [f64]) {
        self.model.time_derivative(t, y, &self.mode, out);
    }
    fn scale(&self, i: usize) -> f64 {
        self.scale[i]
    }
    fn derivatives(&self, t: f64, y: &[f64], f: &mut [f64], ft: &mut [f64], jac: &mut [f64]) {
        self.model.derivatives(t, y, &self.mode, f, ft, jac);
    }
}

const SWITCHES: [SwitchKind; 4] = [
    SwitchKind::Substrate,
    SwitchKind::Tip,
    SwitchKind::Meniscus,
    SwitchKind::TipContact,
];

impl Events for InMode<'_> {
    fn count(&self) -> usize {
        SWITCHES.len()
    }
    fn eval(&self, t: f64, y: &[f64], out: &mut [f64]) {
        write_switching(self.model.switching(t, y, &self.mode), out);
    }
    fn eval_at_step(&self, t: f64, y: &[f64], f: &[f64], ft: &[f64], jac: &[f64], out: &mut [f64]) {
        let mut xdot = [0.0; MAX_STATES];
        let sw = if PushModel::slipping(&self.mode) && self.model.state_rate_from(f, ft, jac, &mut xdot) {
            self.model.switching_along(t, y, &self.mode, &xdot[..self.model.len()])
        } else {
            self.model.switching_with(t, y, &self.mode, None)
        };
        write_switching(sw, out);
    }
}

fn write_switching(s: crate::physics::pushing::Switching, out: &mut [f64]) {
    for (o, v) in out.iter_mut().zip([s.substrate, s.tip, s.meniscus, s.tip_contact]) {
        *o = v.unwrap_or(f64::NAN);
    }
}

/// A gap (m) beyond which a tip that no longer touches the particle has let go of it.
pub const RELEASE_GAP: f64 = 20e-9;

/// How a call of [`Simulation::advance_or_release`] ended.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Advance {
    /// The tip still holds the particle at the end time.
    Holding,
    /// The tip let go: its contact broke and the gap opened beyond [`RELEASE_GAP`]; or the
    /// contact broke while the particle is quasi-static (see below); or, while lifting, the
    /// quasi-static balance reached the fold of the pull-off (the JKR and meniscus equilibrium
    /// the integrator follows vanishes, and the tip snaps free, as on the force curve's
    /// retraction). The state is where the contact broke or the balance vanished.
    ///
    /// A quasi-static particle (no inertia) has no balance once the tip's contact breaks: its
    /// rows then hold only the tip's long-range attraction against a rolling contact with no
    /// rolling resistance (Eq 17 has none), so any `y = Rₐθ + const` is as good as another and
    /// Newton's method walks the particle off to wherever the attraction has decayed (a 0.01 N/m
    /// lever sent it 38 mm in one tick). The break is therefore the release for such a
    /// particle: it stays where the contact broke.
    Released,
}

/// What one call of [`Simulation::advance_to`] did.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct TickReport {
    /// Integrator work (steps, rejections, Jacobians, LUs, local error, wall time).
    pub stats: Stats,
    /// Mode switches handled.
    pub switches: u32,
}

/// Why a simulation stopped.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum SimulationError {
    /// The integrator failed.
    #[error(transparent)]
    Integrate(#[from] IntegrateError),
    /// Mode switches chatter (more than the limit inside one call): the friction law cannot
    /// decide between stick and slip at this resolution.
    #[error("{count} mode switches before t = {t:e} s: chattering between friction phases")]
    Chattering {
        /// Switches counted.
        count: u32,
        /// Time reached.
        t: f64,
    },
    /// The tip's contact broke under a quasi-static particle, or its balance vanished (see
    /// [`Advance::Released`]): [`Simulation::advance_or_release`] calls it a release; for a
    /// fixed-duration run the push lost its particle. A physical outcome of the model, not a
    /// failure of the integrator: the tip's push left the friction cones that hold a particle
    /// with no inertia and no rolling resistance, and it slid or rolled ahead of the tip (see
    /// [`PushModel::break_overlap`]).
    #[error(
        "the tip's contact with the particle broke (or its quasi-static balance vanished) at t = {t:e} s: the tip lost the particle, which slid or rolled away from it"
    )]
    ContactLost {
        /// Time (s).
        t: f64,
    },
    /// A run went over the work it was allowed (integrator steps or trace samples): what a
    /// caller bounds so that no scene, however slow its stage, costs unbounded memory or time.
    #[error(
        "{what} over its budget of {limit} before t = {t:e} s (a very slow stage or a very long push: \
         raise push.speed_um_per_s or shorten the push)"
    )]
    Budget {
        /// What ran over: `integrator steps` or `trace samples`.
        what: &'static str,
        /// The budget.
        limit: u64,
        /// Time reached (s).
        t: f64,
    },
}

/// A push in progress.
#[derive(Debug, Clone)]
pub struct Simulation {
    /// The model.
    pub model: PushModel,
    /// Current discrete mode.
    pub mode: Mode,
    /// Current time (s).
    pub t: f64,
    /// Current state (`x[..model.len()]`).
    pub x: [f64; MAX_STATES],
    /// Work done since the start.
    pub total: Stats,
    /// Time of the first stick → slip of the substrate contact, the shearing time `t*` (s).
    pub shearing_time: Option<f64>,
    integrator: Integrator,
    scale: [f64; MAX_STATES],
    /// Most mode switches in one call before it is called chattering.
    pub max_switches: u32,
    /// The quasi-static balance vanished (see [`Self::rebalance`]): the tip lets go.
    balance_lost: bool,
}

impl Simulation {
    /// Starts a push at `t = 0` from the model's initial state and mode, with the quasi-static
    /// rows balanced.
    pub fn new(model: PushModel, method: Method, opts: Options) -> Simulation {
        let mode = model.initial_mode();
        let mut x = model.initial_state();
        let n = model.len();
        model.equilibrate(0.0, &mut x[..n], &mode);
        let scale = Self::scales(&model);
        let mut sim = Simulation {
            integrator: Integrator::new(method, opts),
            model,
            mode,
            t: 0.0,
            x,
            total: Stats::default(),
            shearing_time: None,
            scale,
            max_switches: 10_000,
            balance_lost: false,
        };
        sim.enforce_mode();
        sim
    }

    /// Events fire when a switching function crosses zero; one that is already negative when a
    /// mode starts (after the quasi-static rows settle, say) would never cross. Apply those
    /// switches at once: stick → slip where the friction demand exceeds the static limit, slip →
    /// stick where the slip runs against its kinetic friction (by more than 1 nm/s: at rest the
    /// slip rate is zero, which is no reason to stick), and the meniscus and contact switches.
    /// Returns how many switches it applied (at most 4).
    fn enforce_mode(&mut self) -> u32 {
        let n = self.model.len();
        let mut applied = 0;
        // A contact switched to slip here is not switched back in the same call (no ping-pong),
        // and a slip with zero kinetic friction never "runs against" it.
        let (mut fresh_as, mut fresh_ta) = (false, false);
        let (mu_as_k, mu_ta_k) = (self.model.p.mu_as_k, self.model.p.mu_ta_k);
        for _ in 0..4 {
            let sw = self.model.switching(self.t, &self.x[..n], &self.mode);
            let stick_violated =
                |t: Tangential, g: Option<f64>| matches!(t, Tangential::Stick { .. }) && g.is_some_and(|g| g < 0.0);
            // A slipping contact whose slip runs against its friction (direction·rate below
            // −1 nm/s, beyond noise) would be pushed by friction: it sticks.
            let slip_reversed = |t: Tangential, g: Option<f64>, fresh: bool, mu_k: f64| {
                !fresh && mu_k > 0.0 && matches!(t, Tangential::Slip { .. }) && g.is_some_and(|g| g < -1e-9)
            };
            let kind = if stick_violated(self.mode.substrate, sw.substrate) {
                fresh_as = true;
                SwitchKind::Substrate
            } else if slip_reversed(self.mode.substrate, sw.substrate, fresh_as, mu_as_k) {
                SwitchKind::Substrate
            } else if stick_violated(self.mode.tip, sw.tip) {
                fresh_ta = true;
                SwitchKind::Tip
            } else if slip_reversed(self.mode.tip, sw.tip, fresh_ta, mu_ta_k) {
                SwitchKind::Tip
            } else if sw.meniscus.is_some_and(|g| g < 0.0) {
                SwitchKind::Meniscus
            } else if sw.tip_contact.is_some_and(|g| g < 0.0) {
                SwitchKind::TipContact
            } else {
                break;
            };
            self.switch(kind);
            applied += 1;
        }
        applied
    }

    /// Applies one switch at the current state.
    fn switch(&mut self, kind: SwitchKind) {
        let n = self.model.len();
        let before = self.mode;
        self.mode = self.model.transition(self.t, &self.x[..n], &self.mode, kind);
        if kind == SwitchKind::Substrate
            && self.shearing_time.is_none()
            && matches!(before.substrate, Tangential::Stick { .. })
        {
            self.shearing_time = Some(self.t);
        }
        // A switch may change a force discontinuously (meniscus, contact): balance the
        // quasi-static rows again and restart the step-size history.
        self.rebalance();
        self.integrator.reset_step();
    }

    /// Whether the particle's position is a quasi-static (algebraic) row.
    fn quasi_static_particle(&self) -> bool {
        self.model.layout.particle_y.vel.is_none()
    }

    /// Balances the quasi-static rows again ([`PushModel::equilibrate`]) after a switch or a new
    /// drive, unless there is no balance to find: a quasi-static particle the tip let go of, or
    /// a Newton solution that moved the particle by more than `Rₐ + Rₜ` (the balance vanished
    /// at a fold, and Newton's method walked off to a far root where the attraction has
    /// decayed: in a roll with an adhesive 0.01 N/m lever it went 3.7 cm). Then the state stays
    /// where it was and [`Self::balance_lost`] is set.
    fn rebalance(&mut self) {
        if self.balance_lost || (!self.mode.tip_contact && self.quasi_static_particle()) {
            return;
        }
        let n = self.model.len();
        let before = self.x;
        let res = self.model.equilibrate(self.t, &mut self.x[..n], &self.mode);
        let l = &self.model.layout;
        let reach = self.model.p.r_a + self.model.p.r_t;
        let moved = |pos: usize| (self.x[pos] - before[pos]).abs();
        let walked = moved(l.particle_y.pos) > reach || l.particle_z.is_some_and(|z| moved(z.pos) > reach);
        if !res.is_finite() || walked || self.x[..n].iter().any(|v| !v.is_finite()) {
            self.x = before;
            self.balance_lost = true;
        }
    }

    /// Typical magnitudes of the states, for the absolute tolerance: 1 nm for positions and
    /// 1 nm of arc for rotations; 1 mm/s (1 nm/µs) for rates. The forces on a femtogram particle
    /// are µN-scale terms that nearly cancel, so its acceleration carries rounding noise of
    /// ~1e-9 m/s²: a rate tolerance much below 1e-9 m/s at millisecond steps would chase noise.
    fn scales(model: &PushModel) -> [f64; MAX_STATES] {
        let mut s = [1e-9; MAX_STATES];
        let l = &model.layout;
        let r_a = model.p.r_a;
        for slot in [
            l.stage,
            Some(l.zeta_y),
            Some(l.zeta_z),
            Some(l.particle_y),
            l.particle_z,
        ]
        .into_iter()
        .flatten()
        {
            s[slot.pos] = 1e-9;
            if let Some(v) = slot.vel {
                s[v] = 1e-3;
            }
        }
        if let Some(r) = l.rotation {
            s[r.pos] = 1e-9 / r_a;
            if let Some(v) = r.vel {
                s[v] = 1e-3 / r_a;
            }
        }
        s
    }

    /// Sets the tip base's drive from now on (a new control segment). The state is continuous;
    /// derivatives cached by the integrator are dropped, and switches the new drive makes due at
    /// once (a slip now running against its friction, say) are applied. Returns how many.
    pub fn set_drive(&mut self, drive: Drive) -> u32 {
        if drive == self.model.drive {
            return 0;
        }
        self.model.drive = drive;
        self.integrator.forget_derivatives();
        self.rebalance();
        self.enforce_mode()
    }

    /// Advances to `t_end` like [`Self::advance_to`], and tells whether the tip let go of the
    /// particle (see [`Advance::Released`]). A failure while the drive is not lifting is an error.
    pub fn advance_or_release(&mut self, t_end: f64) -> Result<Advance, SimulationError> {
        let lifting = self.model.drive.vz > 0.0;
        match self.advance_to(t_end) {
            // The contact broke, or the balance vanished: where it happened, the tip let go.
            Err(SimulationError::ContactLost { .. }) => Ok(Advance::Released),
            Err(_) if lifting => Ok(Advance::Released),
            Err(e) => Err(e),
            Ok(_) => {
                let n = self.model.len();
                let gap = self.model.probe(self.t, &self.x[..n], &self.mode).gap;
                Ok(if !self.mode.tip_contact && gap > RELEASE_GAP {
                    Advance::Released
                } else {
                    Advance::Holding
                })
            }
        }
    }

    /// The integration method.
    pub fn method(&self) -> Method {
        self.integrator.method()
    }

    /// The friction phase now.
    pub fn phase(&self) -> FrictionPhase {
        self.model.phase(&self.mode)
    }

    /// Advances to `t_end`, switching modes at events. Allocation-free.
    pub fn advance_to(&mut self, t_end: f64) -> Result<TickReport, SimulationError> {
        let n = self.model.len();
        let mut report = TickReport::default();
        let mut lost = false;
        while self.t < t_end {
            // The tip's contact broke (at an event, or in the mode a new drive or a meniscus
            // rupture made due at once) and the particle is quasi-static, or its balance
            // vanished: it has no balance without the tip (see [`Advance::Released`]). Stop here,
            // with the state where it happened ([`Self::advance_or_release`] calls it a release).
            if self.balance_lost || (!self.mode.tip_contact && self.quasi_static_particle()) {
                lost = true;
                break;
            }
            let problem = InMode {
                model: &self.model,
                mode: self.mode,
                scale: self.scale,
            };
            let (outcome, st) = match self
                .integrator
                .advance(&problem, &problem, &mut self.t, &mut self.x[..n], t_end)
            {
                // The quasi-static balance ends at a fold (see [`Self::balance_lost`]): the state
                // is where it vanished, and the next pass stops there.
                Err(IntegrateError::Fold { .. }) => {
                    self.balance_lost = true;
                    continue;
                }
                r => r?,
            };

            report.stats.add(&st);
            match outcome {
                Outcome::Reached => break,
                Outcome::Event { index } => {
                    let kind = SWITCHES[index.min(MAX_EVENTS - 1).min(SWITCHES.len() - 1)];
                    self.switch(kind);
                    report.switches += 1 + self.enforce_mode();

                    if report.switches > self.max_switches {
                        return Err(SimulationError::Chattering {
                            count: report.switches,
                            t: self.t,
                        });
                    }
                }
            }
        }
        self.total.add(&report.stats);
        if lost {
            return Err(SimulationError::ContactLost { t: self.t });
        }
        Ok(report)
    }
}

#[cfg(test)]
mod tests;
