//! The 1-DOF haptic device behind one trait, as CHAI3D's `cGenericHapticDevice` does: open (a
//! constructor per backend, chosen by `--device` as a [`DeviceKind`]), read the handle, write a force, know the limits.
//!
//! Sign conventions, SI, for every backend: the handle position is in metres, positive **up**
//! (the tip's height follows it); the force is in newtons, positive **up** (a repulsive tip force,
//! the tip pressed on the surface, pushes the hand up). A backend converts its own units at the
//! edge (encoder counts, motor current).

use std::fmt;

/// What a device can do, read once when it is opened.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DeviceSpec {
    /// Short name for status and logs (`sim`, `serial`, `none`).
    pub name: &'static str,
    /// Largest force the motor renders (N): the bridge never commands more.
    pub max_force: f64,
    /// Travel of the handle (m): `[min, max]`, 0 at the centre.
    pub travel: [f64; 2],
    /// Largest damping the device renders stably at its rate (N·s/m): the passivity
    /// controller's damping stays below it.
    pub max_damping: f64,
    /// Largest stiffness the device renders stably at its rate (N/m): a local linear model's
    /// stiffness is capped at it (Colgate: `b > K T / 2`).
    pub max_stiffness: f64,
    /// The rate the limits above are declared for (Hz): with `max_stiffness` it fixes the
    /// port damping the renderable region is computed from
    /// (`nanopush_proto::haptic::region::port_damping`).
    pub spec_rate_hz: f64,
}

/// One reading of the handle.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct DeviceSample {
    /// Handle position (m), positive up.
    pub position: f64,
    /// Handle velocity (m/s), positive up.
    pub velocity: f64,
    /// Buttons: bit 0 the engage button, bit 1 the clutch (held: the tip stays where it is while
    /// the hand re-centres).
    pub buttons: u32,
}

pub use nanopush_proto::haptic::{BUTTON_CLUTCH, BUTTON_ENGAGE, DeviceFaults};

/// Why a device failed.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum DeviceError {
    /// The `--device` text names no backend, or its argument is wrong.
    #[error("--device {given:?}: {why}; allowed: sim, none, serial:PATH")]
    BadSpec {
        /// What was given.
        given: String,
        /// What is wrong with it.
        why: String,
    },
    /// The device could not be opened or talked to.
    #[error("{device}: {source}")]
    Io {
        /// Which device.
        device: String,
        /// The cause.
        source: std::io::Error,
    },
    /// The device answered with something that is not a valid packet.
    #[error("{device}: {why}")]
    Protocol {
        /// Which device.
        device: String,
        /// What was wrong.
        why: String,
    },
    /// The device is gone: it hung up, the port fails with an I/O error, or its path vanished
    /// (an unplugged cable). Nothing more can be sent; the bridge reopens it by its path.
    #[error("{device}: lost ({why})")]
    Lost {
        /// Which device.
        device: String,
        /// What the system said.
        why: String,
    },
    /// The device has not answered within its time-out.
    #[error("{device}: no answer for {ms} ms")]
    Silent {
        /// Which device.
        device: String,
        /// How long (ms).
        ms: u64,
    },
}

/// A 1-DOF haptic device. One call of [`Device::read`] and one of [`Device::write_force`] per
/// device cycle, in that order; the force holds until the next write.
pub trait Device: Send {
    /// What it can do.
    fn spec(&self) -> DeviceSpec;
    /// The handle now. `dt` is the cycle period (s): a simulated device advances its physics by
    /// it; a real one ignores it.
    fn read(&mut self, dt: f64) -> Result<DeviceSample, DeviceError>;
    /// Renders `force` (N, positive up) until the next call. The caller has clamped it to
    /// [`DeviceSpec::max_force`]; a backend clamps again (defence in depth).
    fn write_force(&mut self, force: f64) -> Result<(), DeviceError>;
    /// What the link tells the person holding the device (used by the simulated operator, who
    /// starts a script once forces are live); real devices ignore it.
    fn observe(&mut self, _link: &LinkView) {}
    /// Whether a finite script has ended (the simulated operator); real devices never end.
    fn finished(&self) -> bool {
        false
    }
    /// Whether the hand holds the tip in contact (the simulated operator's hold, for the
    /// tip-force bound); real devices cannot tell.
    fn holding(&self) -> bool {
        false
    }
    /// Whether the device may have dropped its force while the bridge was paused (a watchdog
    /// that zeroes it when the host falls silent): after such a pause the bridge ramps the force
    /// in from zero. A device that holds its force through any pause says `false`, and the
    /// bridge resumes at the force of the moment (a dip and a ramp would be active: the force
    /// pushing back a handle the hand pressed in meanwhile).
    fn may_drop_force_when_paused(&self) -> bool {
        true
    }
    /// Zeroes the force and lets the device go. Called once, at the end; a backend also
    /// zeroes its force when dropped.
    fn close(&mut self) -> Result<(), DeviceError> {
        self.write_force(0.0)
    }
    /// The fastest cycle rate the device and its link carry (Hz), when they limit it.
    fn max_rate_hz(&self) -> Option<f64> {
        None
    }
    /// The control rate the device declares (Hz), when it declares one.
    fn declared_rate_hz(&self) -> Option<f64> {
        None
    }
    /// What the device and its link counted so far (the device side of [`DeviceFaults`]).
    fn faults(&self) -> DeviceFaults {
        DeviceFaults::default()
    }
}

