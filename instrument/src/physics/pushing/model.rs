//! The kinetic pushing dynamics, **Eq 17**, as a state-space model `M x' = f(t, x)` with an exact
//! Jacobian.
//!
//! # Geometry (the push frame of Sec 2.5)
//! `y` points along the push, `z` up, in the frame of the substrate. The stage moves the
//! cantilever base by `s(t)` relative to the substrate (`s = Vt` for an ideal stage, Eq 13 when
//! the stage is dynamic). The cantilever is tilted by `α`: its long axis is `y' = (cos α, −sin α)`
//! and its normal `z' = (sin α, cos α)` in `(y, z)`, so that pushing loads the particle downward,
//! as in Eq 14 (this choice reproduces Eq 14's `f_as` and `F_as` exactly). The tip is a sphere
//! `Rₜ` whose centre is the base plus the deflection `R(α)ζ`; the particle a sphere `Rₐ` with centre
//! `(y, Rₐ + a₀ + z)` and rotation `θ`. At `t = 0` the tip touches the particle at the contact
//! angle `β` (tip centre at `β` above the horizontal through the particle centre).
//!
//! # Forces
//! - **Tip-particle normal**: JKR (Eq 5) on the overlap `a₀ − h` (gap `h` between the spheres'
//!   surfaces; contact at `h = a₀`) plus the included long-range terms (Eq 1, 3, 4) at
//!   `max(h, a₀)`, along the line of centres `n`.
//! - **Particle-substrate normal**: JKR on the indentation `−z` plus Eq 2, 3, 4 at `a₀ + z`.
//! - **Friction** (Eq 6, 7) at both contacts, as an elastic spring-slider: while a contact sticks
//!   its tangential displacement stretches a spring (`k_as* = 8RₐG*` as in Eq 14's `F_y = k_as* y`;
//!   `k_ta* = 8R̃G*_ta` at the tip) up to the static limit `μˢ(A + F_l)`; while it slips the force
//!   is the kinetic `μᵏ(A + F_l)` against the slip. The tangential coordinates are
//!   `s_as = y − Rₐθ` (substrate contact point) and `ξ = (Rₜ+Rₐ)φ + Rₐθ` (tip contact, `φ` the angle
//!   of `n`; exact while the gap is small against the radii).
//! - **Modes** (Sec 2.5): *stick* (both contacts stick), *slip* (the particle slides on the
//!   substrate), *roll* (it sticks on the substrate, rotates, and slides under the tip). Switches
//!   are discrete events ([`PushModel::switching`]), not a smooth blur.
//!
//! # Equations (one row per state; `Dof::QuasiStatic` rows have zero mass)
//! - cantilever: `m_c* ζ̈ + b ζ̇ + Kζ = R(α)ᵀ F_tip`, `K = C_yz⁻¹` (Eq 10). In statics Eq 17's
//!   first two lines are exactly `ζ = C F` (`k_y ζ_y = F_y + (k_y/k_yz) F_z` is
//!   `ζ_y = (c₂F_y + c₃F_z)/k_c`); in dynamics they put the coupling on the force side, this
//!   model in the stiffness `K`;
//! - particle: `mₐ ÿ = F_y,tip + F_t,as + mₐ s̈`, `mₐ z̈ + b_as ż = P_as + F_lr,as + F_z,tip`,
//!   `I₀ θ̈ = Rₐ(F_t,ta − F_t,as)` (Eq 17 lines 3-5, `I₀ = 2mₐRₐ²/5`);
//! - stage: Eq 13 with the friction load `f_as`.
//!
//! Deviations from the print: Eq 17 mixes `γ = β − α` (an angle) with `γ_L` (a surface energy),
//! named apart here (docs/errata.md item 10); the printed lines for `F_y^c`, `F_z^c` are the projections
//! of `F_tip` that this model computes from the geometry instead.

// Numerical kernels index several arrays with one loop variable: index loops are clearer.
#![allow(clippy::needless_range_loop)]

use crate::numerics::dual::{Dual, DualN, Real};
use crate::numerics::integrate::linalg::Lu;
use crate::physics::forces::capillary::Meniscus;
use crate::physics::pushing::layout::{Layout, MAX_STATES};
use crate::physics::pushing::params::PushParams;

