//! Tests of the hybrid push simulation.

use super::*;
use crate::physics::forces::capillary::Meniscus;
use crate::scene::Scene;

fn scene(name: &str) -> PushModel {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../scenes")
        .join(name);
    PushModel::new(Scene::from_path(&path).unwrap().push_params())
}

#[test]
fn minimal_scene_pushes_and_shears() {
    let model = scene("minimal.toml");
    let mut sim = Simulation::new(model, Method::Rodas4, Options::with_rtol(1e-6));
    for k in 1..=50 {
        sim.advance_to(k as f64 * 1e-3).unwrap();
    }
    let n = sim.model.len();
    assert!(sim.x[..n].iter().all(|v| v.is_finite()));
    let t_star = sim.shearing_time.expect("the particle shears within 50 nm of travel");
    assert!(t_star > 0.0 && t_star < 0.05);
    // After shearing the particle moves with the stage: its y advances.
    let y = sim.x[sim.model.layout.particle_y.pos];
    assert!(y > 10e-9, "particle y = {y:e}");
}

#[test]
fn paper_scene_runs_a_few_ticks() {
    let model = scene("paper-default.toml");
    let mut sim = Simulation::new(model, Method::Rodas4, Options::with_rtol(1e-6));
    for k in 1..=5 {
        let r = sim.advance_to(k as f64 * 1e-3).unwrap();
        eprintln!(
            "tick {k}: steps {} rejected {} switches {} wall {:e}",
            r.stats.steps, r.stats.rejected, r.switches, r.stats.wall_time
        );
    }
    let n = sim.model.len();
    assert!(sim.x[..n].iter().all(|v| v.is_finite()));
}

/// Regression: the error norm once multiplied the absolute tolerance in twice, so states near
/// zero (the cantilever's ζ_y here) were held to a pure relative tolerance and at rtol 1e-10
/// the step size collapsed below 1e-20 s around 1.4-1.9 ms.
#[test]
fn tight_tolerance_does_not_collapse_the_step() {
    let mut sim = Simulation::new(scene("paper-default.toml"), Method::Rodas4, Options::with_rtol(1e-10));
    for k in 1..=2000 {
        sim.advance_to(k as f64 * 1e-6)
            .unwrap_or_else(|e| panic!("at {} ms: {e}", k as f64 * 1e-3));
    }
    assert!(sim.total.steps < 20_000, "{} steps for 2 ms", sim.total.steps);
}

#[test]
fn frictionless_substrate_slides_at_once() {
    // μ_as = 0: the static limit is zero, so the substrate contact starts on its switching
    // boundary; the first push must make it slip (an event from exactly zero to negative).
    let mut p = scene("minimal.toml").p;
    p.mu_as_s = 0.0;
    p.mu_as_k = 0.0;
    let mut sim = Simulation::new(PushModel::new(p), Method::Rodas4, Options::with_rtol(1e-6));
    sim.advance_to(2e-3).unwrap();
    let t = sim.shearing_time.expect("slides");
    assert!(t < 1e-4, "slid only at {t:e} s");
}

