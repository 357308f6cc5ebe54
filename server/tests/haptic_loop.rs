//! The whole bilateral loop in one process, tick by tick, without processes or clocks: the
//! simulated handle and operator and the bridge's device cycle (`nanopush_haptic`), the server's
//! haptic z-control law (`nanopush::control::bilateral`) and the simulated instrument, joined as
//! the iceoryx2 link joins them — each side sees the other's newest sample, one tick late.
//!
//! It shows what the passivity controller is for: at twice the default force scale (the scene's
//! pull-off felt as 2 N, the contact as a 2.9 kN/m spring, above the 2 kN/m the simulated device
//! renders) a hand with a medium grip (4 N·s/m) makes the sampled contact chatter without the
//! controller and rest on the surface with it; in free motion the controller adds no damping.

use nanopush::control::bilateral::{Bilateral, Input, Phase};
use nanopush::instrument::Afm;
use nanopush::scene::Scene;
use nanopush_haptic::bridge::{Bridge, BridgeConfig, CycleRow, Link};
use nanopush_haptic::operator::Script;
use nanopush_haptic::sim::SimDevice;
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

/// The press at twice the force scale with a medium grip: without the controller the handle
/// chatters on the surface (it leaves and re-touches it tens of times) and the loop generates
/// millijoules; with it, the hand rests on the surface and the observed energy stays within
/// the controller's damping cap of zero (−20 µJ).
#[test]
fn a_force_scale_that_chatters_without_the_passivity_controller_rests_with_it() {
    let ticks = 14_000;
    let off = run("press", false, 2.0, 4.0, ticks);
    let on = run("press", true, 2.0, 4.0, ticks);
    let e = on.engaged_at.expect("engaged");
    assert_eq!(off.engaged_at, Some(e), "the two runs engage alike");
    // The press holds for 1 s once the hand feels 0.8 N; look at the second half of the hold.
    let hold = |r: &Run| {
        let i = r.rows[e..]
            .iter()
            .position(|row| row.force >= 0.8)
            .expect("the press reaches 0.8 N")
            + e;
        (i + 500, i + 1000)
    };
    let (a, b) = hold(&on);
    let calm = spread(&on.rows, a, b);
    let (a2, b2) = hold(&off);
    let buzz = spread(&off.rows, a2, b2);
    let e_min = on.rows.iter().map(|r| r.port_energy).fold(f64::INFINITY, f64::min);
    let e_min_off = off.rows.iter().map(|r| r.port_energy).fold(f64::INFINITY, f64::min);
    eprintln!(
        "hold: without the controller the handle spans {:.1} µm, with it {:.2} µm; E_min {e_min_off:.3e} / {e_min:.3e} J",
        buzz * 1e6,
        calm * 1e6
    );
    let touches = |r: &Run| {
        r.rows[e..]
            .windows(2)
            .filter(|w| (w[0].tip_force > 5e-9) != (w[1].tip_force > 5e-9))
            .count()
    };
    eprintln!("contact changes: without {}, with {}", touches(&off), touches(&on));
    assert!(
        buzz > 500e-6,
        "without the controller the contact should chatter: {buzz}"
    );
    assert!(e_min_off < -1e-3, "{e_min_off}");
    assert!(touches(&off) > 3 * touches(&on));
    assert!(calm < 10e-6, "with the controller the hand should rest: {calm}");
    assert!(e_min > -20e-6, "{e_min}");
    // docs/haptics.md's table ("Tests"), to its digits (the run is deterministic): 1565 µm, 90
    // contact changes, −15.3 mJ without the controller; 0.00 µm, 14, −12.5 µJ with it.
    assert!((buzz - 1565e-6).abs() < 0.5e-6, "span {buzz:e}");
    assert!(calm < 0.005e-6, "span {calm:e}");
    assert_eq!((touches(&off), touches(&on)), (90, 14));
    assert!((e_min_off + 15.3e-3).abs() < 0.05e-3, "{e_min_off:e}");
    assert!((e_min + 12.5e-6).abs() < 0.05e-6, "{e_min:e}");
    assert!(on.rows.iter().all(|r| r.force.abs() <= 2.5));
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

/// Contact changes after the engagement and the lowest observed energy of a run.
fn chatter(r: &Run) -> (usize, f64) {
    let e = r.engaged_at.expect("engaged");
    let touches = r.rows[e..]
        .windows(2)
        .filter(|w| (w[0].tip_force > 5e-9) != (w[1].tip_force > 5e-9))
        .count();
    (
        touches,
        r.rows.iter().map(|r| r.port_energy).fold(f64::INFINITY, f64::min),
    )
}

/// The nanoManipulator's local model, measured: with the passivity controller off, at twice the
/// force scale and a 4 kHz device, rendering the server's local linear model between its 1 kHz
/// samples generates a small fraction of the energy that holding its force does, and the contact
/// chatters far less (the full table over rates and scales: `rates_table`, in docs/haptics.md,
/// "Tests").
#[test]
fn the_local_model_makes_a_fast_device_steadier_than_a_held_force() {
    let (t_hold, e_hold) = chatter(&run_at("press", false, false, 4, 2.0, 4.0, 14_000));
    let (t_local, e_local) = chatter(&run_at("press", false, true, 4, 2.0, 4.0, 14_000));
    eprintln!(
        "4 kHz, scale 2, no controller: held force {t_hold} contact changes, E_min {e_hold:.2e} J; local model {t_local}, {e_local:.2e} J"
    );
    assert!(e_local > 0.1 * e_hold, "local {e_local:e} vs held {e_hold:e}");
    assert!(2 * t_local < t_hold, "local {t_local} vs held {t_hold} contact changes");
}

/// docs/haptics.md's table of the local model ("Tests"), cell by cell (deterministic: the simulated
/// hand and instrument have fixed seeds): device rate × rendering × force scale, no controller;
/// contact changes exactly and the lowest port energy to the table's two digits. At ×4 every
/// combination chatters (more than 60 contact changes). Then docs/haptics.md's energy ratios (held
/// force / local model) of the unrounded cells: five- to eightfold at ×1; 2.4×, 47× and 95× at ×2,
/// to their last digit. Printed with `--nocapture`.
#[test]
fn rates_table() {
    // (device cycles per tick, local model, scale) → (contact changes, lowest port energy J).
    type Cell = ((u32, bool, f64), (usize, f64));
    let readme: [Cell; 12] = [
        ((1, false, 1.0), (10, -1.1e-4)),
        ((1, true, 1.0), (4, -2.0e-5)),
        ((1, false, 2.0), (64, -3.6e-2)),
        ((1, true, 2.0), (90, -1.5e-2)),
        ((2, false, 1.0), (6, -5.2e-5)),
        ((2, true, 1.0), (4, -8.9e-6)),
        ((2, false, 2.0), (72, -2.1e-2)),
        ((2, true, 2.0), (26, -4.5e-4)),
        ((4, false, 1.0), (4, -3.3e-5)),
        ((4, true, 1.0), (4, -4.3e-6)),
        ((4, false, 2.0), (82, -1.5e-2)),
        ((4, true, 2.0), (18, -1.6e-4)),
    ];
    println!("| device rate | rendering | force scale | contact changes | lowest port energy (J) |");
    println!("|---|---|---|---|---|");
    let mut energy = std::collections::HashMap::new();
    for per_tick in [1u32, 2, 4] {
        for local in [false, true] {
            for scale in [1.0, 2.0, 4.0] {
                let (t, e) = chatter(&run_at("press", false, local, per_tick, scale, 4.0, 14_000));
                energy.insert((per_tick, local, scale.to_bits()), e);
                let how = if local { "local model" } else { "held force" };
                println!("| {per_tick} kHz | {how} | {scale} | {t} | {e:.2e} |");
                let cell = format!("{per_tick} kHz, {how}, ×{scale}");
                if scale == 4.0 {
                    assert!(t > 60, "{cell} should chatter: {t} contact changes");
                    continue;
                }
                let (_, (t_readme, e_readme)) = readme
                    .iter()
                    .find(|(k, _)| *k == (per_tick, local, scale))
                    .expect("a docs cell");
                assert_eq!(t, *t_readme, "{cell}: contact changes");
                // Two significant digits: within half a unit of the second.
                let unit = 10f64.powf(e_readme.abs().log10().floor() - 1.0);
                assert!(
                    (e - e_readme).abs() <= 0.5 * unit,
                    "{cell}: {e:.3e} J, docs {e_readme:e}"
                );
            }
        }
    }
    // docs/haptics.md's ratios ("Tests"; held force / local model, lowest port energy), from the
    // unrounded cells: five- to eightfold at ×1 at every rate; at ×2, 2.4× (1 kHz), 47× (2 kHz),
    // 95× (4 kHz), each to its last digit.
    let ratio = |per_tick: u32, scale: f64| {
        energy[&(per_tick, false, scale.to_bits())] / energy[&(per_tick, true, scale.to_bits())]
    };
    for per_tick in [1, 2, 4] {
        let r = ratio(per_tick, 1.0);
        println!("{per_tick} kHz ×1: {r:.3}×");
        assert!((5.0..=8.0).contains(&r), "{per_tick} kHz ×1: {r}×");
    }
    for (per_tick, readme, unit) in [(1, 2.4, 0.1), (2, 47.0, 1.0), (4, 95.0, 1.0)] {
        let r = ratio(per_tick, 2.0);
        println!("{per_tick} kHz ×2: {r:.3}×");
        assert!(
            (r - readme).abs() <= 0.5 * unit,
            "{per_tick} kHz ×2: {r}×, docs {readme}×"
        );
    }
}
