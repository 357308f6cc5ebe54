//! The Eq 17 right-hand side, written once generic over [`Real`] (evaluated on `f64` for the
//! dynamics and on dual numbers for its exact Jacobian), in the order the physics goes:
//! 1. [`Kinematics`]: the stage, the cantilever's deflection, the particle, and the line of
//!    centres from the tip to the particle;
//! 2. [`TipContact`]: the tip-particle normal force (JKR, long range, damping) and friction
//!    (Eq 7), as a force on the particle;
//! 3. [`SubstrateContact`]: the particle-substrate forces and friction (Eq 6), and the stage's
//!    acceleration under the friction load (Eq 13);
//! 4. the state derivative: cantilever, particle (y, z, θ) and stage rows.

use super::{Mode, Probe, PushModel, Tangential};
use crate::numerics::dual::Real;
use crate::physics::pushing::layout::{MAX_STATES, Slot};

/// Positions and rates of one state, and the tip-particle geometry.
struct Kinematics<T> {
    /// Stage travel `s` and its rate.
    s: T,
    s_dot: T,
    /// Cantilever deflection in its own axes, and its rates.
    zy: T,
    zz: T,
    zy_d: T,
    zz_d: T,
    /// Particle y, z, rotation θ, and their rates.
    y: T,
    y_d: T,
    z: T,
    z_d: T,
    th: T,
    om: T,
    /// Tip-to-particle centre offset, its length and unit normal and tangent.
    dy: T,
    dz: T,
    dist: T,
    normal: (T, T),
    tangent: (T, T),
    /// Tip velocity (y, z).
    tip_v: (T, T),
    /// Surface gap `dist − (Rₜ + Rₐ)`.
    gap: T,
}

/// The tip-particle contact, as forces on the particle.
struct TipContact<T> {
    normal_ta: T,
    friction_ta: T,
    load_ta: T,
    /// The tip's tangential coordinate `ξ = (Rₜ+Rₐ)φ + Rₐθ` and its rate.
    xi: T,
    xi_d: T,
    /// The force on the particle (y, z).
    on_particle: (T, T),
}

/// The particle-substrate contact and the stage it loads.
struct SubstrateContact<T> {
    lr_as: T,
    elastic_as: T,
    load_as: T,
    contact_as: T,
    slip_rate_as: T,
    friction_as: T,
    stage_accel: T,
}

impl PushModel {
    /// The state derivative (scaled as [`PushModel::mass_diagonal`] says) and the contact
    /// quantities at `(t, x)` in `mode`.
    pub(super) fn eval<T: Real>(&self, t: T, x: &[T], mode: &Mode) -> ([T; MAX_STATES], Probe<T>) {
        let k = self.kinematics(t, x);
        let tc = self.tip_contact(&k, mode);
        let sc = self.substrate_contact(t, &k, &tc, mode);
        let f = self.derivative(&k, &tc, &sc);
        let probe = Probe {
            gap: k.gap,
            normal_ta: tc.normal_ta,
            friction_ta: tc.friction_ta,
            load_ta: tc.load_ta,
            friction_as: sc.friction_as,
            load_as: sc.load_as,
            contact_as: sc.contact_as,
            contact_ta: tc.xi,
            slip_rate_as: sc.slip_rate_as,
            slip_rate_ta: tc.xi_d,
            zeta_z: k.zz,
            zeta_y: k.zy,
            stage: k.s,
            stage_accel: sc.stage_accel,
        };
        (f, probe)
    }

