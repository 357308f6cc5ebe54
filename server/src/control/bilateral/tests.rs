//! The bilateral law against the simulated instrument (the paper's scene, tip over bare
//! substrate): engagement, position and force scaling, limits, clutch, lost link, pushes.

use super::*;
use crate::instrument::Afm;
use crate::scene::Scene;

const UM: f64 = 1e-6;

struct Rig {
    afm: Afm,
    law: Bilateral,
    stage: [f64; 3],
    volts: f64,
    handle: HapticState,
    link: bool,
    pushing: bool,
    last: Option<Output>,
}

impl Rig {
    fn new() -> Rig {
        let scene = Scene::default_scene();
        let mut afm = Afm::from_scene(&scene, 20.0 * UM, 20.0 * UM, 1e-3);
        let r = afm.read();
        Rig {
            afm,
            law: Bilateral::new(scene.bilateral_params(1e-3)),
            stage: r.stage,
            volts: r.volts,
            handle: HapticState {
                max_force: 2.5,
                ..Default::default()
            },
            link: true,
            pushing: false,
            last: None,
        }
    }

    fn tick(&mut self) -> Output {
        self.handle.seq += 1;
        let out = self.law.tick(&Input {
            handle: self.link.then_some(self.handle),
            stage: self.stage,
            volts: self.volts,
            pushing: self.pushing,
        });
        let target = out.target.unwrap_or(self.stage);
        let r = self.afm.step(target).expect("the free tip always steps");
        self.stage = r.stage;
        self.volts = r.volts;
        self.last = Some(out);
        out
    }

    /// Ticks until `done` or `limit` ticks; returns the ticks taken.
    fn until(&mut self, limit: u32, mut done: impl FnMut(&Rig) -> bool) -> u32 {
        for n in 0..limit {
            if done(self) {
                return n;
            }
            self.tick();
        }
        panic!("not reached in {limit} ticks: phase {:?}", self.law.phase());
    }

    fn engaged(&mut self) {
        let stage = self.stage;
        self.law.engage(stage);
        self.until(20_000, |r| r.law.phase() == Phase::Engaged);
    }
}

#[test]
fn engaging_finds_the_surface_parks_and_ramps_the_force_in() {
    let mut rig = Rig::new();
    let start = rig.stage[2];
    rig.law.engage(rig.stage);
    assert_eq!(rig.law.phase(), Phase::Approach);
    rig.until(10_000, |r| r.law.phase() == Phase::Park);
    let zc = rig.law.contact_z().unwrap();
    // The paper's tip starts 3 µm above the substrate and snaps in a few nm above it.
    assert!(
        (start - zc - 3.0 * UM).abs() < 10e-9,
        "detected {:.2} nm below the start",
        (start - zc) * 1e9
    );
    rig.until(1_000, |r| matches!(r.law.phase(), Phase::Settle { .. }));
    let park = rig.stage[2] - zc;
    assert!((park - 100e-9).abs() < 1e-12, "parked {} nm above", park * 1e9);
    // Settles for ENGAGE_TICKS, then ramps over RAMP s with the force growing from 0.
    let n = rig.until(100, |r| matches!(r.law.phase(), Phase::Ramp { .. }));
    assert_eq!(n, ENGAGE_TICKS);
    let mut gains = vec![];
    rig.until(2_000, |r| {
        if let Some(o) = r.last {
            gains.push(o.feedback.gain);
        }
        r.law.phase() == Phase::Engaged
    });
    assert!(gains.windows(2).all(|w| w[1] >= w[0]));
    assert!((gains.len() as f64 - RAMP / 1e-3).abs() <= 2.0, "{}", gains.len());
    let f = rig.tick().feedback;
    assert_eq!((f.gain, f.active, f.flags & FORCE_ENGAGED), (1.0, 1, FORCE_ENGAGED));
    assert!((f.tip_z - 100e-9).abs() < 1e-12);
}