/// State of one frictional contact.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Tangential {
    /// Sticking: the tangential spring is anchored at `anchor` (m).
    Stick {
        /// The spring's rest position in the contact's tangential coordinate (m).
        anchor: f64,
    },
    /// Slipping in `direction` (±1): the friction is kinetic and opposes it.
    Slip {
        /// Sign of the slip velocity.
        direction: f64,
    },
}

/// The discrete part of the hybrid state: what the continuous right-hand side depends on.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Mode {
    /// Particle-substrate friction.
    pub substrate: Tangential,
    /// Tip-particle friction.
    pub tip: Tangential,
    /// Tip-particle meniscus (Eq 3 hysteresis).
    pub meniscus: Meniscus,
    /// Whether the tip-particle JKR contact exists (formed at `h ≤ a₀`, broken below the JKR
    /// stable branch).
    pub tip_contact: bool,
}

/// The friction phase of the particle, as Sec 2.5 names it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum FrictionPhase {
    /// Both contacts stick: static phase (Eq 14).
    Stick,
    /// The particle slides on the substrate.
    Slip,
    /// The particle rolls: it sticks on the substrate and rotates under the tip.
    Roll,
}

impl FrictionPhase {
    /// Lower-case name, for traces.
    pub fn as_str(self) -> &'static str {
        match self {
            FrictionPhase::Stick => "stick",
            FrictionPhase::Slip => "slip",
            FrictionPhase::Roll => "roll",
        }
    }
}

/// Forces and kinematics at one state (SI), for traces, events and reports.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Probe<T> {
    /// Tip-particle surface gap `h` (m); contact at `a₀`.
    pub gap: T,
    /// Tip-particle normal force on the particle, along `n` (N, positive repulsive): `F_ta`.
    pub normal_ta: T,
    /// Tip-particle friction `f_ta` (N, along `ξ`).
    pub friction_ta: T,
    /// Tip-particle normal load for friction, `A_ta + F_l^ta` (N).
    pub load_ta: T,
    /// Particle-substrate friction `f_as` (N, along `y`, on the particle).
    pub friction_as: T,
    /// Particle-substrate normal load for friction, `A_as + F_l^as` (N).
    pub load_as: T,
    /// Substrate contact coordinate `s_as = y − Rₐθ` (m).
    pub contact_as: T,
    /// Tip contact coordinate `ξ` (m).
    pub contact_ta: T,
    /// Rate of `s_as` (m/s): the substrate slip velocity while slipping.
    pub slip_rate_as: T,
    /// Rate of `ξ` (m/s).
    pub slip_rate_ta: T,
    /// Measured deflection `ζ_z'` (m), Eq 11.
    pub zeta_z: T,
    /// `ζ_y'` (m).
    pub zeta_y: T,
    /// Stage displacement `s` (m).
    pub stage: T,
    /// Stage acceleration `s̈` (m/s²).
    pub stage_accel: T,
}

/// The switching functions of the hybrid model. Each is positive while the present mode holds
/// and an event fires when it crosses zero; `None` when a switch does not apply.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Switching {
    /// Substrate: `μˢN − |f|` while sticking (→ slip), `direction·ṡ_as` while slipping
    /// (→ stick; the rate is exact for quasi-static DOFs too, see [`PushModel::contact_rates`]).
    pub substrate: Option<f64>,
    /// Tip: the same for the tip-particle contact.
    pub tip: Option<f64>,
    /// Meniscus: `h − (L_t + a₀)` while absent (→ forms), `L_r + a₀ − h` while formed
    /// (→ ruptures).
    pub meniscus: Option<f64>,
    /// Tip contact: `h − a₀` while apart (→ touches), `(a₀ − h) − δ_min` while in contact
    /// (→ breaks off the JKR stable branch).
    pub tip_contact: Option<f64>,
}