    /// Phase 1: the state's positions and rates, the tip centre `base + R(α)ζ` with
    /// `y' = (cos α, −sin α)`, `z' = (sin α, cos α)`, and the line of centres.
    #[inline]
    fn kinematics<T: Real>(&self, t: T, x: &[T]) -> Kinematics<T> {
        let p = &self.p;
        let l = &self.layout;
        let zero = T::cst(0.0);
        let vel = |s: Option<usize>| s.map_or(zero, |i| x[i]);

        // Stage (Eq 13, or ideal at speed V).
        let (s, s_dot) = match l.stage {
            Some(st) => (x[st.pos], vel(st.vel)),
            None => (self.drive.y(t), T::cst(self.drive.vy)),
        };
        let (zy, zz) = (x[l.zeta_y.pos], x[l.zeta_z.pos]);
        let (zy_d, zz_d) = (vel(l.zeta_y.vel), vel(l.zeta_z.vel));
        let y = x[l.particle_y.pos];
        let y_d = vel(l.particle_y.vel);
        let (z, z_d) = match l.particle_z {
            Some(sl) => (x[sl.pos], vel(sl.vel)),
            None => (T::cst(self.z_fixed), zero),
        };
        let (th, om) = match l.rotation {
            Some(sl) => (x[sl.pos], vel(sl.vel)),
            None => (zero, zero),
        };

        let (sa, ca) = self.rot;
        let tip_y = s + self.base.0 + zy * ca + zz * sa;
        let tip_z = self.drive.z(t) + self.base.1 - zy * sa + zz * ca;
        let tip_vy = s_dot + zy_d * ca + zz_d * sa;
        let tip_vz = -(zy_d * sa) + zz_d * ca + self.drive.vz;
        let pa_z = z + (p.r_a + p.interactions.a0);

        // Line of centres, tip → particle.
        let dy = y - tip_y;
        let dz = pa_z - tip_z;
        let dist = (dy * dy + dz * dz).sqrt();
        let (ny, nz) = (dy / dist, dz / dist);
        Kinematics {
            s,
            s_dot,
            zy,
            zz,
            zy_d,
            zz_d,
            y,
            y_d,
            z,
            z_d,
            th,
            om,
            dy,
            dz,
            dist,
            normal: (ny, nz),
            tangent: (-nz, ny),
            tip_v: (tip_vy, tip_vz),
            gap: dist - (p.r_t + p.r_a),
        }
    }

    /// Phase 2: the tip-particle normal force (positive pushes the particle along n) and
    /// friction, Eq 7.
    #[inline]
    fn tip_contact<T: Real>(&self, k: &Kinematics<T>, mode: &Mode) -> TipContact<T> {
        let p = &self.p;
        let a0 = p.interactions.a0;
        let zero = T::cst(0.0);
        let rsum = p.r_t + p.r_a;
        let gap = k.gap;
        let elastic_ta = if mode.tip_contact {
            p.jkr_ta.load_from_indentation(-(gap - a0)).unwrap_or(zero)
        } else {
            zero
        };
        let lr_ta = p.interactions.tip_particle_force(gap, mode.meniscus);
        // Rates: of the gap and of the tip tangential coordinate ξ = (Rₜ+Rₐ)φ + Rₐθ.
        let (rvy, rvz) = (k.y_d - k.tip_v.0, k.z_d - k.tip_v.1);
        let (dy, dz, dist) = (k.dy, k.dz, k.dist);
        let gap_d = (dy * rvy + dz * rvz) / dist;
        // φ in (−3π/2, π/2]: continuous wherever the particle can be, ahead of the tip, under it
        // or behind it (a tip that rolls over the particle passes φ = −π); the cut is straight
        // above the tip, where the particle, resting on the substrate under the tip, never is.
        // At `atan2`'s own cut, ±π, ξ would jump by 2π(Rₜ+Rₐ) and the tip's stick spring with it.
        let phi = dz.atan2(dy);
        let phi = if phi.re() > std::f64::consts::FRAC_PI_2 {
            phi - 2.0 * std::f64::consts::PI
        } else {
            phi
        };
        let xi = phi * rsum + k.th * p.r_a;
        let phi_d = (dy * rvz - dz * rvy) / (dist * dist);
        let xi_d = phi_d * rsum + k.om * p.r_a;
        // Contact damping along the normal while in contact (every contact dissipates).
        let damping_ta = if mode.tip_contact { gap_d * p.b_ta } else { zero };
        let normal_ta = elastic_ta + lr_ta - damping_ta;
        // Eq 7: f_ta ≤ μ_ta (A_ta + F_l^ta). The external load F_l = elastic + long-range and the
        // adhesion A_ta = −long-range − P_c (JKR pull-off): the long-range part cancels.
        let load_ta = if mode.tip_contact {
            (elastic_ta - p.jkr_ta.pull_off_load()).max_c(0.0)
        } else {
            zero
        };
        let friction_ta = if mode.tip_contact {
            match mode.tip {
                Tangential::Stick { anchor } => -((xi - anchor) * p.k_ta_t) - xi_d * p.b_ta,
                Tangential::Slip { direction } => -(load_ta * (direction * p.mu_ta_k)),
            }
        } else {
            zero
        };
        // ∂ξ/∂p_a = (Rₜ+Rₐ)/dist · t.
        let lever = T::cst(rsum) / dist;
        let ((ny, nz), (ty, tz)) = (k.normal, k.tangent);
        TipContact {
            normal_ta,
            friction_ta,
            load_ta,
            xi,
            xi_d,
            on_particle: (
                normal_ta * ny + friction_ta * lever * ty,
                normal_ta * nz + friction_ta * lever * tz,
            ),
        }
    }