/// The integrator sees the model in one mode: every `Problem` entry point is the model's own
/// (a mass, Jacobian or `∂f/∂t` the integrator does not see would change only the error it
/// controls, so a push's result alone would not tell).
#[test]
fn the_integrators_view_is_the_model_in_its_mode() {
    let mut model = scene("paper-full-dynamics.toml");
    model.drive = Drive {
        t0: 1e-4,
        y0: 2e-9,
        vy: 1.5e-6,
        z0: 0.0,
        vz: 0.4e-6,
    };
    let n = model.len();
    let mode = Mode {
        substrate: Tangential::Slip { direction: 1.0 },
        ..model.initial_mode()
    };
    let mut x = model.initial_state();
    for (i, v) in x[..n].iter_mut().enumerate() {
        *v += 1e-10 * (1.0 + i as f64);
    }
    let scale = Simulation::scales(&model);
    let p = InMode {
        model: &model,
        mode,
        scale,
    };
    let t = 3e-4;
    let (mut a, mut b) = (vec![0.0; n], vec![0.0; n]);
    p.rhs(t, &x[..n], &mut a);
    model.rhs(t, &x[..n], &mode, &mut b);
    assert_eq!(a, b);
    p.time_derivative(t, &x[..n], &mut a);
    model.time_derivative(t, &x[..n], &mode, &mut b);
    assert_eq!(a, b);
    assert!(b.iter().any(|v| *v != 0.0), "the drive moves: ∂f/∂t is not zero");
    let (mut ja, mut jb) = (vec![0.0; n * n], vec![0.0; n * n]);
    p.jacobian(t, &x[..n], &mut ja);
    model.jacobian(t, &x[..n], &mode, &mut jb);
    assert_eq!(ja, jb);
    assert_eq!(p.len(), n);
    for (i, s) in scale.iter().enumerate().take(n) {
        assert_eq!(p.mass(i), model.mass_diagonal()[i]);
        assert_eq!(p.scale(i), *s);
    }
    // Every switching function is an event, in the order of SWITCHES.
    assert_eq!(Events::count(&p), 4);
    let mut ev = [0.0; 4];
    p.eval(t, &x[..n], &mut ev);
    let sw = model.switching(t, &x[..n], &mode);
    let want = [sw.substrate, sw.tip, sw.meniscus, sw.tip_contact].map(|v| v.unwrap_or(f64::NAN));
    for (e, w) in ev.iter().zip(want) {
        assert!(e == &w || (e.is_nan() && w.is_nan()), "{ev:?} vs {want:?}");
    }
    // At a step's end, with f, ∂f/∂t and J known, the same values (the slip rate exact).
    let (mut f, mut ft, mut j) = (vec![0.0; n], vec![0.0; n], vec![0.0; n * n]);
    model.derivatives(t, &x[..n], &mode, &mut f, &mut ft, &mut j);
    let mut at_step = [0.0; 4];
    p.eval_at_step(t, &x[..n], &f, &ft, &j, &mut at_step);
    for (e, w) in at_step.iter().zip(ev) {
        assert!((e - w).abs() <= 1e-9 * w.abs(), "{at_step:?} vs {ev:?}");
    }
    // In stick no rate is needed: the same values again.
    let stick = InMode {
        model: &model,
        mode: model.initial_mode(),
        scale,
    };
    stick.eval_at_step(t, &x[..n], &f, &ft, &j, &mut at_step);
    stick.eval(t, &x[..n], &mut ev);
    assert_eq!(at_step, ev);
}

/// The absolute tolerance's scales by hand: 1 nm for positions, 1 mm/s for rates, and for the
/// rotation the same arc on the particle's surface (1 nm/Rₐ, 1 mm/s / Rₐ).
#[test]
fn tolerance_scales_by_hand() {
    let model = scene("paper-full-dynamics.toml");
    let l = model.layout;
    let s = Simulation::scales(&model);
    let r_a = model.p.r_a;
    for slot in [
        l.stage.unwrap(),
        l.zeta_y,
        l.zeta_z,
        l.particle_y,
        l.particle_z.unwrap(),
    ] {
        assert_eq!((s[slot.pos], s[slot.vel.unwrap()]), (1e-9, 1e-3));
    }
    let rot = l.rotation.unwrap();
    assert_eq!(s[rot.pos], 1e-9 / r_a);
    assert_eq!(s[rot.vel.unwrap()], 1e-3 / r_a);
}

/// A new drive equal to the present one is no new segment; a different one is taken, and a
/// drive that pulls the tip back makes the slipping contact stick at once.
#[test]
fn set_drive_takes_only_a_new_segment() {
    let mut sim = Simulation::new(scene("minimal.toml"), Method::Rodas4, Options::with_rtol(1e-6));
    sim.advance_to(30e-3).unwrap();
    assert_eq!(sim.phase(), FrictionPhase::Slip, "the minimal scene slides by 30 nm");
    let same = sim.model.drive;
    assert_eq!(sim.set_drive(same), 0);
    let back = Drive {
        vy: -same.vy,
        ..same.ramp_to(sim.t, sim.t + 1e-3, same.y_at(sim.t), 0.0)
    };
    assert_eq!(sim.model.drive, same);
    let switched = sim.set_drive(back);
    assert_eq!(sim.model.drive, back);
    sim.advance_to(sim.t + 1e-3).unwrap();
    assert!(
        switched > 0 || sim.phase() == FrictionPhase::Stick,
        "{:?} after {switched} switches",
        sim.phase()
    );
}

