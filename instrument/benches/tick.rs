//! The cost of one 1 ms control tick: `Simulation::advance_to(t + 1 ms)`, for the default
//! (paper) scene and the minimal scene, per method, measured in steady pushing (after 20 ms, past
//! the start transient and the first mode switch). Each sample starts from the same state (the
//! simulation is cloned outside the timed region), so every method integrates the same tick.
//!
//! Run: `cargo bench -p nanopush-instrument --bench tick`. Criterion prints the median ("time: [lo median hi]").

use std::hint::black_box;

use criterion::{BatchSize, Criterion, criterion_group, criterion_main};
use nanopush_instrument::numerics::integrate::{Method, Options};
use nanopush_instrument::physics::pushing::{PushModel, Simulation};

mod common;

fn ticks(c: &mut Criterion) {
    let mut group = c.benchmark_group("tick_1ms");
    for scene in ["paper-default", "minimal"] {
        let s = common::shipped_scene(scene);
        for method in Method::ALL {
            let mut sim = Simulation::new(PushModel::new(s.push_params()), method, Options::with_rtol(1e-6));
            for k in 1..=20 {
                sim.advance_to(k as f64 * 1e-3).expect("warm-up");
            }
            let t_end = sim.t + 1e-3;
            group.bench_function(format!("{scene}/{}", method.name()), |b| {
                b.iter_batched_ref(
                    || sim.clone(),
                    |s| black_box(s.advance_to(t_end).expect("tick")),
                    BatchSize::SmallInput,
                )
            });
        }
    }
    group.finish();
}

/// The parts of a step: one right-hand side, one exact Jacobian (one dual evaluation per
/// column), the switching functions.
fn parts(c: &mut Criterion) {
    let mut group = c.benchmark_group("parts");
    for scene in ["paper-default", "minimal"] {
        let sim = common::warmed_up(scene);
        let (m, t, x, mode) = (&sim.model, sim.t, sim.x, sim.mode);
        let n = m.len();
        let mut f = [0.0; 12];
        let mut j = [0.0; 144];
        group.bench_function(format!("{scene}/rhs"), |b| {
            b.iter(|| m.rhs(black_box(t), black_box(&x[..n]), &mode, &mut f))
        });
        group.bench_function(format!("{scene}/jacobian"), |b| {
            b.iter(|| m.jacobian(black_box(t), black_box(&x[..n]), &mode, &mut j))
        });
        let mut ft = [0.0; 12];
        group.bench_function(format!("{scene}/derivatives"), |b| {
            b.iter(|| m.derivatives(black_box(t), black_box(&x[..n]), &mode, &mut f, &mut ft, &mut j))
        });
        group.bench_function(format!("{scene}/switching"), |b| {
            b.iter(|| black_box(m.switching(black_box(t), &x[..n], &mode)))
        });
    }
    group.finish();
}

criterion_group!(benches, ticks, parts);
criterion_main!(benches);
