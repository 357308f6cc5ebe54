//! The simulated device (`--device sim`): a 1-DOF handle held by the simulated
//! [operator](crate::operator), so the whole haptic loop runs headless.
//!
//! The handle is a mass on a capstan drive with viscous and Coulomb friction, hard stops at its
//! travel and a motor that saturates:
//!
//! ```text
//! m ẍ = F_motor + F_hand(x, ẋ, t) − b ẋ − F_c sign(ẋ)      (|ẋ| > 0, or when the other forces
//!                                                           overcome F_c; else the handle sticks)
//! F_motor = clamp(F_cmd, ±F_max)                             held between device cycles
//! ```
//!
//! The physics is continuous, the controller is sampled: each device cycle integrates the handle
//! in [`SUBSTEPS`] semi-implicit Euler steps with the motor force held (a zero-order hold, as a
//! real amplifier holds its current between servo updates), so a sampled loop that is too stiff
//! goes unstable here the way it would on hardware. Values are those of a Hapkit-class desktop
//! device: 50 g at the handle, 2.5 N, ±40 mm.

use crate::device::{Device, DeviceError, DeviceSample, DeviceSpec, LinkView, clamp_force};
use crate::operator::{Operator, Script};

/// Integration steps per device cycle.
pub const SUBSTEPS: u32 = 20;

/// The handle's physical parameters.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Handle {
    /// Moving mass at the handle (kg).
    pub mass: f64,
    /// Viscous friction (N·s/m).
    pub viscous: f64,
    /// Coulomb friction (N).
    pub coulomb: f64,
    /// Motor force limit (N).
    pub max_force: f64,
    /// Travel (m).
    pub travel: [f64; 2],
}

impl Default for Handle {
    fn default() -> Handle {
        Handle {
            mass: 0.05,
            viscous: 0.05,
            coulomb: 0.02,
            max_force: 2.5,
            travel: [-0.04, 0.04],
        }
    }
}

/// The simulated handle and operator.
#[derive(Debug, Clone)]
pub struct SimDevice {
    /// The handle.
    pub handle: Handle,
    /// The hand.
    pub operator: Operator,
    /// Cycle period the spec's limits are computed for (s).
    period: f64,
    x: f64,
    v: f64,
    force: f64,
    t: f64,
    link: LinkView,
}

impl SimDevice {
    /// A handle at the centre of its travel, held by a hand playing `script`, serviced every
    /// `period` seconds.
    pub fn new(script: Script, period: f64) -> SimDevice {
        SimDevice {
            handle: Handle::default(),
            operator: Operator::new(script, 0.0),
            period,
            x: 0.0,
            v: 0.0,
            force: 0.0,
            t: 0.0,
            link: LinkView::default(),
        }
    }

    /// The motor force held now (N).
    pub fn motor_force(&self) -> f64 {
        self.force
    }

    /// Advances the handle by `dt` with the motor force held.
    fn integrate(&mut self, dt: f64) {
        let h = self.handle;
        let n = SUBSTEPS;
        let ds = dt / f64::from(n);
        for _ in 0..n {
            let other = self.force + self.operator.force(self.x, self.v) - h.viscous * self.v;
            if self.v == 0.0 && other.abs() <= h.coulomb {
                continue; // static friction holds the handle
            }
            let dir = if self.v != 0.0 { self.v.signum() } else { other.signum() };
            let v1 = self.v + ds / h.mass * (other - h.coulomb * dir);
            // Kinetic friction stops the handle; it does not reverse it.
            self.v = if v1 * dir < 0.0 { 0.0 } else { v1 };
            self.x += ds * self.v;
            if self.x <= h.travel[0] || self.x >= h.travel[1] {
                self.x = self.x.clamp(h.travel[0], h.travel[1]);
                self.v = 0.0;
            }
        }
    }
}

