//! The whole bilateral loop in one process, tick by tick, without processes or clocks: the
//! simulated handle and operator and the bridge's device cycle (`nanopush_haptic`), the server's
//! haptic z-control law (`nanopush_instrument::control::bilateral`) and the simulated instrument, joined as
//! the iceoryx2 link joins them — each side sees the other's newest sample, one tick late.
//!
//! At twice the default force scale (the contact asked as a 2.9 kN/m spring, above the 2 kN/m the
//! simulated device renders) the renderable region limits the force scale and the hand rests on
//! the surface with the passivity controller off as with it on; in free motion the controller
//! adds no damping. The grid of every accepted setting is `haptic_grid.rs`.

use nanopush_haptic::bridge::{Bridge, BridgeConfig, CycleRow, Link};
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

struct Run {
    rows: Vec<CycleRow>,
    /// Ticks at which the law was fully engaged.
    engaged_at: Option<usize>,
    /// The surface height the law detected and the stage heights, per tick (m).
    contact_z: f64,
    tip_z: Vec<f64>,
}

/// Runs `ticks` ms of the loop: the bridge with `passivity`, the operator playing `script` with
/// a grip of `damping` N·s/m, the force scale multiplied by `scale`.
fn run(script: &str, passivity: bool, scale: f64, damping: f64, ticks: usize) -> Run {
    run_at(script, passivity, true, 1, scale, damping, ticks)
}

/// [`run`] with the device at `per_tick` cycles per server tick, rendering the local model or
/// holding the server's force.
fn run_at(
    script: &str,
    passivity: bool,
    local_model: bool,
    per_tick: u32,
    scale: f64,
    damping: f64,
    ticks: usize,
) -> Run {
    let dt = 1e-3;
    let scene = Scene::default_scene();
    let mut afm = Afm::from_scene(&scene, 20e-6, 20e-6, dt);
    let mut law = Bilateral::new(scene.bilateral_params(dt));
    law.params.force_gain *= scale;
    let ddt = dt / f64::from(per_tick);
    let mut device = SimDevice::new(Script::parse(script).unwrap(), ddt);
    device.operator.damping = damping;
    let cfg = BridgeConfig {
        passivity,
        local_model,
        rate_hz: 1.0 / ddt,
        ..BridgeConfig::default()
    };
    let mut bridge = Bridge::new(device, cfg, 0);
    let mut wire = Wire::default();
    let mut reading = afm.read();
    law.engage(reading.stage);
    let mut out = Run {
        rows: Vec::with_capacity(ticks),
        engaged_at: None,
        contact_z: f64::NAN,
        tip_z: Vec::with_capacity(ticks),
    };
    for n in 0..ticks {
        let now = (n as u64 + 1) * 1_000_000;
        // Server tick: the newest handle sample, the law, the instrument, the force out.
        let o = law.tick(&Input {
            handle: wire.state,
            stage: reading.stage,
            volts: reading.volts,
            pushing: false,
        });
        let target = o.target.unwrap_or(reading.stage);
        reading = afm.step(target).expect("the free tip steps");
        wire.force = Some(ForceFeedback {
            seq: n as u64,
            time_ns: now,
            ..o.feedback
        });
        if law.phase() == Phase::Engaged && out.engaged_at.is_none() {
            out.engaged_at = Some(n);
        }
        // Device cycles; the row of the last one stands for the tick.
        let mut row = None;
        for c in 0..per_tick {
            row = Some(bridge.cycle(
                now + 30_000 + u64::from(c) * (1_000_000 / u64::from(per_tick)),
                &mut wire,
            ));
        }
        out.rows.push(row.expect("at least one cycle"));
        out.tip_z.push(reading.stage[2]);
    }
    out.contact_z = law.contact_z().unwrap_or(f64::NAN);
    out
}

/// Peak-to-peak of the handle over rows `a..b` (m).
fn spread(rows: &[CycleRow], a: usize, b: usize) -> f64 {
    let it = rows[a..b].iter().map(|r| r.handle);
    it.clone().fold(f64::NEG_INFINITY, f64::max) - it.fold(f64::INFINITY, f64::min)
}

/// The press at twice the force scale (the contact felt as 2.9 kN/m) with a medium grip used to
/// chatter without the passivity controller: the scale is past the simulated
/// device's renderable region (2 kN/m at 1 kHz with a tick of delay), so the force scale in
/// force is lowered to its edge, and the hand rests on the surface with the controller off as
/// with it on: the handle spans less than 10 µm in the second half of the hold, the contact
/// changes a handful of times, never more than 2.5 N.
#[test]
fn a_force_scale_past_the_region_is_limited_and_rests_unassisted() {
    for passivity in [false, true] {
        let r = run("press", passivity, 2.0, 4.0, 14_000);
        let e = r.engaged_at.expect("engaged");
        let i = r.rows[e..]
            .iter()
            .position(|row| row.force >= 0.8)
            .expect("the press reaches 0.8 N")
            + e;
        let calm = spread(&r.rows, i + 500, i + 1000);
        let touches = r.rows[e..]
            .windows(2)
            .filter(|w| (w[0].tip_force > 5e-9) != (w[1].tip_force > 5e-9))
            .count();
        eprintln!(
            "controller {passivity}: span {:.2} µm, {touches} contact changes",
            calm * 1e6
        );
        assert!(calm < 10e-6, "controller {passivity}: the hand should rest: {calm}");
        assert!(touches <= 10, "controller {passivity}: {touches} contact changes");
        assert!(r.rows.iter().all(|row| row.force.abs() <= 2.5));
    }
}

/// At the default scale and in free motion (a ±3 mm sine, the tip 100 nm above the surface)
/// the controller never acts: the handle moves exactly as it does with the controller off, and
/// the tip follows the hand by 10 nm/mm.
#[test]
fn in_free_motion_the_passivity_controller_adds_no_damping() {
    let on = run("sine", true, 1.0, 8.0, 8_000);
    let off = run("sine", false, 1.0, 8.0, 8_000);
    let e = on.engaged_at.expect("engaged");
    assert!(on.rows[e..].iter().all(|row| row.pc_damping == 0.0));
    let most = on.rows[e..]
        .iter()
        .zip(&off.rows[e..])
        .map(|(a, b)| (a.handle - b.handle).abs())
        .fold(0.0, f64::max);
    assert_eq!(most, 0.0, "the handle moved differently with the controller on");
    let heights: Vec<f64> = on.tip_z[e..].iter().map(|z| z - on.contact_z).collect();
    let lo = heights.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = heights.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    // ±3 mm of hand is ±30 nm of tip about the parking height (the handle lags the hand a
    // little; the anchor is where the hand was at the engagement).
    assert!(hi - lo > 50e-9 && hi - lo < 62e-9, "tip span {} nm", (hi - lo) * 1e9);
    assert!(lo > 60e-9, "the tip stayed clear of the surface: {} nm", lo * 1e9);
}
