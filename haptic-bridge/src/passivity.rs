//! Time-domain passivity observer and controller at the device's port (Hannaford & Ryu,
//! *Time-domain passivity control of haptic interfaces*, IEEE T-RA 18(1), 2002).
//!
//! The port is the motor's output: the device renders `f` (N, positive up) on the handle,
//! holding it between cycles (a zero-order hold), while the handle moves `Δx`. The hand pushes
//! against that force, so the energy flowing from the operator into the teleoperator over a
//! cycle is exactly `−f[n−1]·Δx[n]`: the force the motor held times the way it was held over.
//! The environment behind the port is the server's local linear model of the tip-sample force
//! at the hand, `F_ref(x)` (the nanoManipulator's approach, stiffness uncapped): continuous and
//! conservative between server samples. The observer counts the energy the *sampled rendering*
//! takes in beyond what that continuous environment would have taken in along the same path:
//!
//! ```text
//! E[n] = E[n−1] − f[n−1]·Δx[n] + W_ref[n]                                (observer)
//! W_ref[n] = ½ (F_ref(x[n−1]) + F_ref(x[n])) Δx[n]     (the model of that interval; exact)
//! α[n] = min(−E[n] / (Δt·v[n]²), α_max)   if E[n] < −ε and |v[n]| ≥ v_min, else 0
//! f[n] = clamp(f_env[n] − α[n]·v[n], ±F_max)                             (controller)
//! ```
//!
//! With `W_ref = 0` this is Hannaford & Ryu's observer of the raw port (their `f[n]·v[n]·Δt`
//! replaced by the held force over the measured displacement, which is what a zero-order-hold
//! motor does, and which counts the controller's own dissipation without a separate term). Why
//! the reference: the tip-sample force has stored energy the raw observer, starting from zero,
//! reads as activity. At the snap-in the adhesion pulls the hand down with ~1 N over ~0.7 mm of
//! handle (about 0.35 mJ at the default scaling, by `½F²/K`): a raw observer goes that far negative and its
//! controller would damp out exactly the snap-in and the pull-off the operator must feel. What
//! the sampled loop adds — a stiff contact rendered with a hold, a stiffness above what the
//! device renders (the bridge caps it; the reference does not), a force that lags the hand — is
//! the difference between the rendered and the modelled work, and that is what `E` counts: when
//! it goes negative a variable damper `α` dissipates the deficit over the next cycle, and only
//! then; in free motion and for a well-rendered model it adds nothing. The guards: `ε` = 1 nJ
//! (rounding and sensor noise, far below anything a hand feels), no damping at `|v| < v_min`
//! (the division would blow up, and a handle at rest takes no energy), and `α ≤ α_max`, below the
//! damping the device renders stably; a deficit it cannot dissipate at once is carried on.
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
    /// The raw port's energy `−Σ f[n−1]·Δx[n]` (J), no model subtracted.
    raw: f64,
    /// The force rendered in the previous cycle, held over the displacement now measured (N).
    f_prev: f64,
    /// Largest damping (N·s/m).
    pub alpha_max: f64,
    /// Speed below which no damping is applied (m/s).
    pub v_min: f64,
    /// Whether the controller acts (the observer always runs).
    pub enabled: bool,
}

/// Energy deficit below which the controller does not act (J): rounding and noise.
pub const DEFICIT_FLOOR: f64 = 1e-9;

/// One cycle's result.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PassivityOutput {
    /// The force to render (N).
    pub force: f64,
    /// The damping applied this cycle (N·s/m).
    pub damping: f64,
    /// Observed energy after this cycle's dissipation (J).
    pub energy: f64,
    /// The raw port's energy since the last reset (J): `−Σ f[n−1]·Δx[n]`.
    pub raw_energy: f64,
}

impl Passivity {
    /// A controller with damping capped at `alpha_max` (N·s/m) and the velocity guard `v_min`
    /// (m/s); 0.1 mm/s suits a handle read to ~1 µm at 1 kHz.
    pub fn new(alpha_max: f64, v_min: f64) -> Passivity {
        Passivity {
            energy: 0.0,
            raw: 0.0,
            f_prev: 0.0,
            alpha_max,
            v_min,
            enabled: true,
        }
    }

    /// Forgets the energy (a new server or an engagement starts a new port history).
    pub fn reset(&mut self) {
        self.energy = 0.0;
        self.raw = 0.0;
        self.f_prev = 0.0;
    }

