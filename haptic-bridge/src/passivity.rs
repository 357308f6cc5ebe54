//! Time-domain passivity observer and controller at the device's port (Hannaford & Ryu,
//! *Time-domain passivity control of haptic interfaces*, IEEE T-RA 18(1), 2002).
//!
//! The port is the motor's output: the device renders `f` (N, positive up) on the handle that
//! moves at `v` (m/s, positive up). The hand pushes against that force, so the power flowing
//! from the operator into the teleoperator is `−f·v`. The environment behind the port is the
//! server's local linear model of the tip-sample force at the hand, `F_ref(x)` (the
//! nanoManipulator's approach): a continuous, conservative field between server updates. The
//! observer counts the energy the *sampled rendering* takes in beyond what that continuous
//! environment would have taken in along the same path, `W_ref = ∫ F_ref dx` (exact, by the
//! trapezoid rule, for a linear model):
//!
//! ```text
//! E[n] = E[n−1] + Δt·(−f[n]·v[n]) + W_ref[n] + D[n−1]                  (observer)
//! W_ref[n] = ½ (F_ref(x[n−1]) + F_ref(x[n])) (x[n] − x[n−1])
//! α[n] = min(−E[n] / (Δt·v[n]²), α_max)   if E[n] < 0 and |v[n]| ≥ v_min, else 0
//! f_out[n] = clamp(f[n] − α[n]·v[n], ±F_max)                           (controller)
//! D[n] = Δt·(f[n] − f_out[n])·v[n]
//! ```
//!
//! `D` is the energy the controller actually dissipated, `Δt·α·v²` in Hannaford & Ryu's form
//! when the motor does not saturate; counting what the saturated motor really rendered keeps the
//! observer honest when the clamp eats part of the damping.
//!
//! With `W_ref = 0` this is Hannaford & Ryu's observer of the raw port. Why the reference: the
//! tip-sample force has stored energy the raw observer, starting from zero, reads as activity.
//! At the snap-in the adhesion pulls the hand down with ~1 N over ~0.7 mm of handle (0.35 mJ at
//! the default scaling): a raw observer goes 350 µJ negative and its controller would damp out
//! exactly the snap-in and the pull-off the operator must feel. What the sampled loop adds — a
//! stiff contact rendered with a zero-order hold, a held force that lags the hand — is the
//! difference between the rendered and the modelled work, and that is what `E` counts: when it
//! goes negative a variable damper `α` dissipates exactly the deficit in the same cycle, and only
//! then; in free motion and for a well-rendered model (`E ≥ 0`) it adds nothing. The guards: no
//! damping at `|v| < v_min` (the division would blow up, and a handle at rest takes no energy),
//! and `α ≤ α_max`, below the damping the device renders stably; a deficit it cannot dissipate at
//! once is carried to the next cycles.
//!
//! Why here, at the bridge, and not in the server loop: only the bridge sees the force actually
//! rendered (the local model is evaluated at the device's own rate, up to 4 kHz) together with
//! the velocity it acts on, which is what the observer must integrate. The bridge reports `α` and
//! `E` in every `HapticState`; the server shows them (`pc_active`, `/metrics`).

/// The observer and controller of one port.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Passivity {
    /// Observed energy `E[n]` (J), before this cycle's dissipation.
    energy: f64,
    /// Energy the controller dissipated in the previous cycle, `D[n−1]` (J).
    dissipated: f64,
    /// Largest damping (N·s/m).
    pub alpha_max: f64,
    /// Speed below which no damping is applied (m/s).
    pub v_min: f64,
    /// Whether the controller acts (the observer always runs).
    pub enabled: bool,
}

/// One cycle's result.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PassivityOutput {
    /// The force to render (N).
    pub force: f64,
    /// The damping applied this cycle (N·s/m).
    pub damping: f64,
    /// Observed energy after this cycle's dissipation (J).
    pub energy: f64,
}

impl Passivity {
    /// A controller with damping capped at `alpha_max` (N·s/m) and the velocity guard `v_min`
    /// (m/s); 0.1 mm/s suits a handle read to ~1 µm at 1 kHz.
    pub fn new(alpha_max: f64, v_min: f64) -> Passivity {
        Passivity {
            energy: 0.0,
            dissipated: 0.0,
            alpha_max,
            v_min,
            enabled: true,
        }
    }

    /// Forgets the energy (a new server or an engagement starts a new port history).
    pub fn reset(&mut self) {
        self.energy = 0.0;
        self.dissipated = 0.0;
    }