/// A tick reports the switches it made (each event, plus those it made due at once), and a
/// tick that needs more than `max_switches` is refused as chattering while one that needs
/// exactly that many is not.
#[test]
fn switches_are_counted_and_chattering_is_bounded() {
    // The minimal scene shears within 30 ms; per tick, how many switches?
    let run = |max_switches: u32| -> Result<Vec<u32>, u32> {
        let mut sim = Simulation::new(scene("minimal.toml"), Method::Rodas4, Options::with_rtol(1e-6));
        sim.max_switches = max_switches;
        let mut counts = Vec::new();
        for k in 1..=30 {
            match sim.advance_to(k as f64 * 1e-3) {
                Ok(r) => counts.push(r.switches),
                Err(SimulationError::Chattering { count, .. }) => return Err(count),
                Err(e) => panic!("{e}"),
            }
        }
        Ok(counts)
    };
    let counts = run(10_000).unwrap();
    let most = *counts.iter().max().unwrap();
    assert!(most >= 1, "the shearing is a switch: {counts:?}");
    assert!(run(most).is_ok(), "exactly {most} switches is not chattering");
    assert_eq!(
        run(most - 1),
        Err(most),
        "one more than the limit is refused, and counted"
    );
}

/// A mode that does not fit the state (a switching function already negative: the tip pressed
/// in but "apart", a meniscus "absent" around a tip in contact) is set right at once, and each
/// switch is counted.
#[test]
fn a_mode_that_does_not_fit_the_state_is_set_right_at_once() {
    let mut sim = Simulation::new(scene("paper-default.toml"), Method::Rodas4, Options::with_rtol(1e-6));
    let fitted = sim.mode;
    assert!(fitted.tip_contact && fitted.meniscus == Meniscus::Formed, "{fitted:?}");
    assert_eq!(sim.enforce_mode(), 0, "a fitting mode is left alone");

    sim.mode.meniscus = Meniscus::Absent;
    assert!(
        sim.model
            .switching(sim.t, &sim.x[..sim.model.len()], &sim.mode)
            .meniscus
            .unwrap()
            < 0.0
    );
    assert_eq!(sim.enforce_mode(), 1);
    assert_eq!(sim.mode.meniscus, Meniscus::Formed);

    sim.mode.tip_contact = false;
    assert!(
        sim.model
            .switching(sim.t, &sim.x[..sim.model.len()], &sim.mode)
            .tip_contact
            .unwrap()
            < 0.0
    );
    assert_eq!(sim.enforce_mode(), 1);
    assert!(sim.mode.tip_contact);
}

/// A slipping contact at rest keeps slipping: only a slip that runs against its friction by
/// more than 1 nm/s sticks. The minimal scene's push slides by 30 ms; the stage then stops (a
/// new drive that holds), every row is quasi-static, so the slip rate is zero at once.
#[test]
fn a_slip_at_rest_is_no_reason_to_stick() {
    let mut sim = Simulation::new(scene("minimal.toml"), Method::Rodas4, Options::with_rtol(1e-6));
    sim.advance_to(30e-3).unwrap();
    assert_eq!(sim.phase(), FrictionPhase::Slip);
    let d = sim.model.drive;
    let hold = Drive {
        t0: sim.t,
        y0: d.y_at(sim.t),
        vy: 0.0,
        z0: d.z_at(sim.t),
        vz: 0.0,
    };
    assert_eq!(sim.set_drive(hold), 0, "{:?}", sim.mode);
    let n = sim.model.len();
    let (rate_as, _) = sim.model.contact_rates(sim.t, &sim.x[..n], &sim.mode).unwrap();
    assert!(rate_as.abs() < 1e-12, "at rest: {rate_as}");
    assert_eq!(sim.phase(), FrictionPhase::Slip);
}