/// 1 mm of handle is 10 nm of tip; the anchor is where the hand was at the engagement.
#[test]
fn the_tip_follows_the_hand_by_the_position_scale_at_a_limited_rate() {
    let mut rig = Rig::new();
    rig.handle.position = 0.004;
    rig.engaged();
    let z0 = rig.stage[2];
    rig.handle.position = 0.004 + 2e-3;
    rig.until(1_000, |r| (r.stage[2] - z0 - 20e-9).abs() < 1e-15);
    // A 10 mm jump of the hand (100 nm) is followed at the rate limit, 1 µm/s.
    let z1 = rig.stage[2];
    rig.handle.position += 0.01;
    rig.tick();
    let dz = rig.stage[2] - z1;
    assert!((dz - 1000e-9 * 1e-3).abs() < 1e-15, "moved {} nm in one tick", dz * 1e9);
}

/// Pressing down: the tip snaps in (the hand is pulled down), then presses; the force at the hand
/// is the measured tip force times the force scale, and the local model's stiffness is the
/// lever's, scaled; the tip never presses beyond the deflection limit, and beyond it the hand
/// meets a wall.
#[test]
fn pressing_feels_the_snap_in_the_contact_and_the_limit() {
    let mut rig = Rig::new();
    rig.engaged();
    let p = rig.law.params;
    let mut forces = vec![];
    let mut max_zeta: f64 = 0.0;
    // Down 14 mm (140 nm: 40 nm below the parking height's surface) at 3 mm/s.
    for _ in 0..4700 {
        rig.handle.position -= 3e-6;
        let f = rig.tick().feedback;
        forces.push((f.force, f.tip_force, f.stiffness));
        max_zeta = max_zeta.max(f.tip_force / p.k_z);
    }
    let (f_min, _, _) = forces
        .iter()
        .copied()
        .fold((f64::INFINITY, 0.0, 0.0), |a, b| if b.0 < a.0 { b } else { a });
    assert!(f_min < -0.3, "the snap-in pulls the hand down: {f_min} N");
    let &(f_end, tip_end, k_end) = forces.last().unwrap();
    assert!(f_end > 0.5, "pressed: {f_end} N");
    // The limit holds the lever at 80 % of the strategy's safety deflection; the reading's noise
    // and perturbation carry it a little past, never to the safety limit itself.
    let safety = p.max_indent / 0.8;
    assert!(
        max_zeta < safety,
        "ζ {} nm reached the safety limit {} nm",
        max_zeta * 1e9,
        safety * 1e9
    );
    assert!(max_zeta > 0.9 * p.max_indent, "pressed to {} nm", max_zeta * 1e9);
    // Beyond the limit the force keeps growing with the handle (the wall), saturating at the
    // device's limit; the local model has the scaled lever stiffness.
    assert!(f_end <= 2.5 && f_end > p.force_gain * tip_end);
    assert!((k_end + p.force_gain * p.k_z * p.position_gain).abs() < 1e-9, "{k_end}");
    // Every force is the scaled tip force plus the wall, never more than the device takes.
    assert!(forces.iter().all(|f| f.0.abs() <= 2.5));
}

/// A lost link freezes the hand's control and retracts the tip to the parking height; a new
/// link settles and ramps in again, re-anchored where the hand is.
#[test]
fn a_lost_link_retracts_to_the_parking_height_and_resumes_with_a_ramp() {
    let mut rig = Rig::new();
    rig.engaged();
    let zc = rig.law.contact_z().unwrap();
    for _ in 0..700 {
        rig.handle.position -= 2e-5; // 14 mm down at 20 mm/s: the tip is on the surface
        rig.tick();
    }
    assert!(rig.stage[2] - zc < 10e-9);
    rig.link = false;
    let out = rig.tick();
    assert_eq!(rig.law.phase(), Phase::LinkLost);
    assert_eq!(out.feedback.active, 0);
    rig.until(1_000, |r| (r.stage[2] - zc - 100e-9).abs() < 1e-12);
    for _ in 0..100 {
        rig.tick();
        assert!(
            (rig.stage[2] - zc - 100e-9).abs() < 1e-12,
            "holds at the parking height"
        );
    }
    rig.link = true;
    rig.handle.position = -0.02;
    rig.until(50, |r| matches!(r.law.phase(), Phase::Ramp { .. }));
    rig.until(1_100, |r| r.law.phase() == Phase::Engaged);
    // Re-anchored: no jump of the tip.
    assert!((rig.stage[2] - zc - 100e-9).abs() < 1e-12);
}

