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