/// How the instrument drives the tip base during one control tick: the stage reference along the
/// push `y_ref(t) = y₀ + v_y (t − t₀)` (Eq 13's commanded position; the stage itself when it is
/// ideal) and the base height above the particle's substrate `z(t) = z₀ + v_z (t − t₀)` relative to
/// the contact height (z-position control, and the substrate's topography under a moving
/// particle). Piecewise linear in time: the controller sets a new segment at each tick, so the
/// reference is continuous and the integrator sees a smooth problem inside a tick.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Drive {
    /// Start of the segment `t₀` (s).
    pub t0: f64,
    /// Stage reference at `t₀` (m).
    pub y0: f64,
    /// Stage reference rate (m/s).
    pub vy: f64,
    /// Base height offset at `t₀` (m, positive up).
    pub z0: f64,
    /// Base height rate (m/s).
    pub vz: f64,
}

impl Drive {
    /// The paper's constant-speed push: `y_ref = V t`, fixed height.
    pub fn constant_speed(speed: f64) -> Drive {
        Drive {
            t0: 0.0,
            y0: 0.0,
            vy: speed,
            z0: 0.0,
            vz: 0.0,
        }
    }

    /// The segment from `(y_ref(t), z(t))` at time `t` to the targets `(y1, z1)` at `t1 > t`.
    pub fn ramp_to(&self, t: f64, t1: f64, y1: f64, z1: f64) -> Drive {
        let (y, z) = (self.y_at(t), self.z_at(t));
        let dt = t1 - t;
        Drive {
            t0: t,
            y0: y,
            vy: (y1 - y) / dt,
            z0: z,
            vz: (z1 - z) / dt,
        }
    }

    /// Stage reference `y_ref(t)` (m).
    pub fn y_at(&self, t: f64) -> f64 {
        self.y0 + self.vy * (t - self.t0)
    }

    /// Base height offset `z(t)` (m).
    pub fn z_at(&self, t: f64) -> f64 {
        self.z0 + self.vz * (t - self.t0)
    }

    fn y<T: Real>(&self, t: T) -> T {
        (t - self.t0) * self.vy + self.y0
    }

    fn z<T: Real>(&self, t: T) -> T {
        (t - self.t0) * self.vz + self.z0
    }
}

/// The assembled pushing model for one scene: parameters, layout and precomputed constants.
#[derive(Debug, Clone)]
pub struct PushModel {
    /// The parameters.
    pub p: PushParams,
    /// The state layout.
    pub layout: Layout,
    base: (f64, f64),
    rot: (f64, f64),
    k: (f64, f64, f64),
    m_c: f64,
    b_c: f64,
    z_fixed: f64,
    adhesion_as: f64,
    /// [`Self::break_overlap`], fixed by the parameters: the switching function reads it at
    /// every step.
    break_overlap: f64,
    mass: [f64; MAX_STATES],
    /// The tip base's drive (stage reference and height); [`Drive::constant_speed`] at `V` unless
    /// a controller sets it.
    pub drive: Drive,
}

impl PushModel {
    /// Assembles the model; the particle's initial indentation is its JKR equilibrium under the
    /// included long-range attraction with no tip load.
    pub fn new(p: PushParams) -> PushModel {
        // With no friction at either contact (every μ zero) nothing exerts a torque on the
        // particle: its rotation is undetermined (a zero row of the quasi-static Jacobian, which
        // the integrator cannot solve) and moves nothing else. It is left out.
        let mut dofs = p.dofs;
        if p.frictionless() {
            dofs.particle_rotation = crate::physics::pushing::params::Dof::Off;
        }
        let layout = Layout::new(&dofs);
        let a0 = p.interactions.a0;
        let lr_as: f64 = p.interactions.particle_substrate_force(a0);
        let z_fixed = -p.jkr_as.indentation_from_load(-lr_as).unwrap_or(0.0);
        let (sa, ca) = p.cantilever.tilt.sin_cos();
        let (sb, cb) = p.beta.sin_cos();
        // The tip starts in contact, indented by the JKR overlap under the tip-particle
        // attraction (at least 0.01 nm): exactly at the contact point both the Hertz stiffness
        // and the cut-off attraction's gradient vanish, which would leave the quasi-static rows
        // without a usable Jacobian.
        let meniscus = match &p.interactions.tip_particle.capillary {
            Some(c) if c.possible() => Meniscus::Formed,
            _ => Meniscus::Absent,
        };
        let lr_ta: f64 = p.interactions.tip_particle_force(a0, meniscus);
        let overlap = p.jkr_ta.indentation_from_load(-lr_ta).unwrap_or(0.0).max(0.01e-9);
        let d = p.r_t + p.r_a + a0 - overlap;
        let base = (-d * cb, p.r_a + a0 + z_fixed + d * sb);
        let kk = p.cantilever.stiffness_yz();
        let break_overlap = switching::break_overlap(&p, &layout);
        PushModel {
            layout,
            base,
            rot: (sa, ca),
            k: (kk[(0, 0)], kk[(0, 1)], kk[(1, 1)]),
            m_c: p.cantilever.effective_mass(),
            b_c: p.cantilever.damping(),
            z_fixed,
            adhesion_as: p.adhesion_as(),
            break_overlap,
            mass: layout.mass_diagonal(),
            drive: Drive::constant_speed(p.speed),
            p,
        }
    }