#[test]
fn the_clutch_holds_the_tip_and_re_anchors_on_release() {
    let mut rig = Rig::new();
    rig.engaged();
    let z = rig.stage[2];
    rig.handle.buttons = BUTTON_CLUTCH;
    rig.tick();
    assert_eq!(rig.law.phase(), Phase::Clutched);
    for _ in 0..100 {
        rig.handle.position += 1e-4; // 10 mm up while clutched
        let f = rig.tick().feedback;
        assert_eq!(f.gain, 0.0);
        assert_eq!(f.flags & FORCE_CLUTCHED, FORCE_CLUTCHED);
    }
    assert!((rig.stage[2] - z).abs() < 1e-15, "the tip held");
    rig.handle.buttons = 0;
    rig.tick();
    assert!(matches!(rig.law.phase(), Phase::Ramp { .. }));
    rig.handle.position -= 1e-3;
    rig.until(100, |r| (r.stage[2] - (z - 10e-9)).abs() < 1e-15);
}

/// While a push runs, the law leaves z to the strategy and the hand only feels; after it the
/// tip is parked again.
#[test]
fn a_push_owns_z_and_the_hand_only_feels() {
    let mut rig = Rig::new();
    rig.engaged();
    rig.pushing = true;
    let out = rig.tick();
    assert_eq!(rig.law.phase(), Phase::Pushing);
    assert_eq!(out.target, None);
    assert_eq!(out.feedback.flags, FORCE_PUSHING);
    assert_eq!(out.feedback.stiffness, 0.0);
    assert!(
        out.feedback.gain > 0.0 && out.feedback.gain < 0.01,
        "the force ramps in"
    );
    rig.pushing = false;
    rig.tick();
    assert_eq!(rig.law.phase(), Phase::Approach);
}

#[test]
fn release_parks_the_tip_and_lets_the_handle_go() {
    let mut rig = Rig::new();
    rig.engaged();
    let zc = rig.law.contact_z().unwrap();
    for _ in 0..700 {
        rig.handle.position -= 2e-5;
        rig.tick();
    }
    rig.law.release();
    assert_eq!(rig.law.phase(), Phase::Retract);
    rig.until(1_000, |r| r.law.phase() == Phase::Off);
    assert!((rig.stage[2] - zc - 100e-9).abs() < 1e-12);
    let f = rig.tick().feedback;
    assert_eq!((f.active, f.gain, f.force), (0, 0.0, 0.0));
}

/// The engage button toggles; an approach that finds nothing ends off with a fault.
#[test]
fn the_engage_button_toggles_and_no_surface_is_a_fault() {
    let mut rig = Rig::new();
    rig.handle.buttons = BUTTON_ENGAGE;
    rig.tick();
    assert_eq!(rig.law.phase(), Phase::Approach);
    rig.handle.buttons = 0;
    rig.tick();
    rig.handle.buttons = BUTTON_ENGAGE;
    rig.tick();
    assert_eq!(rig.law.phase(), Phase::Off);

    // Nothing within 1 µm below a tip 3 µm up: a fault, and the tip back where it started.
    let mut rig = Rig::new();
    let start = rig.stage[2];
    rig.law.params.search_depth = 1.0 * UM;
    rig.law.engage(rig.stage);
    rig.until(3_000, |r| r.law.phase() == Phase::Off);
    assert_eq!(rig.law.fault(), Some(Fault::NoSurface));
    assert!(
        (rig.stage[2] - start).abs() < 1e-12,
        "left {} nm below the start",
        (start - rig.stage[2]) * 1e9
    );
}

/// A push that starts while the hand is engaged ramps the force in (never the full force in one
/// tick) and gives the tip back to the hand after it; one that starts after a release does not.
#[test]
fn a_push_ramps_the_force_in_and_returns_the_tip_only_to_an_engaged_hand() {
    let mut rig = Rig::new();
    rig.engaged();
    rig.pushing = true;
    let gains: Vec<f64> = (0..1100).map(|_| rig.tick().feedback.gain).collect();
    assert!(gains[0] < 0.01 && gains.windows(2).all(|w| w[1] >= w[0]) && gains[1099] == 1.0);
    rig.pushing = false;
    rig.tick();
    assert_eq!(rig.law.phase(), Phase::Approach);

    let mut rig = Rig::new();
    rig.engaged();
    rig.law.release();
    rig.pushing = true;
    rig.tick();
    rig.pushing = false;
    rig.tick();
    assert!(
        matches!(rig.law.phase(), Phase::Off | Phase::Retract),
        "{:?}",
        rig.law.phase()
    );
}

