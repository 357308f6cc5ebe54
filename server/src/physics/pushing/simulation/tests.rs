//! Tests of the hybrid push simulation.

use super::*;
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

#[test]
#[ignore]
fn debug_transitions() {
    let m = scene("paper-default.toml");
    let mut sim = Simulation::new(m, Method::Rodas4, Options::with_rtol(1e-10));
    sim.max_switches = 30;
    let mut last = sim.mode;
    let n = sim.model.len();
    for k in 1..=2000 {
        let r = sim.advance_to(k as f64 * 1e-6);
        if sim.mode != last || r.is_err() {
            let sw = sim.model.switching(sim.t, &sim.x[..n], &sim.mode);
            eprintln!("t={:.9e} mode {:?} sw {:?} r {:?}", sim.t, sim.mode, sw, r.as_ref().map(|r| r.switches));
            last = sim.mode;
        }
        if r.is_err() { break; }
    }
}

#[test]
#[ignore]
fn debug_collapse() {
    use crate::physics::integrate::methods::Work;
    use crate::physics::integrate::Problem;
    let m = scene("paper-default.toml");
    let mut sim = Simulation::new(m, Method::Rodas4, Options::with_rtol(1e-10));
    for k in 1..=2000 {
        if let Err(e) = sim.advance_to(k as f64 * 1e-6) { eprintln!("failed: {e}"); break; }
    }
    let n = sim.model.len();
    let names = sim.model.layout.names();
    let prob = InMode { model: &sim.model, mode: sim.mode, scale: sim.scale };
    eprintln!("t={} x={:?}", sim.t, &sim.x[..n]);
    for h in [1e-20, 1e-16, 1e-12, 1e-10, 1e-8, 1e-6] {
        let mut w = Work::new(Method::Rodas4);
        w.n = n;
        for i in 0..n { w.mass[i] = prob.mass(i); w.y0[i] = sim.x[i]; w.scale[i] = 1e-10 * prob.scale(i) + 1e-10 * sim.x[i].abs(); }
        prob.rhs(sim.t, &sim.x[..n], &mut w.f0[..n]);
        prob.time_derivative(sim.t, &sim.x[..n], &mut w.ft[..n]);
        prob.jacobian(sim.t, &sim.x[..n], &mut w.jac[..n * n]);
        w.step(&prob, sim.t, h).unwrap();
        let comps: Vec<String> = (0..n).map(|i| format!("{}={:.1e}", names[i], w.err[i] / w.scale[i])).collect();
        eprintln!("h={h:e}: {} f0={:?}", comps.join(" "), &w.f0[..n]);
    }
}