    /// Phase 3: the particle-substrate contact, Eq 6 (its load is the tip's downward push on
    /// the particle), and the stage (Eq 13), which carries the friction load `−f_as`.
    #[inline]
    fn substrate_contact<T: Real>(
        &self,
        t: T,
        k: &Kinematics<T>,
        tc: &TipContact<T>,
        mode: &Mode,
    ) -> SubstrateContact<T> {
        let p = &self.p;
        let zero = T::cst(0.0);
        let gap_as = k.z + p.interactions.a0;
        let lr_as = p.interactions.particle_substrate_force(gap_as);
        let elastic_as = p.jkr_as.load_from_indentation(-k.z).unwrap_or(zero);
        let load_as = (-tc.on_particle.1 + self.adhesion_as).max_c(0.0);
        let contact_as = k.y - k.th * p.r_a;
        let slip_rate_as = k.y_d - k.om * p.r_a;
        let friction_as = match mode.substrate {
            Tangential::Stick { anchor } => -((contact_as - anchor) * p.k_as_t) - slip_rate_as * p.b_as,
            Tangential::Slip { direction } => -(load_as * (direction * p.mu_as_k)),
        };
        let stage_accel = match self.layout.stage {
            Some(_) => {
                let w = p.stage.omega();
                (self.drive.y(t) + friction_as / p.stage.stiffness() - k.s) * (w * w) - k.s_dot * (w / p.stage.q_y)
            }
            None => zero,
        };
        SubstrateContact {
            lr_as,
            elastic_as,
            load_as,
            contact_as,
            slip_rate_as,
            friction_as,
            stage_accel,
        }
    }

    /// Phase 4: the state derivative. Cantilever `m ζ̈ + b ζ̇ + Kζ = R(α)ᵀ F_tip` with
    /// `F_tip = −F_on_particle`; the particle's y with the frame's fictitious force when the
    /// stage accelerates, its z and rotation; the stage.
    #[inline]
    fn derivative<T: Real>(&self, k: &Kinematics<T>, tc: &TipContact<T>, sc: &SubstrateContact<T>) -> [T; MAX_STATES] {
        let p = &self.p;
        let l = &self.layout;
        let zero = T::cst(0.0);
        let mut f = [zero; MAX_STATES];
        let mut put = |slot: Slot, force: T, mass: f64, scale: f64, rate: T| match slot.vel {
            Some(v) => {
                f[slot.pos] = rate;
                f[v] = force / mass;
            }
            None => f[slot.pos] = force / scale,
        };

        let (sa, ca) = self.rot;
        let (fpa_y, fpa_z) = tc.on_particle;
        let (ftip_y, ftip_z) = (-fpa_y, -fpa_z);
        let fp_y = ftip_y * ca - ftip_z * sa;
        let fp_z = ftip_y * sa + ftip_z * ca;
        let (k11, k12, k22) = self.k;
        let damp = |r: T| if l.zeta_y.vel.is_some() { r * self.b_c } else { zero };
        let kc = p.cantilever.k_c;
        let (zy, zz) = (k.zy, k.zz);
        put(
            l.zeta_y,
            fp_y - zy * k11 - zz * k12 - damp(k.zy_d),
            self.m_c,
            kc,
            k.zy_d,
        );
        put(
            l.zeta_z,
            fp_z - zy * k12 - zz * k22 - damp(k.zz_d),
            self.m_c,
            kc,
            k.zz_d,
        );

        put(
            l.particle_y,
            fpa_y + sc.friction_as + sc.stage_accel * p.m_a,
            p.m_a,
            p.k_as_t,
            k.y_d,
        );
        if let Some(sl) = l.particle_z {
            let damping = if sl.vel.is_some() { k.z_d * p.b_as } else { zero };
            put(sl, sc.elastic_as + sc.lr_as + fpa_z - damping, p.m_a, p.k_as_t, k.z_d);
        }
        if let Some(sl) = l.rotation {
            let torque = (tc.friction_ta - sc.friction_as) * p.r_a;
            put(sl, torque, self.p.inertia(), p.k_as_t * p.r_a * p.r_a, k.om);
        }
        if let Some(st) = l.stage {
            f[st.pos] = k.s_dot;
            if let Some(v) = st.vel {
                f[v] = sc.stage_accel;
            }
        }
        f
    }
}