/// A quasi-static particle has no balance without the tip: once the contact is broken the push
/// stops where it is ([`SimulationError::ContactLost`]) and the state is unchanged; advancing
/// to where it already is does nothing. Lifted at 1 mm/s, the minimal scene's tip lets go
/// ([`Simulation::advance_or_release`]) where its contact breaks, before the tick's end.
#[test]
fn without_the_tip_a_quasi_static_particle_is_let_go() {
    let mut sim = Simulation::new(scene("paper-default.toml"), Method::Rodas4, Options::with_rtol(1e-6));
    assert!(sim.quasi_static_particle());
    sim.mode.tip_contact = false;
    let before = sim.x;
    assert_eq!(sim.advance_to(0.0).unwrap().switches, 0);
    assert!(matches!(sim.advance_to(1e-4), Err(SimulationError::ContactLost { .. })));
    assert_eq!((sim.t, sim.x), (0.0, before));

    let mut model = scene("minimal.toml");
    model.drive = Drive {
        vz: 1e-3,
        ..Drive::constant_speed(0.0)
    };
    let mut sim = Simulation::new(model, Method::Rodas4, Options::with_rtol(1e-6));
    assert_eq!(sim.advance_or_release(1e-3).unwrap(), Advance::Released);
    assert!(
        !sim.mode.tip_contact && sim.t < 1e-3,
        "released where it broke, at {} s",
        sim.t
    );
}

/// Any other failure is an error while the tip pushes, and a release while it lifts (the
/// particle is let go wherever the failure happened): chattering made certain with
/// `max_switches = 0` under the minimal scene's push, which shears within 30 ms.
#[test]
fn a_failure_is_a_release_only_while_lifting() {
    let run = |vz: f64| {
        let mut model = scene("minimal.toml");
        model.drive.vz = vz;
        let mut sim = Simulation::new(model, Method::Rodas4, Options::with_rtol(1e-6));
        sim.max_switches = 0;
        sim.advance_or_release(30e-3)
    };
    assert!(matches!(run(0.0), Err(SimulationError::Chattering { count: 1, .. })));
    assert!(matches!(run(-1e-9), Err(SimulationError::Chattering { count: 1, .. })));
    assert_eq!(run(1e-9).unwrap(), Advance::Released);
}

/// Steps and rejections of each 1 ms tick of a push at rtol 1e-6, from the start (Rodas4).
fn steps_per_tick(model: PushModel, ticks: usize) -> Vec<(u64, u64)> {
    let mut sim = Simulation::new(model, Method::Rodas4, Options::with_rtol(1e-6));
    (1..=ticks)
        .map(|k| {
            let r = sim.advance_to(k as f64 * 1e-3).unwrap();
            (r.stats.steps, r.stats.rejected)
        })
        .collect()
}

/// The steps per 1 ms tick of the quasi-static scenes (Rodas4, rtol 1e-6) in docs/model.md, "The
/// pushing dynamics (Eq 17)", and docs/benchmarks.md, "Cost of one 1 ms tick
/// (`cargo bench -p nanopush-instrument --bench tick`)", exactly: the default scene takes 13 steps (and 1
/// rejection) in its first tick, 5 steps and 1 rejection in the tick the benchmark times (the 21st,
/// after 20 ms), and 3 by 50 ms; never more than 13 or fewer than 3. The minimal scene's
/// benchmarked tick is 1 step of six model evaluations (Rodas4's six stages, the Jacobian from the
/// dual numbers of the last).
#[test]
fn the_default_scenes_step_counts_per_tick_are_pinned() {
    let ticks = steps_per_tick(scene("paper-default.toml"), 50);
    assert_eq!(ticks[0], (13, 1), "first tick");
    assert_eq!(ticks[20], (5, 1), "the benchmarked tick, 20-21 ms");
    assert_eq!(ticks[49], (3, 0), "49-50 ms");
    assert_eq!(ticks.iter().map(|t| t.0).max(), Some(13), "{ticks:?}");
    assert_eq!(ticks.iter().map(|t| t.0).min(), Some(3), "{ticks:?}");

    let mut sim = Simulation::new(scene("minimal.toml"), Method::Rodas4, Options::with_rtol(1e-6));
    sim.advance_to(20e-3).unwrap();
    let r = sim.advance_to(21e-3).unwrap();
    assert_eq!((r.stats.steps, r.stats.rejected, r.stats.rhs_evals), (1, 0, 6));
}

