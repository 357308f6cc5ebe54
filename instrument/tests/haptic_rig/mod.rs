//! The whole bilateral loop in one process, tick by tick, for the grid test and the
//! `haptic_region` benchmark: the simulated handle and hand with the bridge's device cycle, the
//! server's law and the simulated instrument, joined as the iceoryx2 link joins them (each side
//! sees the other's newest sample, one tick late), at `per_tick` device cycles per 1 ms tick,
//! optionally with the pauses of a loaded machine ([`Stalls`]): a server that stalls catches up
//! with its missed ticks back to back, a bridge that stalls skips its cycles (the simulated
//! handle, integrated per cycle, stands still meanwhile; the motor holds its force).

use nanopush_haptic::bridge::{Bridge, BridgeConfig, CycleRow, Link};
use nanopush_haptic::device::{Device, DeviceError, DeviceSample, DeviceSpec, LinkView};
use nanopush_haptic::operator::Script;
use nanopush_haptic::sim::SimDevice;
use nanopush_instrument::afm::Afm;
use nanopush_instrument::control::bilateral::{Bilateral, Input, Phase};
use nanopush_instrument::scene::Scene;
use nanopush_proto::haptic::{ForceFeedback, HapticState};

/// The link: the newest sample each way.
#[derive(Default)]
struct Wire {
    state: Option<HapticState>,
    force: Option<ForceFeedback>,
}

impl Link for Wire {
    fn publish(&mut self, s: &HapticState) {
        self.state = Some(*s);
    }
    fn newest(&mut self) -> Option<ForceFeedback> {
        self.force.take()
    }
}

/// Pauses of a loaded machine: each millisecond, the server (the bridge) stalls for 2-6 ms with
/// probability `server` (`bridge`), from a xorshift generator seeded with `seed`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Stalls {
    /// Probability per ms that the server stalls.
    pub server: f64,
    /// Probability per ms that the bridge stalls.
    pub bridge: f64,
    /// Seed (not 0).
    pub seed: u64,
}

impl Stalls {
    /// No pauses.
    pub const NONE: Stalls = Stalls {
        server: 0.0,
        bridge: 0.0,
        seed: 1,
    };
}

/// Plays `script` at `nm_per_mm` and `pull_off_n` (set as a `scale` request sets them) with the
/// paper scene, the device at `per_tick` cycles per tick, until the script ends or `max_ticks`
/// ticks: the rows of the device cycles from the engagement on (the law at full force), and the
/// law as it ended.
pub fn closed_loop(
    script: Script,
    nm_per_mm: f64,
    pull_off_n: f64,
    per_tick: u32,
    max_ticks: u64,
) -> (Vec<CycleRow>, Bilateral) {
    closed_loop_with(script, nm_per_mm, pull_off_n, per_tick, max_ticks, Stalls::NONE)
}

/// The simulated handle declaring another damping limit in its specification, as a serial device's info
/// packet may declare it (`None`: the simulated device's own).
#[allow(dead_code)] // used by the grid test, not by the benchmark
pub struct Declared {
    /// The simulated handle and hand.
    pub sim: SimDevice,
    /// The largest damping it declares (N·s/m).
    pub max_damping: Option<f64>,
}

impl Device for Declared {
    fn spec(&self) -> DeviceSpec {
        let own = self.sim.spec();
        DeviceSpec {
            max_damping: self.max_damping.unwrap_or(own.max_damping),
            ..own
        }
    }
    fn read(&mut self, dt: f64) -> Result<DeviceSample, DeviceError> {
        self.sim.read(dt)
    }
    fn write_force(&mut self, force: f64) -> Result<(), DeviceError> {
        self.sim.write_force(force)
    }
    fn observe(&mut self, link: &LinkView) {
        self.sim.observe(link)
    }
    fn finished(&self) -> bool {
        self.sim.finished()
    }
    fn holding(&self) -> bool {
        self.sim.holding()
    }
    fn may_drop_force_when_paused(&self) -> bool {
        self.sim.may_drop_force_when_paused()
    }
}

/// [`closed_loop`] with the pauses `stalls` (the bridge's server time-out at 100 ms, as the
/// end-to-end tests run it, so that a server's pause is not a lost link).
pub fn closed_loop_with(
    script: Script,
    nm_per_mm: f64,
    pull_off_n: f64,
    per_tick: u32,
    max_ticks: u64,
    stalls: Stalls,
) -> (Vec<CycleRow>, Bilateral) {
    let ddt = 1e-3 / f64::from(per_tick);
    let device = Declared {
        sim: SimDevice::new(script, ddt),
        max_damping: None,
    };
    closed_loop_on(device, nm_per_mm, pull_off_n, per_tick, max_ticks, stalls)
}

/// [`closed_loop_with`] on `device` (serviced every `1 ms / per_tick`).
pub fn closed_loop_on(
    device: Declared,
    nm_per_mm: f64,
    pull_off_n: f64,
    per_tick: u32,
    max_ticks: u64,
    stalls: Stalls,
) -> (Vec<CycleRow>, Bilateral) {
    let mut rng = stalls.seed.max(1);
    let mut uniform = move || {
        rng ^= rng << 13;
        rng ^= rng >> 7;
        rng ^= rng << 17;
        (rng % 1_000_000) as f64 * 1e-6
    };
    let dt = 1e-3;
    let scene = Scene::default_scene();
    let mut afm = Afm::from_scene(&scene, 20e-6, 20e-6, dt);
    let mut law = Bilateral::new(scene.bilateral_params(dt));
    law.rescale(
        Some(nm_per_mm * 1e-6),
        Some(pull_off_n / scene.tip_sample().adhesion()),
        None,
    );
    let ddt = dt / f64::from(per_tick);
    let cfg = BridgeConfig {
        rate_hz: 1.0 / ddt,
        stale_ns: if stalls == Stalls::NONE {
            BridgeConfig::default().stale_ns
        } else {
            100_000_000
        },
        ..BridgeConfig::default()
    };
    let mut bridge = Bridge::new(device, cfg, 0);
    let mut wire = Wire::default();
    let mut reading = afm.read();
    law.engage(reading.stage);
    let mut rows = Vec::new();
    let mut engaged = false;
    let (mut server_stall, mut bridge_stall, mut due) = (0u32, 0u32, 0u32);
    let mut pause = |p: f64, left: &mut u32| {
        if *left == 0 && p > 0.0 && uniform() < p {
            *left = 2 + (uniform() * 5.0) as u32;
        }
        let paused = *left > 0;
        *left = left.saturating_sub(1);
        paused
    };
    for n in 0..max_ticks {
        let now = (n + 1) * 1_000_000;
        due += 1;
        if !pause(stalls.server, &mut server_stall) {
            // The ticks missed in a stall are made up back to back.
            for _ in 0..std::mem::take(&mut due) {
                let o = law.tick(&Input {
                    handle: wire.state,
                    stage: reading.stage,
                    volts: reading.volts,
                    pushing: false,
                });
                reading = afm.step(o.target.unwrap_or(reading.stage)).expect("the free tip steps");
                wire.force = Some(ForceFeedback {
                    seq: n,
                    time_ns: now,
                    ..o.feedback
                });
                engaged |= law.phase() == Phase::Engaged;
            }
        }
        if pause(stalls.bridge, &mut bridge_stall) {
            continue;
        }
        for c in 0..u64::from(per_tick) {
            let row = bridge.cycle(now + 30_000 + c * 1_000_000 / u64::from(per_tick), &mut wire);
            if engaged {
                rows.push(row);
            }
        }
        if bridge.device.sim.operator.finished() {
            break;
        }
    }
    (rows, law)
}
