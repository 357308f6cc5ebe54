//! The control loop advances the physics once per tick: that call must not allocate. A counting
//! global allocator checks it over the shipped quasi-static scenes and every method, from the
//! first tick on (mode switches included).

use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering};

use nanopush::physics::integrate::{Method, Options};
use nanopush::physics::pushing::{PushModel, Simulation};
use nanopush::scene::Scene;

struct Counting;

static ALLOCATIONS: AtomicUsize = AtomicUsize::new(0);

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
        // SAFETY: forwarded unchanged to the system allocator.
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: forwarded unchanged to the system allocator.
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
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
            let before = ALLOCATIONS.load(Ordering::Relaxed);
            let (mut steps, mut switches) = (0, 0);
            for k in 1..=40 {
                let r = sim.advance_to(k as f64 * 1e-3).unwrap();
                steps += r.stats.steps;
                switches += r.switches;
            }
            let allocated = ALLOCATIONS.load(Ordering::Relaxed) - before;
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
