//! The bilateral law against the simulated instrument (the paper's scene, tip over bare
//! substrate): engagement, position and force scaling, limits, clutch, lost link, pushes.

use super::*;
use crate::afm::Afm;
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
                max_stiffness: 2000.0,
                spec_rate_hz: 1000.0,
                rate_hz: 1000.0,
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
    let mut lowest = start;
    rig.until(3_000, |r| {
        lowest = lowest.min(r.stage[2]);
        r.law.phase() == Phase::Off
    });
    assert_eq!(rig.law.fault(), Some(Fault::NoSurface));
    // It searched the whole 1 µm (one approach step past it), then backed up.
    assert!(
        (start - lowest - 1.0 * UM).abs() <= 1.5e-9,
        "searched {} nm",
        (start - lowest) * 1e9
    );
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

/// docs/haptics.md, "Haptic z-control": the force ramps in "once the force the hand would get has
/// stayed below 0.2 N for 3 ticks", "over 1 s".
#[test]
fn engagement_waits_for_a_small_force_then_ramps_in() {
    assert_eq!((ENGAGE_FORCE, ENGAGE_TICKS, RAMP), (0.2, 3, 1.0));
}

/// docs/haptics.md, "Two processes" and "Passivity", on the paper scene (`[haptic]` at its
/// defaults, 10 nm/mm and 1 N): the tip stops where the lever reaches 80 % of the strategy's safety
/// deflection — (−4.0 V − (−0.2 V)) / (−0.8 V/nm) = 4.75 nm, so 3.80 nm; `g_f` maps the scene's
/// adhesion, 55.09 nN, to 1 N; the contact's stiffness at the hand `g_f k_z g_p` is 1.45 kN/m (2.90 kN/m
/// at the force scale ×2 of the haptic loop's table), and the snap-in's stored energy at the
/// hand, ½F²/K with F = 1 N, is 0.34 mJ.
#[test]
fn the_paper_scenes_hand_stops_at_the_contact_and_feels_its_stiffness() {
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

/// `Scene::bilateral_params` from the paper scene's file by hand (`[haptic]` at its defaults): at
/// most 300 nm above the surface; the approach searches the strategy's 10 µm below its 3 µm start;
/// the tip touches when the lever bends by 5 σ of the readout's noise, at least 0.2 nm (5 mV at
/// 0.8 V/nm is 6.25 pm, so 0.2 nm here; 100 mV is 0.625 nm).
#[test]
fn the_paper_scenes_haptic_limits_follow_its_strategy_and_sensor() {
    let mut scene = Scene::default_scene();
    let p = scene.bilateral_params(1e-3);
    let close = |a: f64, b: f64| (a - b).abs() <= 1e-12 * b.abs();
    assert!(close(p.max_height, 300e-9), "{}", p.max_height);
    assert!(close(p.search_depth, 13e-6), "{}", p.search_depth);
    assert_eq!(p.contact_deflection, 0.2e-9);
    assert!(close(p.park_gap, 100e-9) && p.tick == 1e-3);
    assert!(close(p.max_speed, 1e-6) && close(p.approach_speed, 1e-6));
    scene.file.sensor.noise_rms_mv = 100.0;
    let p = scene.bilateral_params(1e-3);
    assert!(close(p.contact_deflection, 0.625e-9), "{}", p.contact_deflection);
}

#[test]
fn every_phase_has_its_protocol_name() {
    let names: Vec<&str> = [
        Phase::Off,
        Phase::Approach,
        Phase::Park,
        Phase::Settle { small: 2 },
        Phase::Ramp { gain: 0.5 },
        Phase::Engaged,
        Phase::Clutched,
        Phase::Pushing,
        Phase::LinkLost,
        Phase::Retract,
    ]
    .iter()
    .map(Phase::name)
    .collect();
    assert_eq!(
        names,
        [
            "off",
            "approach",
            "park",
            "settle",
            "ramp",
            "engaged",
            "clutched",
            "pushing",
            "link_lost",
            "retract"
        ]
    );
}

/// The force ramps in linearly, a tick's worth of `RAMP` each tick, flagged as engaged from its
/// first tick; the tip force is the lever's stiffness times the deflection read from the
/// voltage, `k_z (V − V₀)/G` (Eqs 11-12), and the hand gets it times the ramp and `g_f` once it
/// is beyond the sensor's noise (`|ζ| > ζ_c`; within it, nothing: the noise is not rendered).
#[test]
fn the_ramp_grows_each_tick_and_the_hand_feels_the_scaled_force() {
    let mut rig = Rig::new();
    let p = rig.law.params;
    rig.law.engage(rig.stage);
    rig.until(20_000, |r| matches!(r.law.phase(), Phase::Ramp { .. }));
    assert_eq!(rig.last.unwrap().feedback.flags, FORCE_ENGAGED);
    let mut k = 0;
    while rig.law.phase() != Phase::Engaged {
        k += 1;
        let v = rig.volts;
        let f = rig.tick().feedback;
        let want = (k as f64 * 1e-3 / RAMP).min(1.0);
        assert!((f.gain - want).abs() < 1e-12, "tick {k}: gain {} want {want}", f.gain);
        assert_eq!((f.flags, f.active), (FORCE_ENGAGED, 1), "tick {k}");
        let tip = p.k_z * (v - p.baseline) / p.sensor_gain;
        assert!((f.tip_force - tip).abs() <= 1e-12 * tip.abs(), "{} {tip}", f.tip_force);
        let touching = ((v - p.baseline) / p.sensor_gain).abs() > p.contact_deflection;
        let hand = if touching { f.gain * p.force_gain * tip } else { 0.0 };
        assert!((f.force - hand).abs() <= 1e-12 * hand.abs(), "{} {hand}", f.force);
    }
    assert_eq!(k, 1000);
}

/// `engaged()` is any phase but off; `recenter` moves the anchor to the hand so the tip stays
/// and the next millimetre of hand is 10 nm from there; `link_lost` parks an engaged hand and
/// leaves an idle law alone.
#[test]
fn engaged_recenter_and_link_lost_do_what_they_say() {
    let mut rig = Rig::new();
    assert!(!rig.law.engaged());
    rig.law.link_lost();
    assert_eq!(rig.law.phase(), Phase::Off);
    rig.engaged();
    assert!(rig.law.engaged());
    let z = rig.stage[2];
    rig.handle.position = 0.03;
    rig.law.recenter(0.03);
    for _ in 0..50 {
        rig.tick();
    }
    assert!((rig.stage[2] - z).abs() < 1e-15, "the tip stayed");
    rig.handle.position = 0.031;
    rig.until(100, |r| (r.stage[2] - (z + 10e-9)).abs() < 1e-15);
    rig.law.link_lost();
    assert_eq!(rig.law.phase(), Phase::LinkLost);
    assert!(rig.law.engaged());
}

/// The law alone over a flat surface at `zc`, through an ideal stage (the tip is where the law
/// put it): the approach meets the surface at `zc`; after it the lever bends by `stiff` times
/// the indentation `max(0, zc − z)` (0: a surface the lever does not feel), read through the
/// scene's sensor.
struct Ideal {
    law: Bilateral,
    z: f64,
    zc: f64,
    stiff: f64,
    handle: HapticState,
    pushing: bool,
}

impl Ideal {
    fn engaged(stiff: f64) -> Ideal {
        let p = Scene::default_scene().bilateral_params(1e-3);
        let mut s = Ideal {
            law: Bilateral::new(p),
            z: 1e-6,
            zc: 0.0,
            stiff,
            handle: HapticState {
                max_force: 1e3,
                max_stiffness: 2000.0,
                spec_rate_hz: 1000.0,
                rate_hz: 1000.0,
                ..Default::default()
            },
            pushing: false,
        };
        s.law.engage([0.0, 0.0, s.z]);
        for _ in 0..5000 {
            s.tick();
            if s.law.phase() == Phase::Engaged {
                return s;
            }
        }
        panic!("not engaged: {:?}", s.law.phase());
    }

    fn tick(&mut self) -> Output {
        let p = self.law.params;
        let volts = if self.law.phase() == Phase::Approach {
            p.baseline
                + if self.z <= self.zc {
                    2.0 * p.substrate_threshold
                } else {
                    0.0
                }
        } else {
            p.baseline + p.sensor_gain * self.stiff * (self.zc - self.z).max(0.0)
        };
        let out = self.law.tick(&Input {
            handle: Some(self.handle),
            stage: [0.0, 0.0, self.z],
            volts,
            pushing: self.pushing,
        });
        if let Some(t) = out.target {
            self.z = t[2];
        }
        out
    }

    /// Where the hand asks the tip to be: the anchor (the hand at 0, the parking height) plus
    /// the scaled travel.
    fn z_des(&self) -> f64 {
        self.law.contact_z().unwrap() + self.law.params.park_gap + self.law.params.position_gain * self.handle.position
    }

    /// The hand's position that asks for the height `z`.
    fn hand_for(&self, z: f64) -> f64 {
        (z - self.law.contact_z().unwrap() - self.law.params.park_gap) / self.law.params.position_gain
    }
}

/// Up, the hand takes the tip at most 300 nm above the surface and meets a wall there (the
/// coupling spring `g_f k_z (z_hi − z_des)`, pulling it down); down onto a surface the lever
/// does not feel, the tip stops 20 nm past the deflection limit below it and the hand meets a
/// wall `g_f k_z (z_lo − z_des)` with the wall's stiffness in the local model.
#[test]
fn the_tip_stays_within_its_limits_and_the_hand_meets_a_wall() {
    let mut s = Ideal::engaged(0.0);
    let p = s.law.params;
    let zc = s.law.contact_z().unwrap();
    assert!((zc - s.zc).abs() <= p.approach_speed * p.tick, "met at {zc}");
    // Not touching, no wall: no force, no stiffness.
    let f = s.tick().feedback;
    assert_eq!((f.force, f.stiffness), (0.0, 0.0));
    s.handle.position = 1.0;
    for _ in 0..1000 {
        s.tick();
    }
    assert!((s.z - (zc + 300e-9)).abs() < 1e-14, "{} nm above", (s.z - zc) * 1e9);
    let f = s.tick().feedback;
    let top = p.force_gain * p.k_z * (zc + 300e-9 - s.z_des());
    assert!(top < 0.0 && f.force == top.max(-1e3), "{} {top}", f.force);
    assert_eq!(f.stiffness, -p.force_gain * p.k_z * p.position_gain);
    s.handle.position = -0.05;
    for _ in 0..1000 {
        s.tick();
    }
    let lo = zc - p.max_indent - FLOOR_MARGIN;
    assert!((s.z - lo).abs() < 1e-14, "{} nm below", (zc - s.z) * 1e9);
    let f = s.tick().feedback;
    let wall = p.force_gain * p.k_z * (lo - s.z_des());
    assert!(
        wall > 0.0 && (f.force - wall).abs() <= 1e-12 * wall,
        "{} {wall}",
        f.force
    );
    assert_eq!(f.stiffness, -p.force_gain * p.k_z * p.position_gain);
}

/// Pressing on a surface the lever feels one to one: the tip stops where the lever reaches its
/// deflection limit, `zc − max_indent`, and the hand feels the tip force there plus the wall;
/// lifting the hand above that floor lets the tip follow again. Touching within the limit sends
/// the lever's scaled stiffness; during a push, none (the strategy owns z).
#[test]
fn the_lever_limit_is_a_floor_the_hand_leaves_by_lifting() {
    let mut s = Ideal::engaged(1.0);
    let p = s.law.params;
    // 1 nm into the surface: touching, within the limit.
    s.handle.position = s.hand_for(s.zc - 1e-9);
    for _ in 0..200 {
        s.tick();
    }
    assert!((s.z - (s.zc - 1e-9)).abs() < 1e-14, "{} nm in", (s.zc - s.z) * 1e9);
    let f = s.tick().feedback;
    let tip = p.k_z * 1e-9;
    assert!((f.tip_force - tip).abs() < 1e-9 * tip && (f.force - p.force_gain * tip).abs() < 1e-9 * f.force);
    assert_eq!(f.stiffness, -p.force_gain * p.k_z * p.position_gain);
    // Far down: the floor where ζ = max_indent.
    s.handle.position = -0.05;
    for _ in 0..1000 {
        s.tick();
    }
    assert!(
        (s.z - (s.zc - p.max_indent)).abs() < 1e-14,
        "{} nm in",
        (s.zc - s.z) * 1e9
    );
    let f = s.tick().feedback;
    let want = p.force_gain * p.k_z * (p.max_indent + (s.z - s.z_des()));
    assert!((f.force - want).abs() <= 1e-9 * want, "{} {want}", f.force);
    // Back up to 1 nm above the floor: the tip follows.
    s.handle.position = s.hand_for(s.zc - p.max_indent + 1e-9);
    for _ in 0..200 {
        s.tick();
    }
    assert!(
        (s.z - s.z_des()).abs() < 1e-14,
        "{} nm from the hand",
        (s.z - s.z_des()) * 1e9
    );
    // The floor went with the lift: where the surface is now 5 nm lower (a particle gone from
    // under the tip), pressing again stops at the new limit, not the old floor.
    s.zc -= 5e-9;
    s.handle.position = -0.05;
    for _ in 0..1000 {
        s.tick();
    }
    assert!(
        (s.z - (s.zc - p.max_indent)).abs() < 1e-14,
        "{} nm in",
        (s.zc - s.z) * 1e9
    );
    s.pushing = true;
    let f = s.tick().feedback;
    assert!(f.tip_force > 0.0);
    assert_eq!((f.stiffness, f.flags), (0.0, FORCE_PUSHING));
}