impl Device for SimDevice {
    fn spec(&self) -> DeviceSpec {
        DeviceSpec {
            name: "sim",
            max_force: self.handle.max_force,
            travel: self.handle.travel,
            // A damper rendered with a zero-order hold on the bare handle is stable below
            // 2m/T; keep a factor of two.
            max_damping: self.handle.mass / self.period,
            // What a hand-held Hapkit-class handle renders at 1 kHz in practice (the bare
            // handle alone, by Colgate's `b > KT/2` with its own 0.05 N·s/m, only ~100 N/m;
            // the hand's damping and the passivity controller carry the rest).
            max_stiffness: 2000.0,
            spec_rate_hz: 1000.0,
        }
    }

    fn read(&mut self, dt: f64) -> Result<DeviceSample, DeviceError> {
        self.operator.update(self.t, dt, self.link.engaged, self.force);
        self.integrate(dt);
        self.t += dt;
        Ok(DeviceSample {
            position: self.x,
            velocity: self.v,
            buttons: 0,
        })
    }

    fn write_force(&mut self, force: f64) -> Result<(), DeviceError> {
        self.force = clamp_force(force, self.handle.max_force);
        Ok(())
    }

    fn observe(&mut self, link: &LinkView) {
        self.link = *link;
    }

    fn finished(&self) -> bool {
        self.operator.finished()
    }

    fn holding(&self) -> bool {
        self.operator.holding()
    }

    /// The simulated motor holds its force through any pause of the bridge, and the handle,
    /// integrated cycle by cycle, stands still meanwhile.
    fn may_drop_force_when_paused(&self) -> bool {
        false
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// With no force and the hand holding, the handle stays put; with a constant motor force it
    /// settles where the hand's spring balances it (F / k_h away), within Coulomb friction.
    #[test]
    fn the_handle_settles_where_the_hand_balances_the_motor() {
        let dt = 1e-3;
        let mut d = SimDevice::new(Script::Hold, dt);
        for _ in 0..1000 {
            let s = d.read(dt).unwrap();
            assert_eq!(s.position, 0.0);
        }
        d.write_force(1.0).unwrap();
        let mut s = DeviceSample::default();
        for _ in 0..3000 {
            s = d.read(dt).unwrap();
        }
        let expect = 1.0 / d.operator.stiffness;
        let tol = d.handle.coulomb / d.operator.stiffness + 1e-6;
        assert!((s.position - expect).abs() <= tol, "{} vs {expect}", s.position);
        assert!(s.velocity.abs() < 1e-4);
    }

    #[test]
    fn the_motor_saturates_and_the_stops_hold() {
        let dt = 1e-3;
        let mut d = SimDevice::new(Script::Hold, dt);
        d.operator.stiffness = 0.0;
        d.operator.damping = 0.0;
        d.write_force(100.0).unwrap();
        assert_eq!(d.motor_force(), d.handle.max_force);
        d.write_force(f64::NAN).unwrap();
        assert_eq!(d.motor_force(), 0.0);
        d.write_force(-100.0).unwrap();
        let mut s = DeviceSample::default();
        for _ in 0..2000 {
            s = d.read(dt).unwrap();
        }
        assert_eq!(s.position, d.handle.travel[0]);
        assert_eq!(s.velocity, 0.0);
    }

    /// Free motion: the hand's spring-damper with the handle's mass is a damped oscillator; a
    /// step of the set point is followed with the damping ratio
    /// `ζ = (b_h + b) / (2 √(k_h m))`, so no overshoot beyond what ζ allows.
    #[test]
    fn the_hand_follows_a_sine_in_free_motion() {
        let dt = 1e-3;
        let mut d = SimDevice::new(Script::parse("sine").unwrap(), dt);
        let mut worst: f64 = 0.0;
        for _ in 0..4000 {
            let s = d.read(dt).unwrap();
            worst = worst.max((s.position - d.operator.set_point()).abs());
        }
        // At 0.5 Hz the hand lags its set point by far less than a millimetre.
        assert!(worst < 1e-4, "{worst}");
    }
}