/// docs/model.md's full model (`paper-full-dynamics`: 12 states) and its cost ("The pushing
/// dynamics (Eq 17)"), rotation off: it shears at the reduced model's t* (6.2078 ms in both), and
/// the 1 ms tick that holds the first slip, where the cantilever's 3.7 MHz lateral mode rings,
/// takes 62 941 steps (and 6699 rejections), ~16 ns a step, against the 6 steps of the tick before
/// it. (~5 s in debug.)
#[test]
fn the_full_models_first_slip_step_count_is_pinned() {
    let rotation_off = |name: &str| {
        let mut model = scene(name);
        model.p.dofs.particle_rotation = crate::physics::pushing::params::Dof::Off;
        PushModel::new(model.p)
    };
    let mut reduced = Simulation::new(
        rotation_off("paper-default.toml"),
        Method::Rodas4,
        Options::with_rtol(1e-6),
    );
    reduced.advance_to(7e-3).unwrap();
    let mut full = Simulation::new(
        rotation_off("paper-full-dynamics.toml"),
        Method::Rodas4,
        Options::with_rtol(1e-6),
    );
    assert_eq!(scene("paper-full-dynamics.toml").len(), 12, "the full model");
    assert_eq!(full.model.len(), 10, "12 states less the rotation's two");
    let mut ticks = Vec::new();
    for k in 1..=7 {
        let r = full.advance_to(k as f64 * 1e-3).unwrap();
        ticks.push((r.stats.steps, r.stats.rejected));
    }
    assert_eq!(ticks[5], (6, 0), "5-6 ms, before the shear");
    assert_eq!(ticks[6], (62_941, 6_699), "6-7 ms, the first slip");
    let (t_full, t_reduced) = (full.shearing_time.unwrap(), reduced.shearing_time.unwrap());
    assert!((t_full - 6.2078e-3).abs() < 0.05e-6, "full t* {t_full:e} s");
    assert!((t_reduced - 6.2078e-3).abs() < 0.05e-6, "reduced t* {t_reduced:e} s");
}

/// The minimal scene with no adhesion (van der Waals off, dry: a Hertz tip contact and nothing
/// but the tip's push to load the substrate), a quasi-static rolling particle on a dynamic
/// stage, pushed at β = 30° with μ_as 0.1: the push's horizontal share, cot 30° = 1.73 of its
/// downward one, is far outside the substrate's friction cone. The particle slides ahead of the
/// tip at vanishing load; the integrator's step once collapsed to 7e-21 s at 2.0 µs following
/// it into the Hertz law's zero-stiffness root. The contact breaks instead, at the start.
#[test]
fn a_particle_pushed_outside_its_friction_cone_leaves_the_tip() {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/minimal.toml");
    let text = std::fs::read_to_string(path)
        .unwrap()
        .replace("van_der_waals = true", "van_der_waals = false")
        .replace("particle_rotation = \"off\"", "particle_rotation = \"quasi_static\"")
        .replace("stage = \"off\"", "stage = \"dynamic\"")
        .replace("particle_substrate_static = 0.3 ", "particle_substrate_static = 0.1 ")
        .replace(
            "particle_substrate_kinetic = 0.2 ",
            "particle_substrate_kinetic = 0.05 ",
        )
        .replace("particle_id = 1", "particle_id = 1\ncontact_angle_deg = 30.0");
    let scene = Scene::parse("minimal, no adhesion", &text).unwrap();
    let model = PushModel::new(scene.push_params());
    assert_eq!(model.p.jkr_ta.pull_off_load(), 0.0, "a Hertz tip contact");
    let mut sim = Simulation::new(model, Method::Rodas4, Options::with_rtol(1e-6));
    match sim.advance_to(1e-4) {
        Err(SimulationError::ContactLost { t }) => assert!(t < 1e-6, "the contact broke at {t:e} s"),
        other => panic!("expected the tip to lose the particle at the start, got {other:?}"),
    }
    assert!(!sim.mode.tip_contact);
    let n = sim.model.len();
    assert!(sim.x[..n].iter().all(|v| v.is_finite()));
}

