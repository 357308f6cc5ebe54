//! The haptic link's state and counters: atomics written by the control loop and the
//! supervisor, read by `/api/status`, `/metrics` and telemetry.

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering::Relaxed};

use nanopush_proto::haptic::{HapticState, monotonic_ns};

use super::link::LINK_UP;
use crate::serve::histogram::Histogram;

/// The haptic link's state, written by the control loop (and the supervisor), read by the
/// status route, the metrics route and the telemetry task. Floats are stored as bits.
#[derive(Debug, Default)]
pub struct HapticMetrics {
    /// `LINK_*`.
    pub link: AtomicU64,
    /// Device code of the bridge (`nanopush_proto::haptic::DEVICE_*`).
    pub device: AtomicU64,
    /// The bridge's process id.
    pub pid: AtomicU64,
    /// Index of the bilateral phase in [`PHASES`].
    pub phase: AtomicU64,
    /// Handle position (m), f64 bits.
    pub handle_m: AtomicU64,
    /// Force rendered at the hand (N), f64 bits (from the bridge's newest sample).
    pub force_n: AtomicU64,
    /// Tip force `k_z ζ_z` from the measured deflection (N), f64 bits.
    pub tip_force_n: AtomicU64,
    /// Passivity damping now (N·s/m), f64 bits.
    pub pc_damping: AtomicU64,
    /// Observed port energy (J), f64 bits.
    pub port_energy: AtomicU64,
    /// Samples with the passivity controller acting.
    pub pc_active_samples: AtomicU64,
    /// `monotonic_ns` of the last sample with the controller acting.
    pub pc_last_ns: AtomicU64,
    /// Bridge restarts by the supervisor.
    pub restarts: AtomicU64,
    /// Device samples the bridge dropped (its count).
    pub dropped_samples: AtomicU64,
    /// Samples the server rejected (not finite, out of range).
    pub rejected_samples: AtomicU64,
    /// Times the link went down.
    pub link_downs: AtomicU64,
    /// Times the link came up.
    pub link_ups: AtomicU64,
    /// Age of the newest sample when the link last went down (ns).
    pub last_down_age_ns: AtomicU64,
    /// The tip's height above the detected surface (m), f64 bits; NaN before an approach.
    pub tip_z_m: AtomicU64,
    /// The last fault of haptic z-control ([`FAULTS`] index; 0: none).
    pub fault: AtomicU64,
    /// Samples received.
    pub samples: AtomicU64,
    /// `monotonic_ns` of the last sample (0: never).
    pub last_ns: AtomicU64,
    /// End-to-end latency the bridge measured (device sample → force back at the device), s.
    pub latency: Histogram,
    /// Whether a mode other than `none` runs.
    pub enabled: AtomicBool,
    /// The bridge's device cycle rate (Hz), f64 bits.
    pub rate_hz: AtomicU64,
    /// The device's faults as the bridge counted them ([`nanopush_proto::haptic::DeviceFaults::KINDS`] order).
    pub device_faults: [AtomicU64; 8],
    /// A bridge has told its device's counters (a sample, or a lost device's state).
    pub device_noted: AtomicBool,
}

/// Names of the bilateral phases, in [`crate::control::bilateral::Phase`] order.
pub const PHASES: [&str; 10] = [
    "off",
    "approach",
    "park",
    "settle",
    "ramp",
    "engaged",
    "clutched",
    "pushing",
    "link_lost",
    "retract",
];

/// Names of the faults in [`HapticMetrics::fault`].
pub const FAULTS: [&str; 3] = ["none", "no_surface", "second_server"];

/// The index of a phase name in [`PHASES`].
pub fn phase_index(name: &str) -> u64 {
    PHASES.iter().position(|p| *p == name).unwrap_or(0) as u64
}

fn f(bits: &AtomicU64) -> f64 {
    f64::from_bits(bits.load(Relaxed))
}

impl HapticMetrics {
    /// `up`, `down` or `off`.
    pub fn link_name(&self) -> &'static str {
        if !self.enabled.load(Relaxed) {
            return "off";
        }
        match self.link.load(Relaxed) {
            LINK_UP => "up",
            _ => "down",
        }
    }

    /// The phase's name.
    pub fn phase_name(&self) -> &'static str {
        PHASES[(self.phase.load(Relaxed) as usize).min(PHASES.len() - 1)]
    }

    /// The tip's height above the detected surface (m).
    pub fn tip_z_m(&self) -> f64 {
        f(&self.tip_z_m)
    }

    /// The last fault's name (`none` when there was none).
    pub fn fault_name(&self) -> &'static str {
        FAULTS[(self.fault.load(Relaxed) as usize).min(FAULTS.len() - 1)]
    }

    /// Tip force (N).
    pub fn tip_force_n(&self) -> f64 {
        f(&self.tip_force_n)
    }

    /// Handle position (m).
    pub fn handle_m(&self) -> f64 {
        f(&self.handle_m)
    }

    /// Force at the hand (N).
    pub fn force_n(&self) -> f64 {
        f(&self.force_n)
    }

    /// Passivity damping (N·s/m).
    pub fn pc_damping(&self) -> f64 {
        f(&self.pc_damping)
    }

    /// Observed port energy (J).
    pub fn port_energy(&self) -> f64 {
        f(&self.port_energy)
    }

    /// Whether the passivity controller acted within the last 100 ms.
    pub fn pc_active(&self) -> bool {
        let last = self.pc_last_ns.load(Relaxed);
        last != 0 && monotonic_ns().saturating_sub(last) < 100_000_000
    }

    /// The bridge's device counters and rate from `s` (also from a state that carries no handle
    /// sample: a lost device).
    pub fn note_device(&self, s: &HapticState) {
        self.device.store(u64::from(s.device), Relaxed);
        self.pid.store(u64::from(s.pid), Relaxed);
        self.rate_hz.store(s.rate_hz.to_bits(), Relaxed);
        for (slot, v) in self.device_faults.iter().zip(s.faults.counts()) {
            slot.store(v, Relaxed);
        }
        self.device_noted.store(true, Relaxed);
    }

    /// Records a sample from the bridge (called by the loop).
    pub fn sample(&self, s: &HapticState, now_ns: u64) {
        self.samples.fetch_add(1, Relaxed);
        self.last_ns.store(now_ns, Relaxed);
        self.handle_m.store(s.position.to_bits(), Relaxed);
        self.force_n.store(s.force.to_bits(), Relaxed);
        self.pc_damping.store(s.pc_damping.to_bits(), Relaxed);
        self.port_energy.store(s.port_energy.to_bits(), Relaxed);
        self.dropped_samples.store(s.dropped, Relaxed);
        self.note_device(s);
        if s.pc_damping > 0.0 {
            self.pc_active_samples.fetch_add(1, Relaxed);
            self.pc_last_ns.store(now_ns, Relaxed);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn phase_names_match_the_law() {
        use crate::control::bilateral::Phase;
        for p in [
            Phase::Off,
            Phase::Approach,
            Phase::Park,
            Phase::Settle { small: 0 },
            Phase::Ramp { gain: 0.0 },
            Phase::Engaged,
            Phase::Clutched,
            Phase::Pushing,
            Phase::LinkLost,
            Phase::Retract,
        ] {
            assert_eq!(PHASES[phase_index(p.name()) as usize], p.name());
        }
    }
}
