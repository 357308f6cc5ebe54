//! The assembly's planning: 100 particles onto 100 sites (a 10 × 10 grid of 4 µm pitch in the
//! middle of a 300 µm stage, the particles scattered around it with 30 inside its area), and
//! the parts: the assignment alone (Kuhn-Munkres, 100 × 100), and one route around 100 particles
//! that needs the visibility graph. Goal: a plan of 100 onto 100 in under 1 s.
//!
//! Run: `cargo bench -p nanopush-instrument --bench assembly_plan`.

use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use nanopush_instrument::assembly::assign::assign;
use nanopush_instrument::assembly::{Constraints, Pattern, PlanSettings, Seen, plan};
use nanopush_instrument::control::route::Obstacle;
use rand::rngs::SmallRng;
use rand::{Rng, SeedableRng};

const UM: f64 = 1e-6;

fn settings() -> PlanSettings {
    PlanSettings {
        tolerance: 25e-9,
        clearance: 0.5 * UM,
        max_push: 20.0 * UM,
        approach: 2.0 * UM,
        tip_radius: 30e-9,
        range: 300.0 * UM,
    }
}

/// 100 particles: 30 inside the grid's area (between its sites), 70 around it.
fn field(pattern: &Pattern) -> Vec<Seen> {
    let mut rng = SmallRng::seed_from_u64(1);
    let mut out: Vec<Seen> = Vec::new();
    let centre = pattern.centre();
    while out.len() < 100 {
        let inside = out.len() < 30;
        let p = if inside {
            (
                centre.0 + rng.random_range(-20.0..20.0) * UM,
                centre.1 + rng.random_range(-20.0..20.0) * UM,
            )
        } else {
            (rng.random_range(10.0..290.0) * UM, rng.random_range(10.0..290.0) * UM)
        };
        let apart = out.iter().all(|q| (q.x - p.0).hypot(q.y - p.1) > 2.5 * UM);
        let off_sites = pattern.sites.iter().all(|s| (s.x - p.0).hypot(s.y - p.1) > 1.6 * UM);
        if apart && off_sites {
            out.push(Seen {
                x: p.0,
                y: p.1,
                radius: 0.5 * UM,
            });
        }
    }
    out
}

fn planning(c: &mut Criterion) {
    let pattern = Pattern::generate("grid:rows=10,cols=10,spacing_um=4", (150.0 * UM, 150.0 * UM)).unwrap();
    let particles = field(&pattern);
    let s = settings();
    let first = plan(&particles, &pattern, &s, &Constraints::default());
    println!(
        "plan of 100 onto 100: {} moves, {} of 100 sites fillable, {} legs",
        first.moves.len(),
        first.fillable(),
        first.moves.iter().map(|m| m.legs.len()).sum::<usize>()
    );
    let mut group = c.benchmark_group("assembly");
    group.sample_size(10);
    group.bench_function("plan_100_onto_100", |b| {
        b.iter(|| black_box(plan(&particles, &pattern, &s, &Constraints::default())))
    });
    let sites: Vec<(f64, f64)> = pattern.sites.iter().map(|x| (x.x, x.y)).collect();
    let at: Vec<(f64, f64)> = particles.iter().map(|p| (p.x, p.y)).collect();
    group.bench_function("assign_100_by_100", |b| {
        b.iter(|| black_box(assign(&sites, &at, |_, _| true)))
    });
    // A route through the filled grid's field: from one side of it to the other.
    let obstacles: Vec<Obstacle> = sites
        .iter()
        .map(|&(x, y)| Obstacle { x, y, radius: 0.5 * UM })
        .chain(particles.iter().map(|p| Obstacle {
            x: p.x,
            y: p.y,
            radius: p.radius,
        }))
        .collect();
    let router = s.router(0.5 * UM);
    let (from, to) = ((120.0 * UM, 151.0 * UM), (180.0 * UM, 149.0 * UM));
    let legs = router.route(from, to, &obstacles);
    println!(
        "route across the grid: {}",
        legs.as_ref()
            .map_or_else(|e| e.to_string(), |l| format!("{} legs", l.len()))
    );
    group.bench_function("route_around_200", |b| {
        b.iter(|| black_box(router.route(from, to, &obstacles)))
    });
    group.finish();
}

criterion_group!(benches, planning);
criterion_main!(benches);