    /// The particle's vertical displacement when its z DOF is off: its equilibrium indentation
    /// under the substrate attraction (m, negative = into the substrate).
    pub fn frozen_particle_z(&self) -> f64 {
        self.z_fixed
    }

    /// State dimension.
    pub fn len(&self) -> usize {
        self.layout.len
    }

    /// Whether the state is empty (never: the cantilever and particle y are always present).
    pub fn is_empty(&self) -> bool {
        self.layout.len == 0
    }

    /// Initial state: particle at rest at its equilibrium indentation, tip touching it at `β`,
    /// indented by the JKR overlap that balances the tip-particle attraction, cantilever
    /// undeflected, stage at 0. Quasi-static rows are not yet balanced: see
    /// [`Self::equilibrate`].
    pub fn initial_state(&self) -> [f64; MAX_STATES] {
        let mut x = [0.0; MAX_STATES];
        if let Some(z) = self.layout.particle_z {
            x[z.pos] = self.z_fixed;
        }
        x
    }

    /// Initial mode: both contacts stick where they are, the meniscus is formed if the humidity
    /// allows one, the tip is in contact.
    pub fn initial_mode(&self) -> Mode {
        let meniscus = match &self.p.interactions.tip_particle.capillary {
            Some(c) if c.possible() => Meniscus::Formed,
            _ => Meniscus::Absent,
        };
        let mut mode = Mode {
            substrate: Tangential::Stick { anchor: 0.0 },
            tip: Tangential::Stick { anchor: 0.0 },
            meniscus,
            tip_contact: true,
        };
        let x = self.initial_state();
        let pr = self.probe(0.0, &x[..self.len()], &mode);
        mode.substrate = Tangential::Stick { anchor: pr.contact_as };
        mode.tip = Tangential::Stick { anchor: pr.contact_ta };
        mode
    }

    /// The friction phase a mode stands for.
    pub fn phase(&self, mode: &Mode) -> FrictionPhase {
        match (mode.substrate, mode.tip, self.layout.rotation.is_some()) {
            (Tangential::Slip { .. }, _, _) => FrictionPhase::Slip,
            (Tangential::Stick { .. }, Tangential::Slip { .. }, true) => FrictionPhase::Roll,
            _ => FrictionPhase::Stick,
        }
    }

    /// The diagonal mass matrix of `M x' = f` (computed once, with the layout).
    pub fn mass_diagonal(&self) -> [f64; MAX_STATES] {
        self.mass
    }

    /// The right-hand side `f(t, x)` for the given mode; writes `out[..len]`.
    pub fn rhs(&self, t: f64, x: &[f64], mode: &Mode, out: &mut [f64]) {
        let (f, _) = self.eval(t, x, mode);
        out[..self.len()].copy_from_slice(&f[..self.len()]);
    }

    /// `∂f/∂t` at `(t, x)` (the drive `y_ref(t)`, `z(t)` is the only explicit time dependence), by
    /// one dual evaluation with `t` as the active variable.
    pub fn time_derivative(&self, t: f64, x: &[f64], mode: &Mode, out: &mut [f64]) {
        let n = self.len();
        let mut xd = [Dual::default(); MAX_STATES];
        for (d, &v) in xd.iter_mut().zip(x.iter()).take(n) {
            *d = Dual::new(v, 0.0);
        }
        let (f, _) = self.eval(Dual::var(t), &xd[..n], mode);
        for i in 0..n {
            out[i] = f[i].eps;
        }
    }

