//! The control loop advances the physics once per tick: that call must not allocate. A counting
//! global allocator checks it over the shipped quasi-static scenes and every method, from the
//! first tick on (mode switches included).
//!
//! Only the test thread's own allocations are counted (a thread-local counter): the test
//! harness's main thread allocates while the test thread starts (it records the running test),
//! and a process-wide counter once caught that in CI (2 "allocations in 40 ticks" on a loaded
//! machine, none on rerun).

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;

use nanopush_instrument::numerics::integrate::{Method, Options};
use nanopush_instrument::physics::pushing::{PushModel, Simulation};
use nanopush_instrument::scene::Scene;

struct Counting;

thread_local! {
    /// Allocations made by this thread (const-initialized: reading it never allocates).
    static ALLOCATIONS: Cell<usize> = const { Cell::new(0) };
}

fn count_one() {
    // `try_with`: a thread being torn down has no counter, and is not the test's.
    let _ = ALLOCATIONS.try_with(|n| n.set(n.get() + 1));
}

fn allocations() -> usize {
    ALLOCATIONS.with(Cell::get)
}

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        count_one();
        // SAFETY: forwarded unchanged to the system allocator.
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: forwarded unchanged to the system allocator.
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        count_one();
        // SAFETY: forwarded unchanged to the system allocator.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

#[test]
fn a_tick_does_not_allocate() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes");
    for name in [
        "paper-default.toml",
        "minimal.toml",
        "gold-latex-500nm.toml",
        "gold-14nm.toml",
    ] {
        let scene = Scene::from_path(&dir.join(name)).unwrap();
        for method in Method::ALL {
            let mut sim = Simulation::new(PushModel::new(scene.push_params()), method, Options::with_rtol(1e-6));
            // From the first tick on, so the start transient and the mode switches (events,
            // transitions, re-balancing) are inside the counted window.
            let before = allocations();
            let (mut steps, mut switches) = (0, 0);
            for k in 1..=40 {
                let r = sim.advance_to(k as f64 * 1e-3).unwrap();
                steps += r.stats.steps;
                switches += r.switches;
            }
            let allocated = allocations() - before;
            assert!(steps > 0);
            assert_eq!(
                allocated,
                0,
                "{name} with {}: {allocated} allocations in 40 ticks",
                method.name()
            );
            assert!(switches > 0, "{name}: the counted window should include a mode switch");
        }
    }
}