/// New scales never reach the hand in one step: the force ramps in again from zero, and the
/// tip does not jump (re-anchored at the handle).
#[test]
fn a_new_scale_ramps_in_again() {
    let mut rig = Rig::new();
    rig.engaged();
    let z = rig.stage[2];
    let x = rig.handle.position;
    rig.law
        .rescale(Some(2e-5), Some(rig.law.params.force_gain * 5.0), Some(x));
    let f = rig.tick().feedback;
    assert!(matches!(rig.law.phase(), Phase::Ramp { .. }));
    assert!(f.gain < 0.01);
    assert!((rig.stage[2] - z).abs() < 1e-15);
    // 1 mm of hand is now 20 nm of tip.
    rig.handle.position -= 1e-3;
    rig.until(100, |r| (r.stage[2] - (z - 20e-9)).abs() < 1e-15);
}

/// README, "Haptic z-control": the force ramps in "once the force the hand would get has stayed
/// below 0.2 N for 3 ticks", "over 1 s".
#[test]
fn engagement_waits_for_0_2_n_over_3_ticks_and_ramps_over_1_s() {
    assert_eq!((ENGAGE_FORCE, ENGAGE_TICKS, RAMP), (0.2, 3, 1.0));
}

/// README, "Two processes" and "Passivity", on the paper scene (`[haptic]` at its defaults, 10
/// nm/mm and 1 N): the tip stops where the lever reaches 80 % of the strategy's safety
/// deflection — (−4.0 V − (−0.2 V)) / (−0.8 V/nm) = 4.75 nm, so 3.80 nm; `g_f` maps the scene's
/// adhesion, 55.09 nN, to 1 N; the contact's stiffness at the hand `g_f k_z g_p` is 1.45 kN/m (2.90 kN/m
/// at the force scale ×2 of the haptic loop's table), and the snap-in's stored energy at the
/// hand, ½F²/K with F = 1 N, is 0.34 mJ.
#[test]
fn the_paper_scenes_hand_stops_at_3_80_nm_feels_1_n_and_a_1_45_kn_per_m_contact() {
    let scene = Scene::default_scene();
    let f = &scene.file;
    assert_eq!(
        (f.strategy.safety_limit_v, f.sensor.baseline_v, f.sensor.gain_v_per_nm),
        (-4.0, -0.2, -0.8)
    );
    let p = scene.bilateral_params(1e-3);
    let safety = 4.75e-9;
    assert!((p.max_indent - 0.8 * safety).abs() < 1e-15, "{} nm", p.max_indent * 1e9);
    assert!((p.max_indent - 3.80e-9).abs() < 0.005e-9);
    assert_eq!(p.position_gain, 1e-5);
    let adhesion = scene.tip_sample().adhesion();
    assert!((adhesion - 55.09e-9).abs() <= 0.005e-9, "{} nN", adhesion * 1e9);
    assert!(
        (p.force_gain * adhesion - 1.0).abs() < 1e-12,
        "{}",
        p.force_gain * adhesion
    );
    let k_hand = p.force_gain * p.k_z * p.position_gain;
    eprintln!(
        "adhesion {:.4} nN, k_z {} N/m, K at the hand {:.4} kN/m, ½F²/K {:.4} mJ",
        adhesion * 1e9,
        p.k_z,
        k_hand * 1e-3,
        0.5 / k_hand * 1e3
    );
    assert!((k_hand - 1.45e3).abs() <= 5.0, "{k_hand} N/m");
    assert!((2.0 * k_hand - 2.90e3).abs() <= 5.0, "{} N/m", 2.0 * k_hand);
    let stored = 0.5 * 1.0f64.powi(2) / k_hand;
    assert!((stored - 0.34e-3).abs() <= 0.005e-3, "{stored} J");
}
