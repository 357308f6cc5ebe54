//! The control loop advances the physics once per tick: that call must not allocate. A counting
//! global allocator checks it over the shipped scenes and every method.

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
            // Warm up past the start and (for most scenes) a mode switch.
            for k in 1..=20 {
                sim.advance_to(k as f64 * 1e-3).unwrap();
            }
            let before = ALLOCATIONS.load(Ordering::Relaxed);
            let mut steps = 0;
            for k in 21..=40 {
                steps += sim.advance_to(k as f64 * 1e-3).unwrap().stats.steps;
            }
            let allocated = ALLOCATIONS.load(Ordering::Relaxed) - before;
            assert!(steps > 0);
            assert_eq!(
                allocated,
                0,
                "{name} with {}: {allocated} allocations in 20 ticks",
                method.name()
            );
        }
    }
}