/// A random scene of the validator ranges (`nanopush campaign --random 1 --seed N --ranges
/// validator --scenes`) pushed from β = 30° as the plan's first contact angle, in ticks of
/// 0.1 ms for at most 0.5 s: the simulation where it stopped and how.
fn push_validator_seed(seed: u64) -> (Simulation, Result<(), SimulationError>) {
    push_scene(match seed {
        21 => include_str!("scenes/validator-seed-21.toml"),
        79 => include_str!("scenes/validator-seed-79.toml"),
        82 => include_str!("scenes/validator-seed-82.toml"),
        107 => include_str!("scenes/validator-seed-107.toml"),
        _ => unreachable!(),
    })
}

/// [`push_validator_seed`] for a scene's text.
fn push_scene(text: &str) -> (Simulation, Result<(), SimulationError>) {
    let text = text.replace("[push]\n", "[push]\ncontact_angle_deg = 30.0\n");
    let scene = Scene::parse("validator seed", &text).unwrap();
    let mut sim = Simulation::new(
        PushModel::new(scene.push_params()),
        Method::Rodas4,
        Options::with_rtol(1e-6),
    );
    for k in 1..=5000 {
        if let Err(e) = sim.advance_to(k as f64 * 1e-4) {
            return (sim, Err(e));
        }
    }
    (sim, Ok(()))
}

/// The determinant of the quasi-static rows' block of the Jacobian at the simulation's state,
/// signed so that it is positive for a stable balance: `(−1)^m det ∂f_a/∂x_a`.
fn balance_det(sim: &Simulation) -> f64 {
    let n = sim.model.len();
    let mut jac = [0.0; MAX_STATES * MAX_STATES];
    sim.model.jacobian(sim.t, &sim.x[..n], &sim.mode, &mut jac);
    let mass = sim.model.mass_diagonal();
    let alg: Vec<usize> = (0..n).filter(|&i| mass[i] == 0.0).collect();
    let a = nalgebra::DMatrix::from_fn(alg.len(), alg.len(), |r, c| jac[alg[c] * n + alg[r]]);
    (-1f64).powi(alg.len() as i32) * a.determinant()
}

/// Validator seed 79 (a 3.5 nm particle, a 1.5 nm tip on a 1.9 N/m lever, a meniscus): the tip
/// rides over the particle on a stretched JKR contact until, at 5.5044 ms, the quasi-static
/// balance folds 29 fm short of the JKR stable branch's end `δ_min` (the contact's negative
/// stiffness there outgrows the lever's): the tip pulls off. The step once collapsed to 9e-21 s
/// there; now the push loses its particle at the fold, the balance having turned unstable.
#[test]
fn the_tip_pulls_off_where_the_quasi_static_balance_folds() {
    let (sim, r) = push_validator_seed(79);
    let t = match r {
        Err(SimulationError::ContactLost { t }) => t,
        other => panic!("expected the tip to lose the particle, got {other:?}"),
    };
    assert!((t - 5.5044e-3).abs() < 0.0001e-3, "lost at {t:e} s");
    let n = sim.model.len();
    let pr = sim.model.probe(sim.t, &sim.x[..n], &sim.mode);
    let beyond = (sim.model.p.interactions.a0 - pr.gap) - sim.model.p.jkr_ta.min_indentation();
    assert!(beyond > 0.0 && beyond < 1e-13, "{beyond:e} m short of δ_min");
    assert!(sim.mode.tip_contact);
    assert!(balance_det(&sim) < 0.0, "the balance is unstable where the push stops");
}

