//! The haptic link's state and counters: atomics written by the control loop and the
//! supervisor, read by `/api/status`, `/metrics` and telemetry.

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering::Relaxed};

use nanopush_proto::haptic::region::Limit;
use nanopush_proto::haptic::{HapticState, monotonic_ns};
use nanopush_proto::ws::HapticScales;

use nanopush_instrument::control::bilateral::{BilateralParams, Coupling};

use super::link::LINK_UP;
use crate::histogram::Histogram;

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
    /// The raw port's energy since the force went live (J), f64 bits.
    pub raw_port_energy: AtomicU64,
    /// The most the environment can give back at the hand (J), f64 bits: `½ F² / K` with `F`
    /// the pull-off at the hand in force and `K` the felt stiffness.
    pub stored_energy_bound: AtomicU64,
    /// The scales in force (written by the loop every tick).
    pub scales: ScaleAtomics,
    /// Times energy bounding lowered the force scale.
    pub energy_bounds: AtomicU64,
    /// The scales the last accepted `scale` asked for (nm/mm, pull-off at the hand in N), which
    /// the loop may not have taken yet: the next `scale`'s `ok` builds on them.
    pub asked_scales: std::sync::Mutex<Option<(f64, f64)>>,
}

/// The scales of haptic z-control in force, f64 bits, and why they differ from those asked.
#[derive(Debug, Default)]
pub struct ScaleAtomics {
    /// Tip nm per handle mm.
    pub nm_per_mm: AtomicU64,
    /// Pull-off felt at the hand in force (N).
    pub pull_off_at_hand_n: AtomicU64,
    /// Pull-off asked (N).
    pub asked_pull_off_at_hand_n: AtomicU64,
    /// Felt contact stiffness in force (N/m).
    pub felt_stiffness: AtomicU64,
    /// The renderable region's edge (N/m); 0 before a device is known.
    pub max_stiffness: AtomicU64,
    /// The round-trip delay the region is computed for (s).
    pub delay_s: AtomicU64,
    /// [`nanopush_proto::haptic::region::Limit::code`].
    pub limit: AtomicU64,
}

impl ScaleAtomics {
    /// The scales as the `ok` of a `scale`, `/api/status` and telemetry show them.
    pub fn snapshot(&self) -> HapticScales {
        let limit = Limit::from_code(self.limit.load(Relaxed) as u32);
        let k_max = f(&self.max_stiffness);
        HapticScales {
            nm_per_mm: f(&self.nm_per_mm),
            pull_off_at_hand_n: f(&self.pull_off_at_hand_n),
            asked_pull_off_at_hand_n: f(&self.asked_pull_off_at_hand_n),
            felt_stiffness_n_per_m: f(&self.felt_stiffness),
            max_stiffness_n_per_m: (k_max > 0.0).then_some(k_max),
            delay_s: f(&self.delay_s),
            limit: limit.name().into(),
            reason: (limit != Limit::None).then(|| limit.reason().into()),
        }
    }
}

/// Names of the bilateral phases, in [`nanopush_instrument::control::bilateral::Phase`] order.
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

    /// Whether the handle's values are live: a sample has come and the link is up. Once it is
    /// down they are unknown (the bridge may be dead and the device hold what it last had).
    pub fn live(&self) -> bool {
        self.samples.load(Relaxed) > 0 && self.link_name() == "up"
    }

    /// Force at the hand (N) while [`HapticMetrics::live`], NaN (unknown) otherwise.
    pub fn live_force_n(&self) -> f64 {
        if self.live() { self.force_n() } else { f64::NAN }
    }

    /// Handle position (m) while [`HapticMetrics::live`], NaN (unknown) otherwise.
    pub fn live_handle_m(&self) -> f64 {
        if self.live() { self.handle_m() } else { f64::NAN }
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

    /// The raw port's energy (J).
    pub fn raw_port_energy(&self) -> f64 {
        f(&self.raw_port_energy)
    }

    /// The environment's stored-energy bound at the hand (J).
    pub fn stored_energy_bound(&self) -> f64 {
        f(&self.stored_energy_bound)
    }

    /// The scales in force, the region and energy bounding (called by the loop every tick):
    /// `params` as asked, `c` the coupling of the law.
    pub fn note_scales(&self, p: &BilateralParams, c: &Coupling) {
        let s = &self.scales;
        // Before a device is known nothing is rendered; the scales shown are those asked.
        let g = if c.k_max() > 0.0 { c.force_gain() } else { p.force_gain };
        let felt = g * p.k_z * p.position_gain;
        let pull_off = g * p.adhesion;
        let store = |a: &AtomicU64, v: f64| a.store(v.to_bits(), Relaxed);
        store(&s.nm_per_mm, p.position_gain * 1e-3 / 1e-9);
        store(&s.pull_off_at_hand_n, pull_off);
        store(&s.asked_pull_off_at_hand_n, p.force_gain * p.adhesion);
        store(&s.felt_stiffness, felt);
        store(&s.max_stiffness, c.k_max());
        store(&s.delay_s, c.delay());
        s.limit.store(u64::from(c.limit().code()), Relaxed);
        let bound = if felt > 0.0 {
            0.5 * pull_off * pull_off / felt
        } else {
            0.0
        };
        store(&self.stored_energy_bound, bound);
        self.energy_bounds.store(c.bounds(), Relaxed);
    }

    /// Records a sample from the bridge (called by the loop).
    pub fn sample(&self, s: &HapticState, now_ns: u64) {
        self.samples.fetch_add(1, Relaxed);
        self.last_ns.store(now_ns, Relaxed);
        self.handle_m.store(s.position.to_bits(), Relaxed);
        self.force_n.store(s.force.to_bits(), Relaxed);
        self.pc_damping.store(s.pc_damping.to_bits(), Relaxed);
        self.port_energy.store(s.port_energy.to_bits(), Relaxed);
        self.raw_port_energy.store(s.raw_port_energy.to_bits(), Relaxed);
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
        use nanopush_instrument::control::bilateral::Phase;
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
