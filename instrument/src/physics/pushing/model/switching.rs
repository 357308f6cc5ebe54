//! The non-smooth events of Eq 17: when a stuck contact breaks loose, a slipping one sticks,
//! the tip touches or leaves the particle, or the meniscus forms or breaks; and the mode after
//! each ([`PushModel::transition`]).

use super::{Mode, Probe, PushModel, Switching, Tangential};
use crate::numerics::dual::Dual;
use crate::physics::forces::capillary::Meniscus;
use crate::physics::pushing::layout::{Layout, MAX_STATES};
use crate::physics::pushing::params::PushParams;

impl PushModel {
    /// The switching functions at `(t, x)` (see [`Switching`]); an event fires when a value
    /// becomes negative. Slip→stick needs the slip rate, which a quasi-static DOF does not carry:
    /// then it is `None` and the integrator decides from the sign of the force balance.
    pub fn switching(&self, t: f64, x: &[f64], mode: &Mode) -> Switching {
        let rates = if Self::slipping(mode) {
            self.contact_rates(t, x, mode)
        } else {
            None
        };
        self.switching_with(t, x, mode, rates)
    }

    /// Whether a contact slips in this mode (then the switching functions need the rates).
    pub fn slipping(mode: &Mode) -> bool {
        matches!(mode.substrate, Tangential::Slip { .. }) || matches!(mode.tip, Tangential::Slip { .. })
    }

    /// [`Self::switching`] with the contact rates `(ṡ_as, ξ̇)` already known.
    pub fn switching_with(&self, t: f64, x: &[f64], mode: &Mode, rates: Option<(f64, f64)>) -> Switching {
        self.switching_from(&self.probe(t, x, mode), mode, rates)
    }

    /// The switching functions along a known `ẋ`: one dual evaluation gives the probe and the
    /// contact rates together (what the integrator uses at the end of each step).
    pub fn switching_along(&self, t: f64, x: &[f64], mode: &Mode, xdot: &[f64]) -> Switching {
        let n = self.len();
        let mut xd = [Dual::default(); MAX_STATES];
        for i in 0..n {
            xd[i] = Dual::new(x[i], xdot[i]);
        }
        let (_, pd) = self.eval(Dual::var(t), &xd[..n], mode);
        let re = |d: Dual| d.re;
        let pr = Probe {
            gap: re(pd.gap),
            normal_ta: re(pd.normal_ta),
            friction_ta: re(pd.friction_ta),
            load_ta: re(pd.load_ta),
            friction_as: re(pd.friction_as),
            load_as: re(pd.load_as),
            contact_as: re(pd.contact_as),
            contact_ta: re(pd.contact_ta),
            slip_rate_as: re(pd.slip_rate_as),
            slip_rate_ta: re(pd.slip_rate_ta),
            zeta_z: re(pd.zeta_z),
            zeta_y: re(pd.zeta_y),
            stage: re(pd.stage),
            stage_accel: re(pd.stage_accel),
        };
        self.switching_from(&pr, mode, Some((pd.contact_as.eps, pd.contact_ta.eps)))
    }

    fn switching_from(&self, pr: &Probe<f64>, mode: &Mode, rates: Option<(f64, f64)>) -> Switching {
        let p = &self.p;
        let a0 = p.interactions.a0;
        let tangential = |t: Tangential, mu_s: f64, load: f64, force: f64, rate: Option<f64>| match t {
            Tangential::Stick { .. } => Some(mu_s * load.max(0.0) - force.abs()),
            Tangential::Slip { direction } => rate.map(|r| direction * r),
        };
        let meniscus = p
            .interactions
            .tip_particle
            .capillary
            .filter(|c| c.possible())
            .map(|c| match mode.meniscus {
                Meniscus::Absent => pr.gap - (c.formation_gap + a0),
                Meniscus::Formed => c.rupture_gap + a0 - pr.gap,
            });
        let tip_contact = Some(if mode.tip_contact {
            (a0 - pr.gap) - self.break_overlap()
        } else {
            pr.gap - a0
        });
        let tip_friction = if mode.tip_contact {
            tangential(mode.tip, p.mu_ta_s, pr.load_ta, pr.friction_ta, rates.map(|r| r.1))
        } else {
            None
        };
        Switching {
            substrate: tangential(
                mode.substrate,
                p.mu_as_s,
                pr.load_as,
                pr.friction_as,
                rates.map(|r| r.0),
            ),
            tip: tip_friction,
            meniscus,
            tip_contact,
        }
    }

    /// The overlap `a₀ − h` at which the tip's contact breaks ([`break_overlap`], computed once
    /// with the model).
    pub fn break_overlap(&self) -> f64 {
        self.break_overlap
    }