    /// One cycle of length `dt` (s) over which the handle moved `dx` (m) under the force of the
    /// previous cycle and now moves at `v` (m/s): the rendering asks for `force` (N) for the next
    /// cycle; `w_ref` (J) is the work the environment's continuous model did on the handle over
    /// the step that ended (0 to observe the raw port); `max_force` (N) is the motor's limit.
    /// Non-finite inputs render no force and leave the energy untouched.
    pub fn step(&mut self, force: f64, dx: f64, v: f64, dt: f64, w_ref: f64, max_force: f64) -> PassivityOutput {
        let finite = force.is_finite() && dx.is_finite() && v.is_finite() && w_ref.is_finite();
        if !(finite && dt.is_finite() && dt > 0.0) {
            self.f_prev = 0.0;
            return PassivityOutput {
                force: 0.0,
                damping: 0.0,
                energy: self.energy,
                raw_energy: self.raw,
            };
        }
        self.energy += -self.f_prev * dx + w_ref;
        self.raw -= self.f_prev * dx;
        let alpha = if self.enabled && self.energy < -DEFICIT_FLOOR && v.abs() >= self.v_min {
            (-self.energy / (dt * v * v)).min(self.alpha_max)
        } else {
            0.0
        };
        let out = crate::device::clamp_force(force - alpha * v, max_force);
        self.f_prev = out;
        PassivityOutput {
            force: out,
            damping: alpha,
            energy: self.energy,
            raw_energy: self.raw,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A virtual spring `f = −k x` rendered with a hold and seen at the raw port (no
    /// reference): the observer sees the spring's stored `k x²/2` less the classic sampled-data
    /// leak `k Δx²/2` per cycle (Colgate: a held spring is slightly active), and the controller
    /// dissipates no more than that leak.
    #[test]
    fn a_held_spring_at_the_raw_port_stores_its_energy_less_the_sampling_leak() {
        let (k, dt) = (200.0, 1e-4);
        let mut pc = Passivity::new(50.0, 1e-4);
        let (mut x_prev, mut leak, mut dissipated) = (0.0, 0.0, 0.0);
        for n in 0..20_000 {
            let t = n as f64 * dt;
            let x = 0.01 * (t * 2.0).sin();
            let v = 0.02 * (t * 2.0).cos();
            let dx = x - x_prev;
            x_prev = x;
            let out = pc.step(-k * x, dx, v, dt, 0.0, 1e9);
            leak += 0.5 * k * dx * dx;
            dissipated += out.damping * v * v * dt;
            let stored = 0.5 * k * x * x;
            assert!(
                (out.energy - stored).abs() < 1e-5,
                "t {t}: E {} stored {stored}",
                out.energy
            );
        }
        assert!(
            dissipated <= 2.0 * leak + 1e-9,
            "dissipated {dissipated:e} J, leak {leak:e} J"
        );
    }

    /// A constant force rendered exactly as its model says (an adhesion pulling the hand) is
    /// not activity once the model's work is the reference: no damping, the energy holds; at the
    /// raw port the same force is read as active and damped away.
    #[test]
    fn a_modelled_force_is_not_damped_but_the_raw_port_would_damp_it() {
        let (f, dt, v) = (-1.0, 1e-3, -0.004);
        let mut with_ref = Passivity::new(50.0, 1e-4);
        let mut raw = Passivity::new(50.0, 1e-4);
        for i in 0..200 {
            let a = with_ref.step(f, v * dt, v, dt, f * v * dt, 1e9);
            assert_eq!(a.damping, 0.0);
            assert!(a.energy >= 0.0);
            let b = raw.step(f, v * dt, v, dt, 0.0, 1e9);
            assert!(b.damping > 0.0 || i == 0, "step {i}");
        }
    }

    /// An active element (a negative damper, `f = +b v`, which feeds energy to the hand) is
    /// caught after the first cycle it acts in and cancelled: the controller's damping equals
    /// the element's, the rendered force vanishes and the energy stops falling.
    #[test]
    fn an_active_element_is_damped_exactly() {
        let (b, dt) = (3.0, 1e-3);
        let mut pc = Passivity::new(100.0, 1e-4);
        for n in 0..1000 {
            let v = 0.01 + 1e-5 * n as f64;
            let out = pc.step(b * v, v * dt, v, dt, 0.0, 1e9);
            // Each cycle's power gets through before it is seen, and is taken out in the next:
            // the deficit stays at one cycle's worth, `b v² Δt`.
            assert!(out.energy >= -1.01 * b * v * v * dt, "energy {}", out.energy);
            if n > 0 {
                assert!((out.damping - b).abs() < 0.01 * b, "α {} at n {n}", out.damping);
                assert!(out.force.abs() < 0.01 * b * v, "force {} at n {n}", out.force);
            }
        }
    }

    /// The guards: no damping at rest (no division by ~0), never above the cap, a deficit
    /// beyond the cap carried to the next cycles, nothing below the 1 nJ floor.
    #[test]
    fn guards_hold_at_rest_and_at_the_cap() {
        let dt = 1e-3;
        let mut pc = Passivity::new(10.0, 1e-4);
        // A 5 N force pushing the hand along its motion: a deficit of 50 µJ per cycle.
        pc.step(5.0, 0.01 * dt, 0.01, dt, 0.0, 1e9);
        let out = pc.step(5.0, 0.01 * dt, 0.01, dt, 0.0, 1e9);
        assert_eq!(out.damping, 10.0, "capped");
        assert!(out.energy < -4e-5);
        // The handle stops: no damping, the deficit is carried.
        let rest = pc.step(5.0, 0.0, 0.0, dt, 0.0, 1e9);
        assert_eq!((rest.damping, rest.force), (0.0, 5.0));
        assert_eq!(rest.energy, out.energy - out.force * 0.0);
        let tiny = pc.step(5.0, 1e-6 * dt, 1e-6, dt, 0.0, 1e9);
        assert_eq!(tiny.damping, 0.0);
        // A deficit below the floor is left alone.
        let mut small = Passivity::new(10.0, 1e-4);
        small.step(5e-5, 0.01 * dt, 0.01, dt, 0.0, 1e9);
        let s = small.step(5e-5, 0.01 * dt, 0.01, dt, 0.0, 1e9);
        assert!(s.energy < 0.0 && s.energy > -DEFICIT_FLOOR);
        assert_eq!(s.damping, 0.0);
        // A disabled controller observes but does not act.
        let mut off = Passivity::new(10.0, 1e-4);
        off.enabled = false;
        off.step(5.0, 0.01 * dt, 0.01, dt, 0.0, 1e9);
        let o = off.step(5.0, 0.01 * dt, 0.01, dt, 0.0, 1e9);
        assert_eq!((o.damping, o.force), (0.0, 5.0));
        assert!(o.energy < 0.0);
        // Non-finite input renders nothing.
        assert_eq!(pc.step(f64::NAN, 0.01 * dt, 0.01, dt, 0.0, 1e9).force, 0.0);
        assert_eq!(pc.step(1.0, f64::INFINITY, f64::INFINITY, dt, 0.0, 1e9).force, 0.0);
        assert_eq!(pc.step(1.0, 0.01 * dt, 0.01, dt, f64::NAN, 1e9).force, 0.0);
    }

    /// docs/haptics.md, "Passivity": a deficit is dissipated "only when `E < −1 nJ`, never at
    /// `|v| < 0.1 mm/s`": just past each edge the controller acts, just short of it not.
    #[test]
    fn damping_starts_past_the_deficit_floor_and_the_speed_guard() {
        assert_eq!(DEFICIT_FLOOR, 1e-9);
        let dt = 1e-3;
        // A force held over a 10 µm step along it: a deficit of force × 10 µm.
        let deficit = |f: f64, v: f64| {
            let mut pc = Passivity::new(1e3, 1e-4);
            pc.step(f, 0.0, v, dt, 0.0, 1e9);
            pc.step(f, 1e-5, v, dt, 0.0, 1e9)
        };
        let past = deficit(1.1e-4, 0.01);
        assert!((past.energy + 1.1e-9).abs() < 1e-15 && past.damping > 0.0, "{past:?}");
        let short = deficit(0.9e-4, 0.01);
        assert!(
            (short.energy + 0.9e-9).abs() < 1e-15 && short.damping == 0.0,
            "{short:?}"
        );
        // A 1 µJ deficit: damped at 0.101 mm/s, not at 0.099 mm/s.
        assert!(deficit(0.1, 1.01e-4).damping > 0.0);
        assert_eq!(deficit(0.1, 0.99e-4).damping, 0.0);
    }
}