impl Device for Box<dyn Device> {
    fn spec(&self) -> DeviceSpec {
        (**self).spec()
    }
    fn read(&mut self, dt: f64) -> Result<DeviceSample, DeviceError> {
        (**self).read(dt)
    }
    fn write_force(&mut self, force: f64) -> Result<(), DeviceError> {
        (**self).write_force(force)
    }
    fn observe(&mut self, link: &LinkView) {
        (**self).observe(link)
    }
    fn holding(&self) -> bool {
        (**self).holding()
    }
    fn may_drop_force_when_paused(&self) -> bool {
        (**self).may_drop_force_when_paused()
    }
    fn finished(&self) -> bool {
        (**self).finished()
    }
    fn close(&mut self) -> Result<(), DeviceError> {
        (**self).close()
    }
    fn max_rate_hz(&self) -> Option<f64> {
        (**self).max_rate_hz()
    }
    fn declared_rate_hz(&self) -> Option<f64> {
        (**self).declared_rate_hz()
    }
    fn faults(&self) -> DeviceFaults {
        (**self).faults()
    }
}

/// What the bridge knows of the server, for [`Device::observe`].
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct LinkView {
    /// Time since the bridge started (s).
    pub t: f64,
    /// A server is live (a force sample within the stale limit).
    pub up: bool,
    /// Haptic z-control is engaged and its force ramp has finished.
    pub engaged: bool,
    /// The tip's height above the detected substrate (m), NaN when unknown.
    pub tip_z: f64,
}

/// `--device` as parsed: which backend, with its argument.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum DeviceKind {
    /// The simulated handle and operator.
    Sim,
    /// A serial device at this path.
    Serial(String),
    /// No device: the bridge publishes nothing.
    None,
}

impl fmt::Display for DeviceKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            DeviceKind::Sim => f.write_str("sim"),
            DeviceKind::Serial(p) => write!(f, "serial:{p}"),
            DeviceKind::None => f.write_str("none"),
        }
    }
}

impl std::str::FromStr for DeviceKind {
    type Err = DeviceError;
    fn from_str(s: &str) -> Result<DeviceKind, DeviceError> {
        let bad = |why: &str| DeviceError::BadSpec {
            given: s.to_string(),
            why: why.to_string(),
        };
        match s {
            "sim" => Ok(DeviceKind::Sim),
            "none" => Ok(DeviceKind::None),
            _ => match s.strip_prefix("serial:") {
                Some("") => Err(bad("the serial device needs a path, e.g. serial:/dev/ttyACM0")),
                Some(path) => Ok(DeviceKind::Serial(path.to_string())),
                None => Err(bad("unknown device")),
            },
        }
    }
}

/// Clamps `force` to `±max` and renders NaN as no force: the last line of defence before a motor.
pub fn clamp_force(force: f64, max: f64) -> f64 {
    if force.is_nan() { 0.0 } else { force.clamp(-max, max) }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn device_kinds_parse_and_name_what_is_wrong() {
        assert_eq!("sim".parse::<DeviceKind>().unwrap(), DeviceKind::Sim);
        assert_eq!("none".parse::<DeviceKind>().unwrap(), DeviceKind::None);
        assert_eq!(
            "serial:/dev/ttyACM0".parse::<DeviceKind>().unwrap(),
            DeviceKind::Serial("/dev/ttyACM0".into())
        );
        let e = "serial:".parse::<DeviceKind>().unwrap_err().to_string();
        assert!(
            e.contains("needs a path") && e.contains("allowed: sim, none, serial:PATH"),
            "{e}"
        );
        let e = "phantom".parse::<DeviceKind>().unwrap_err().to_string();
        assert!(e.contains("\"phantom\"") && e.contains("unknown device"), "{e}");
    }

    #[test]
    fn the_force_clamp_holds_whatever_it_is_given() {
        assert_eq!(clamp_force(5.0, 2.0), 2.0);
        assert_eq!(clamp_force(-5.0, 2.0), -2.0);
        assert_eq!(clamp_force(f64::NAN, 2.0), 0.0);
        assert_eq!(clamp_force(f64::INFINITY, 2.0), 2.0);
        assert_eq!(clamp_force(0.5, 2.0), 0.5);
    }
}
