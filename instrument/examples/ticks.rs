//! Runs many 1 ms ticks of a scene (for profilers such as `valgrind --tool=callgrind`):
//! `cargo run --release -p nanopush-instrument --example ticks -- scenes/minimal.toml 2000`.

use nanopush_instrument::numerics::integrate::{Method, Options};
use nanopush_instrument::physics::pushing::{PushModel, Simulation};
use nanopush_instrument::scene::Scene;

fn main() {
    let mut args = std::env::args().skip(1);
    let path = args.next().unwrap_or_else(|| "scenes/paper-default.toml".into());
    let ticks: u32 = args.next().and_then(|s| s.parse().ok()).unwrap_or(1000);
    let scene = match Scene::from_path(std::path::Path::new(&path)) {
        Ok(s) => s,
        Err(e) => {
            eprintln!("error: {e}");
            std::process::exit(2);
        }
    };
    let mut sim = Simulation::new(
        PushModel::new(scene.push_params()),
        Method::Rodas4,
        Options::with_rtol(1e-6),
    );
    let mut steps = 0;
    for k in 1..=ticks {
        match sim.advance_to(k as f64 * 1e-3) {
            Ok(r) => steps += r.stats.steps,
            Err(e) => {
                eprintln!("error at tick {k}: {e}");
                std::process::exit(1);
            }
        }
    }
    println!("{ticks} ticks, {steps} steps, final phase {}", sim.phase().as_str());
}