/// Validator seeds 21 and 82: the particle sticks at both contacts and rolls under the tip
/// (rotation, cantilever and particle quasi-static); its rolling balance loses stiffness as the
/// tip's load grows and folds, at 69.73 ms and 81.81 ms, with no contact event near (both
/// friction limits and the contact far from their switches; the balance's determinant down by five
/// orders or past zero). The particle rolls out from under
/// the tip: the push loses it, where the step once collapsed to 4e-21 s.
#[test]
fn a_particle_rolling_under_the_tip_leaves_it_where_its_balance_folds() {
    for (seed, t_fold) in [(21, 69.731e-3), (82, 81.811e-3)] {
        let (sim, r) = push_validator_seed(seed);
        let t = match r {
            Err(SimulationError::ContactLost { t }) => t,
            other => panic!("seed {seed}: expected the tip to lose the particle, got {other:?}"),
        };
        assert!((t - t_fold).abs() < 0.001e-3, "seed {seed}: lost at {t:e} s");
        let n = sim.model.len();
        let sw = sim.model.switching(sim.t, &sim.x[..n], &sim.mode);
        for g in [sw.substrate, sw.tip, sw.meniscus, sw.tip_contact] {
            assert!(g.is_some_and(|g| g > 1e-10), "seed {seed}: a switch is near: {sw:?}");
        }
        let start = Simulation::new(sim.model.clone(), Method::Rodas4, Options::with_rtol(1e-6));
        let d = balance_det(&sim);
        assert!(
            d.abs() < 1e-5 * balance_det(&start),
            "seed {seed}: det {d:e} at the fold"
        );
    }
}

/// Lab campaign seed 41 (an 8 nm particle under an 8 nm tip on a 0.29 N/m lever, dry): the
/// particle rolls under the tip until its balance folds at 58.597 ms, one step after the
/// friction phase switched. The switch restarts the balance's history, so a single block of
/// `∂f_a/∂y_a` is all there is to tell the fold by: it is singular to working precision there
/// (its determinant −1.5e-15 where the last step before the switch had 8.9e-7), and the push
/// loses its particle instead of collapsing its step to 3e-21 s.
#[test]
fn a_fold_one_step_after_a_phase_switch_loses_the_particle() {
    let text = include_str!("scenes/lab-seed-41.toml").replace("[push]\n", "[push]\ncontact_angle_deg = 30.0\n");
    let scene = Scene::parse("lab seed 41", &text).unwrap();
    let model = PushModel::new(scene.push_params());
    // `nanopush simulate --duration 0.16 --sample 0.0001`: 1600 samples.
    let r =
        crate::physics::pushing::trace::run_push(model.clone(), Method::Rodas4, Options::with_rtol(1e-6), 0.16, 1e-4);
    let t = match r {
        Err(SimulationError::ContactLost { t }) => t,
        other => panic!("expected the tip to lose the particle, got {other:?}"),
    };
    assert!((t - 58.597e-3).abs() < 0.001e-3, "lost at {t:e} s");
}

/// Validator seed 107: a soft lever (0.048 N/m) whose tip sticks to the particle by adhesion
/// (JKR and meniscus, 0.1 µN) rolls over it; the line of centres turns past the horizontal
/// behind the particle (φ = −π) at 0.4124 s, where `atan2`'s cut made ξ jump by 2π(Rₜ+Rₐ) and
/// the step collapsed. The contact holds: the push runs its 0.5 s, the particle rolled 10 rad,
/// its balance stable.
#[test]
fn a_tip_rolling_over_the_particle_keeps_its_contact_past_the_horizontal() {
    let (sim, r) = push_validator_seed(107);
    r.unwrap();
    assert_eq!(sim.t, 0.5);
    assert!(sim.mode.tip_contact);
    let n = sim.model.len();
    let pr = sim.model.probe(sim.t, &sim.x[..n], &sim.mode);
    let p = &sim.model.p;
    let theta = sim.x[sim.model.layout.rotation.unwrap().pos];
    assert!((theta - 10.03).abs() < 0.01, "rolled {theta} rad");
    let phi = (pr.contact_ta - theta * p.r_a) / (p.r_t + p.r_a);
    assert!(phi < -std::f64::consts::PI && phi > -4.2, "φ = {phi}");
    assert!(balance_det(&sim) > 0.0);
}