    /// The exact Jacobian `∂f/∂x` (column-major `len × len`, as nalgebra stores it), one
    /// forward-mode dual evaluation per column: no finite differences, no allocation.
    pub fn jacobian(&self, t: f64, x: &[f64], mode: &Mode, jac: &mut [f64]) {
        let n = self.len();
        let mut xd = [Dual::default(); MAX_STATES];
        for (d, &v) in xd.iter_mut().zip(x.iter()).take(n) {
            *d = Dual::new(v, 0.0);
        }
        for j in 0..n {
            xd[j].eps = 1.0;
            let (f, _) = self.eval(Dual::new(t, 0.0), &xd[..n], mode);
            for i in 0..n {
                jac[j * n + i] = f[i].eps;
            }
            xd[j].eps = 0.0;
        }
    }

    /// `f`, `∂f/∂t` and the Jacobian (column-major) in one pass: the model evaluated once on
    /// multi-lane dual numbers, one lane per state plus one for time. Equal to [`Self::rhs`],
    /// [`Self::time_derivative`] and [`Self::jacobian`], at about a third of their cost.
    pub fn derivatives(&self, t: f64, x: &[f64], mode: &Mode, f: &mut [f64], ft: &mut [f64], jac: &mut [f64]) {
        match self.len() {
            0..=4 => self.derivatives_n::<5>(t, x, mode, f, ft, jac),
            5..=8 => self.derivatives_n::<9>(t, x, mode, f, ft, jac),
            _ => self.derivatives_n::<13>(t, x, mode, f, ft, jac),
        }
    }

    fn derivatives_n<const N: usize>(
        &self,
        t: f64,
        x: &[f64],
        mode: &Mode,
        f: &mut [f64],
        ft: &mut [f64],
        jac: &mut [f64],
    ) {
        let n = self.len();
        let mut xd = [DualN::<N>::constant(0.0); MAX_STATES];
        for j in 0..n {
            xd[j] = DualN::seed(x[j], j);
        }
        let (out, _) = self.eval(DualN::seed(t, N - 1), &xd[..n], mode);
        for i in 0..n {
            f[i] = out[i].re;
            ft[i] = out[i].eps[N - 1];
            for j in 0..n {
                jac[j * n + i] = out[i].eps[j];
            }
        }
    }

    /// Forces and kinematics at `(t, x)`.
    pub fn probe(&self, t: f64, x: &[f64], mode: &Mode) -> Probe<f64> {
        self.eval(t, x, mode).1
    }

    /// The indices of the algebraic (zero-mass) rows, and how many there are.
    fn algebraic_rows(&self) -> ([usize; MAX_STATES], usize) {
        let mut alg = [0usize; MAX_STATES];
        let mut m = 0;
        for (i, &mass) in self.mass[..self.len()].iter().enumerate() {
            if mass == 0.0 {
                alg[m] = i;
                m += 1;
            }
        }
        (alg, m)
    }

    /// Balances the quasi-static (algebraic) rows by Newton's method, holding the differential
    /// states fixed: a consistent initial value for the DAE, and again after an event changes
    /// a force discontinuously. Returns the final residual norm (m). No allocation.
    pub fn equilibrate(&self, t: f64, x: &mut [f64], mode: &Mode) -> f64 {
        let n = self.len();
        let (alg, m) = self.algebraic_rows();
        let mut f = [0.0; MAX_STATES];
        let mut jac = [0.0; MAX_STATES * MAX_STATES];
        let mut res = 0.0;
        let mut lu = Lu::default();
        for _ in 0..100 {
            self.rhs(t, x, mode, &mut f);
            res = alg[..m].iter().map(|&i| f[i] * f[i]).sum::<f64>().sqrt();
            if m == 0 || res < 1e-16 || !res.is_finite() {
                break;
            }
            self.jacobian(t, x, mode, &mut jac);
            let mut a = [0.0; MAX_STATES * MAX_STATES];
            let mut b = [0.0; MAX_STATES];
            for c in 0..m {
                for r in 0..m {
                    a[c * m + r] = jac[alg[c] * n + alg[r]];
                }
                b[c] = -f[alg[c]];
            }
            if !lu.factor(m, &a) {
                break;
            }
            lu.solve(&mut b[..m]);
            for k in 0..m {
                x[alg[k]] += b[k];
            }
        }
        res
    }

