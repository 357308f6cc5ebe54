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