    /// One cycle of length `dt` (s): the rendering asks for `force` (N) with the handle at
    /// velocity `v` (m/s); `w_ref` (J) is the work the environment's continuous model did on
    /// the handle over the same step (0 to observe the raw port); `max_force` (N) is the motor's
    /// limit. Non-finite inputs render no force and leave the energy untouched.
    pub fn step(&mut self, force: f64, v: f64, dt: f64, w_ref: f64, max_force: f64) -> PassivityOutput {
        if !(force.is_finite() && v.is_finite() && dt.is_finite() && dt > 0.0 && w_ref.is_finite()) {
            return PassivityOutput {
                force: 0.0,
                damping: 0.0,
                energy: self.energy,
            };
        }
        self.energy += dt * (-force * v) + w_ref + self.dissipated;
        let alpha = if self.enabled && self.energy < 0.0 && v.abs() >= self.v_min {
            (-self.energy / (dt * v * v)).min(self.alpha_max)
        } else {
            0.0
        };
        let out = crate::device::clamp_force(force - alpha * v, max_force);
        self.dissipated = dt * (force - out) * v;
        PassivityOutput {
            force: out,
            damping: alpha,
            energy: self.energy + self.dissipated,
        }
    }

    /// Observed energy before the last cycle's dissipation, `E[n]` (J).
    pub fn observed(&self) -> f64 {
        self.energy
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A virtual spring `f = −k x` seen at the raw port (no reference): the energy the
    /// observer sees is the spring's stored `k x²/2` (to the rectangle rule's error), and the
    /// controller adds nothing but that error's worth near `x = 0` (< 10⁻³ N·s/m, against the
    /// hand's 8 N·s/m).
    #[test]
    fn a_spring_at_the_raw_port_stores_its_energy_and_gets_no_damping() {
        let (k, dt) = (200.0, 1e-4);
        let mut pc = Passivity::new(50.0, 1e-4);
        let mut max_alpha: f64 = 0.0;
        for n in 0..20_000 {
            let t = n as f64 * dt;
            let x = 0.01 * (t * 2.0).sin();
            let v = 0.02 * (t * 2.0).cos();
            let out = pc.step(-k * x, v, dt, 0.0, 1e9);
            max_alpha = max_alpha.max(out.damping);
            let stored = 0.5 * k * x * x;
            assert!((out.energy - stored).abs() < 2e-5, "t {t}: E {} stored {stored}", out.energy);
        }
        assert!(max_alpha < 1e-3, "{max_alpha}");
    }

    /// A constant force rendered exactly as its model says (an adhesion pulling the hand) is
    /// not activity once the model's work is the reference: no damping, energy stays 0; at the
    /// raw port the same force is read as active and damped away.
    #[test]
    fn a_modelled_force_is_not_damped_but_the_raw_port_would_damp_it() {
        let (f, dt, v) = (-1.0, 1e-3, -0.004);
        let mut with_ref = Passivity::new(50.0, 1e-4);
        let mut raw = Passivity::new(50.0, 1e-4);
        for _ in 0..200 {
            let a = with_ref.step(f, v, dt, f * v * dt, 1e9);
            assert_eq!(a.damping, 0.0);
            assert!(a.energy.abs() < 1e-15);
            let b = raw.step(f, v, dt, 0.0, 1e9);
            assert!(b.damping > 0.0);
        }
    }

    /// An active element (a negative damper, `f = +b v`, which feeds energy to the hand) is
    /// caught in the first cycle and cancelled exactly: the output damping equals the element's.
    #[test]
    fn an_active_element_is_damped_exactly() {
        let (b, dt) = (3.0, 1e-3);
        let mut pc = Passivity::new(100.0, 1e-4);
        for n in 0..1000 {
            let v = 0.01 + 1e-5 * n as f64;
            let out = pc.step(b * v, v, dt, 0.0, 1e9);
            assert!(out.energy >= -1e-15, "energy {}", out.energy);
            assert!((out.damping - b).abs() < 1e-9 || n == 0, "α {} at n {n}", out.damping);
            assert!(out.force.abs() < 1e-9 || n == 0);
        }
    }

    /// The guards: no damping at rest (no division by ~0), never above the cap, and a deficit
    /// beyond the cap carried to the next cycles.
    #[test]
    fn guards_hold_at_rest_and_at_the_cap() {
        let dt = 1e-3;
        let mut pc = Passivity::new(10.0, 1e-4);
        // An energy deficit built while moving, then the handle stops.
        let out = pc.step(5.0, 0.01, dt, 0.0, 1e9);
        assert_eq!(out.damping, 10.0);
        assert!(out.energy < 0.0);
        let rest = pc.step(5.0, 0.0, dt, 0.0, 1e9);
        assert_eq!(rest.damping, 0.0);
        assert_eq!(rest.force, 5.0);
        let tiny = pc.step(5.0, 1e-6, dt, 0.0, 1e9);
        assert_eq!(tiny.damping, 0.0);
        // A disabled controller observes but does not act.
        let mut off = Passivity::new(10.0, 1e-4);
        off.enabled = false;
        let o = off.step(5.0, 0.01, dt, 0.0, 1e9);
        assert_eq!((o.damping, o.force), (0.0, 5.0));
        assert!(o.energy < 0.0);
        // Non-finite input renders nothing.
        assert_eq!(pc.step(f64::NAN, 0.01, dt, 0.0, 1e9).force, 0.0);
        assert_eq!(pc.step(1.0, f64::INFINITY, dt, 0.0, 1e9).force, 0.0);
        assert_eq!(pc.step(1.0, 0.01, dt, f64::NAN, 1e9).force, 0.0);
    }
}