    /// The time derivative of the whole state, `ẋ`: `f` on the differential rows; on the
    /// algebraic rows the derivative of the constraint, `J_aa ẋ_a = −(J_ad ẋ_d + ∂f_a/∂t)`.
    /// `false` when the constraint Jacobian is singular.
    pub fn state_rate(&self, t: f64, x: &[f64], mode: &Mode, out: &mut [f64]) -> bool {
        let n = self.len();
        let mut f = [0.0; MAX_STATES];
        let mut jac = [0.0; MAX_STATES * MAX_STATES];
        let mut ft = [0.0; MAX_STATES];
        self.rhs(t, x, mode, &mut f);
        self.jacobian(t, x, mode, &mut jac);
        self.time_derivative(t, x, mode, &mut ft);
        self.state_rate_from(&f[..n], &ft[..n], &jac[..n * n], out)
    }

    /// [`Self::state_rate`] from `f`, `∂f/∂t` and `J` already evaluated at the state.
    pub fn state_rate_from(&self, f: &[f64], ft: &[f64], jac: &[f64], out: &mut [f64]) -> bool {
        let n = self.len();
        let mass = self.mass_diagonal();
        out[..n].copy_from_slice(&f[..n]);
        let (alg, m) = self.algebraic_rows();
        if m == 0 {
            return true;
        }
        let mut a = [0.0; MAX_STATES * MAX_STATES];
        let mut b = [0.0; MAX_STATES];
        for (r, &i) in alg[..m].iter().enumerate() {
            let mut rhs = -ft[i];
            for j in 0..n {
                if mass[j] != 0.0 {
                    rhs -= jac[j * n + i] * out[j];
                }
            }
            b[r] = rhs;
            for (c, &j) in alg[..m].iter().enumerate() {
                a[c * m + r] = jac[j * n + i];
            }
        }
        let mut lu = Lu::default();
        if !lu.factor(m, &a) {
            return false;
        }
        lu.solve(&mut b[..m]);
        for (k, &i) in alg[..m].iter().enumerate() {
            out[i] = b[k];
        }
        true
    }

    /// Rates of the two tangential contact coordinates `(ṡ_as, ξ̇)` (m/s), exact for dynamic
    /// and quasi-static DOFs alike: the probe is differentiated along `(ẋ, 1)`.
    pub fn contact_rates(&self, t: f64, x: &[f64], mode: &Mode) -> Option<(f64, f64)> {
        let mut xdot = [0.0; MAX_STATES];
        if !self.state_rate(t, x, mode, &mut xdot) {
            return None;
        }
        Some(self.contact_rates_along(t, x, mode, &xdot))
    }

    /// The contact rates along a known `ẋ`.
    pub fn contact_rates_along(&self, t: f64, x: &[f64], mode: &Mode, xdot: &[f64]) -> (f64, f64) {
        let n = self.len();
        let mut xd = [Dual::default(); MAX_STATES];
        for i in 0..n {
            xd[i] = Dual::new(x[i], xdot[i]);
        }
        let (_, pr) = self.eval(Dual::var(t), &xd[..n], mode);
        (pr.contact_as.eps, pr.contact_ta.eps)
    }

    /// The measured deflection `ζ_z'` (m) at a state.
    pub fn measured_deflection(&self, x: &[f64]) -> f64 {
        x[self.layout.zeta_z.pos]
    }
}

impl Probe<f64> {
    /// Whether every field is finite.
    pub fn is_finite(&self) -> bool {
        [
            self.gap,
            self.normal_ta,
            self.friction_ta,
            self.load_ta,
            self.friction_as,
            self.load_as,
            self.zeta_z,
            self.zeta_y,
            self.stage,
        ]
        .iter()
        .all(|v| v.is_finite())
    }
}

mod eval;
mod switching;

pub use switching::{SwitchKind, UNLOADED_OVERLAP};

#[cfg(test)]
mod eq17_reference;
#[cfg(test)]
mod events_tests;
#[cfg(test)]
mod tests;