    /// The mode after the switch whose function crossed zero, keeping forces continuous: a contact
    /// that starts to slip slips against the friction force it was holding (spring and damping);
    /// one that sticks again is anchored so that the spring force equals the kinetic friction.
    pub fn transition(&self, t: f64, x: &[f64], mode: &Mode, which: SwitchKind) -> Mode {
        let pr = self.probe(t, x, mode);
        let p = &self.p;
        let mut m = *mode;
        match which {
            SwitchKind::Substrate => {
                m.substrate = match mode.substrate {
                    // The contact slips against the friction it was holding (spring and damping).
                    Tangential::Stick { .. } => Tangential::Slip {
                        direction: -sign(pr.friction_as),
                    },
                    Tangential::Slip { direction } => Tangential::Stick {
                        anchor: pr.contact_as - direction * p.mu_as_k * pr.load_as.max(0.0) / p.k_as_t,
                    },
                }
            }
            SwitchKind::Tip => {
                m.tip = match mode.tip {
                    Tangential::Stick { .. } => Tangential::Slip {
                        direction: -sign(pr.friction_ta),
                    },
                    Tangential::Slip { direction } => Tangential::Stick {
                        anchor: pr.contact_ta - direction * p.mu_ta_k * pr.load_ta.max(0.0) / p.k_ta_t,
                    },
                }
            }
            SwitchKind::Meniscus => {
                m.meniscus = match mode.meniscus {
                    Meniscus::Absent => Meniscus::Formed,
                    Meniscus::Formed => Meniscus::Absent,
                }
            }
            SwitchKind::TipContact => {
                m.tip_contact = !mode.tip_contact;
                if m.tip_contact {
                    m.tip = Tangential::Stick { anchor: pr.contact_ta };
                }
            }
        }
        m
    }
}

/// The overlap `a₀ − h` at which the tip's contact breaks: the JKR stable branch's end `δ_min`
/// (negative for an adhesive contact, where the load at the break is finite and tensile); where
/// the tip's push is the particle's only load ([`unloaded_root`]), [`UNLOADED_OVERLAP`].
///
/// A Hertz contact's load `P ∝ δ^{3/2}` has no stiffness at `δ = 0`. A quasi-static particle
/// that the tip pushes outside its friction cone with no adhesion (every force on it then scales
/// with the tip's load) has only the load-free balance `P = 0`: it slides or rolls ahead of the
/// tip, and its rows tend to that root of multiplicity 3/2, where their Jacobian is singular.
/// The integrator cannot follow it there (the step fell below 1e-20 s within microseconds) and
/// the event at `δ = 0` is never crossed. Below `UNLOADED_OVERLAP` the contact carries under
/// `K·δ^{3/2}` ≈ 1e-16 N, so it is broken there, and the push reports what the physics says: the
/// particle left the tip. A dynamic particle is carried by its inertia through such a contact,
/// and any adhesion gives the balance a load of its own: both keep `δ_min`.
pub(super) fn break_overlap(p: &PushParams, layout: &Layout) -> f64 {
    let d_min = p.jkr_ta.min_indentation();
    if unloaded_root(p, layout) {
        d_min.max(UNLOADED_OVERLAP)
    } else {
        d_min
    }
}

/// Whether the tip's push is the only load on the particle and its contact is Hertz: a
/// quasi-static particle, no adhesion at either contact (no attraction at contact, no JKR
/// pull-off, no meniscus). Then every force on the particle scales with the tip's load, and a
/// push outside the friction cones has only the load-free balance.
fn unloaded_root(p: &PushParams, layout: &Layout) -> bool {
    layout.particle_y.vel.is_none()
        && p.jkr_ta.min_indentation() >= 0.0
        && p.adhesion_as() == 0.0
        && p.adhesion_ta() == 0.0
}

/// The overlap (m) below which the tip's contact with a quasi-static particle carries no load
/// (see [`PushModel::break_overlap`]): 1 fm, the integrator's position resolution at the
/// prediction's tolerance (`atol` 1e-6 on a 1 nm scale) and 10⁴ times below the 0.01 nm a push
/// starts with.
pub const UNLOADED_OVERLAP: f64 = 1e-15;

/// Which switch fired.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SwitchKind {
    /// Particle-substrate stick ↔ slip.
    Substrate,
    /// Tip-particle stick ↔ slip.
    Tip,
    /// Meniscus formation / rupture.
    Meniscus,
    /// Tip-particle contact make / break.
    TipContact,
}

fn sign(v: f64) -> f64 {
    if v < 0.0 { -1.0 } else { 1.0 }
}
