//! The operator's side of a move, before any push: find the particle in a local scan near
//! where it is believed to be (Sec 4: the operator works from scanned images), and plan the legs
//! around the other particles the scene's overview scan shows. Used by `nanopush push` and by
//! the server alike.

use crate::control::route::{Leg, Obstacle, RouteError, Router};
use crate::scan::{HeightImage, LocateError, Located, ScanParams, Surface, Tip, find_particles, localize, scan};
use crate::scene::Scene;

/// Shorter than this (m) a move is already done.
pub const DONE_WITHIN: f64 = 10e-9;

/// Where the operator wants the particle.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum MoveTarget {
    /// A distance (m) along a unit direction from where the particle is found.
    Distance {
        /// Distance (m).
        distance: f64,
        /// Unit direction.
        direction: (f64, f64),
    },
    /// A point (m).
    Point((f64, f64)),
}

impl MoveTarget {
    /// The target point for a particle found at `from`.
    pub fn point(&self, from: (f64, f64)) -> (f64, f64) {
        match *self {
            MoveTarget::Distance { distance, direction } => {
                (from.0 + direction.0 * distance, from.1 + direction.1 * distance)
            }
            MoveTarget::Point(p) => p,
        }
    }
}

/// Why a move cannot be routed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MoveError {
    /// The local scan shows no particle near the believed position.
    #[error("particle not found in a scan near ({:.3}, {:.3}) µm: {cause}", .near.0 * 1e6, .near.1 * 1e6)]
    NotFound {
        /// Where it was looked for (m).
        near: (f64, f64),
        /// Why (in the message, not a `source`: printed once).
        cause: LocateError,
    },
    /// No path.
    #[error(transparent)]
    Route(#[from] RouteError),
}

/// A routed move: the particle located and the legs to its target.
#[derive(Debug, Clone, PartialEq)]
pub struct MoveRoute {
    /// The local scan.
    pub local: HeightImage,
    /// The particle as the local scan shows it.
    pub located: Located,
    /// The target point (m).
    pub target: (f64, f64),
    /// The legs; empty when the particle is already within [`DONE_WITHIN`] of the target.
    pub legs: Vec<Leg>,
}

/// Pixels of the local scan.
pub const LOCAL_PIXELS: usize = 128;

/// The side of the local scan for a particle of radius `r_a` under a tip of radius `r_t` (m),
/// on a stage of travel `range`: 12 particle radii (substrate all around the particle, for the
/// levelling), at least 4 µm (room for where the particle is believed to be), but with at least
/// four pixels across the particle's image, whose half-width is `Rₐ + Rₜ` (a pitch of at most
/// `(Rₐ + Rₜ)/4`: the side at most `32 (Rₐ + Rₜ)` at 128 pixels), and at most the stage's travel.
/// A 14 nm gold particle under a 10 nm tip gets 544 nm (4.25 nm pixels) where the fixed 4 µm
/// gave 31 nm pixels and lost it between them; a 10 µm particle gets 100 µm where a 20 µm cap
/// filled the image with the particle and left no substrate to level on.
pub fn local_scan_size(r_a: f64, r_t: f64, range: f64) -> f64 {
    let resolving = (r_a + r_t) / 4.0 * LOCAL_PIXELS as f64;
    (12.0 * r_a).max(4e-6).min(resolving).min(range)
}

/// A 128-pixel local scan around `near` (m), sized by [`local_scan_size`] on a stage of travel
/// `range` (m), and the particle nearest to `near` in it (within a quarter of the side).
pub fn locate_near(
    surface: &Surface,
    tip: Tip,
    base: ScanParams,
    near: (f64, f64),
    radius_hint: f64,
    range: f64,
) -> (HeightImage, Result<Located, LocateError>) {
    let size = local_scan_size(radius_hint, tip.radius, range);
    let params = ScanParams {
        centre_x: near.0,
        centre_y: near.1,
        size,
        pixels: LOCAL_PIXELS,
        ..base
    };
    let img = scan(surface, tip, params);
    let located = localize(&img, &tip, near.0, near.1, 0.25 * size);
    (img, located)
}

/// Locates the particle believed at `near` (radius about `radius_hint`) and plans its move to
/// `target` around the other particles of the scene's overview scan (`[scan]`), with the
/// strategy's longest push and clearance. The target keeps a particle of `radius_hint` on the
/// stage ([`Router::edge_radius`]).
pub fn route_move(
    scene: &Scene,
    surface: &Surface,
    near: (f64, f64),
    radius_hint: f64,
    target: MoveTarget,
) -> Result<MoveRoute, MoveError> {
    let tip = Tip::from_scene(scene);
    let base = ScanParams::from_scene(scene);
    let range = scene.file.stage.range_um * 1e-6;
    let (local, located) = locate_near(surface, tip, base, near, radius_hint, range);
    let located = located.map_err(|cause| MoveError::NotFound { near, cause })?;
    let from = (located.x, located.y);
    let to = target.point(from);
    if (to.0 - from.0).hypot(to.1 - from.1) < DONE_WITHIN {
        return Ok(MoveRoute {
            local,
            located,
            target: to,
            legs: Vec::new(),
        });
    }
    // The particle itself shows in the overview too, within a pixel or two of where the local
    // scan found it: it is not an obstacle.
    let own = (2.0 * located.radius).max(2.0 * base.pixel());
    let obstacles: Vec<Obstacle> = find_particles(&scan(surface, tip, base), &tip)
        .iter()
        .filter(|l| (l.x - from.0).hypot(l.y - from.1) > own)
        .map(|l| Obstacle {
            x: l.x,
            y: l.y,
            radius: l.radius,
        })
        .collect();
    let st = &scene.file.strategy;
    let router = Router {
        radius: located.radius,
        edge_radius: radius_hint,
        max_push: st.max_push_um * 1e-6,
        clearance: st.clearance_um * 1e-6,
        run_up: st.approach_distance_um * 1e-6 + 2.0 * located.radius,
        tip_radius: tip.radius,
        range: scene.file.stage.range_um * 1e-6,
    };
    let mut obstacles = obstacles;
    let mut legs = router.route(from, to, &obstacles)?;
    // Particles too small for the overview's pixels, found by scanning the legs' corridors;
    // each find re-plans, and the new legs are scanned in turn.
    for _ in 0..CORRIDOR_ROUNDS {
        let found = corridor_obstacles(surface, tip, base, &router, &legs, from);
        let near = |a: &Obstacle, b: &Obstacle| (a.x - b.x).hypot(a.y - b.y) < a.radius + b.radius + 2.0 * base.pixel();
        let new: Vec<Obstacle> = found
            .into_iter()
            .filter(|o| !obstacles.iter().any(|q| near(o, q)))
            .collect();
        if new.is_empty() {
            break;
        }
        obstacles.extend(new);
        legs = router.route(from, to, &obstacles)?;
    }
    Ok(MoveRoute {
        local,
        located,
        target: to,
        legs,
    })
}

/// Pixels a side of each corridor scan.
const CORRIDOR_PIXELS: usize = 128;

/// Corridor scans and re-plans at most.
const CORRIDOR_ROUNDS: usize = 3;

/// The particles in the corridors the legs sweep that the overview scan may be too coarse to
/// show (a 25 nm gold particle is a pixel of a 50 µm, 256-pixel overview, and a push would go
/// through it). The corridor is the router's for an obstacle smaller
/// than the overview shows: `h = Rₐ + clearance + 2 overview pixels` either side of each leg
/// and its run-up. It is covered by square scans of [`CORRIDOR_PIXELS`] a side, one every `2h`
/// along the leg, each counting only what it finds in its inner square of half-side `h√2` (which
/// holds the corridor's cross-section at any angle); the margin beyond, `Rₐ + Rₜ`, is wide
/// enough that a particle cut by a square's edge, whose centre a cut image misplaces, is found
/// whole by the next one. A find is a particle only when it stands twice the localization
/// threshold high, as the scene validator requires of every particle (a roughness bump is
/// not). The pushed particle, found where it lies (within `Rₐ` of `from`, or two pixels when
/// it is smaller), is not an obstacle.
fn corridor_obstacles(
    surface: &Surface,
    tip: Tip,
    base: ScanParams,
    router: &Router,
    legs: &[Leg],
    from: (f64, f64),
) -> Vec<Obstacle> {
    let h = router.radius + router.clearance + 2.0 * base.pixel();
    let inner = h * std::f64::consts::SQRT_2;
    let side = 2.0 * (inner + router.radius + tip.radius);
    let least_height = 2.0 * (6.0 * base.noise_rms).max(0.5e-9);
    let mut found = Vec::new();
    for leg in legs {
        let d = leg.direction();
        let start = (leg.from.0 - d.0 * router.run_up, leg.from.1 - d.1 * router.run_up);
        let len = leg.length() + router.run_up;
        let squares = (len / (2.0 * h)).ceil().max(1.0) as usize;
        for k in 0..squares {
            let a = (k as f64 + 0.5) * len / squares as f64;
            let c = (start.0 + d.0 * a, start.1 + d.1 * a);
            let params = ScanParams {
                centre_x: c.0,
                centre_y: c.1,
                size: side,
                pixels: CORRIDOR_PIXELS,
                ..base
            };
            for l in find_particles(&scan(surface, tip, params), &tip) {
                let inside = (l.x - c.0).abs() <= inner && (l.y - c.1).abs() <= inner;
                // Within its radius, or two pixels for a particle smaller than they are (a 7 nm
                // particle is found 10 nm from where the local scan put it).
                let own = (l.x - from.0).hypot(l.y - from.1) < router.radius.max(2.0 * side / CORRIDOR_PIXELS as f64);
                if inside && !own && l.height >= least_height {
                    found.push(Obstacle {
                        x: l.x,
                        y: l.y,
                        radius: l.radius,
                    });
                }
            }
        }
    }
    found
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 25 nm gold particle 3 µm ahead of a 500 nm one is a pixel of the 50 µm overview,
    /// which a push would go through. The corridor scans find it and the
    /// plan goes around; without it the same move is one leg (no roughness bump or cut image
    /// is taken for a particle).
    #[test]
    fn a_neighbour_the_overview_misses_is_found_in_the_corridor() {
        let text =
            std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/../scenes/gold-latex-500nm.toml")).unwrap();
        let small = "\n[[particles]]\nid = 9\nmaterial = \"gold\"\nradius_nm = 25.0\nx_um = 43.0\ny_um = 30.0\nyoungs_modulus_gpa = 79.0\npoisson_ratio = 0.42\ndensity_kg_per_m3 = 19300.0\nhamaker_zj = 400.0\n";
        let target = MoveTarget::Point((45e-6, 30e-6));
        let plain = Scene::parse("plain", &text).unwrap();
        let route = route_move(&plain, &Surface::from_scene(&plain), (40e-6, 30e-6), 500e-9, target).unwrap();
        assert_eq!(route.legs.len(), 1, "{:?}", route.legs);
        let with = Scene::parse("with", &(text + small)).unwrap();
        let overview = find_particles(
            &scan(
                &Surface::from_scene(&with),
                Tip::from_scene(&with),
                ScanParams::from_scene(&with),
            ),
            &Tip::from_scene(&with),
        );
        assert!(
            overview.iter().all(|l| (l.x - 43e-6).hypot(l.y - 30e-6) > 0.2e-6),
            "the overview does not show it: {overview:?}"
        );
        let route = route_move(&with, &Surface::from_scene(&with), (40e-6, 30e-6), 500e-9, target).unwrap();
        assert!(route.legs.len() >= 2, "{:?}", route.legs);
        let p = Router {
            radius: 500e-9,
            edge_radius: 500e-9,
            max_push: 20e-6,
            clearance: with.file.strategy.clearance_um * 1e-6,
            run_up: 0.0,
            tip_radius: 30e-9,
            range: 100e-6,
        };
        let o = Obstacle {
            x: 43e-6,
            y: 30e-6,
            radius: 25e-9,
        };
        for l in &route.legs {
            let leg = Leg { from: l.from, to: l.to };
            assert!(
                p.route(leg.from, leg.to, &[o]).is_ok_and(|legs| legs.len() == 1),
                "{leg:?} passes the neighbour"
            );
        }
    }

    #[test]
    fn the_default_particle_is_found_and_a_long_move_split() {
        let scene = Scene::default_scene();
        let surface = Surface::from_scene(&scene);
        let p = scene.pushed_particle();
        let near = (p.x_um * 1e-6 + 0.3e-6, p.y_um * 1e-6 - 0.2e-6);
        let target = MoveTarget::Distance {
            distance: 30e-6,
            direction: (0.0, 1.0),
        };
        let route = route_move(&scene, &surface, near, 1e-6, target).unwrap();
        assert!((route.located.x - p.x_um * 1e-6).abs() < 50e-9);
        assert!((route.located.radius - 1e-6).abs() < 0.05e-6);
        // 30 µm with pushes of at most 20 µm: two legs, ending at the target.
        assert_eq!(route.legs.len(), 2);
        assert_eq!(route.legs.last().unwrap().to, route.target);
        // Already there: no legs.
        let here = route_move(
            &scene,
            &surface,
            near,
            1e-6,
            MoveTarget::Point((route.located.x, route.located.y)),
        )
        .unwrap();
        assert!(here.legs.is_empty());
        // Nothing near a point of bare substrate.
        let e = route_move(&scene, &surface, (20e-6, 20e-6), 1e-6, target).unwrap_err();
        assert!(matches!(e, MoveError::NotFound { .. }), "{e}");
    }

    /// docs/manipulation.md, "Sensor gains and the shipped scenes" (and this module's doc): a 14 nm
    /// gold particle (Rₐ = 7 nm) under a 10 nm tip gets a 544 nm local scan, `32 (Rₐ + Rₜ)`, with
    /// 4.25 nm pixels, where a fixed 4 µm scan's pixels were 31 nm; a 10 µm particle gets the whole
    /// 100 µm stage.
    #[test]
    fn a_tiny_particle_gets_a_local_scan_four_pixels_across_it() {
        let size = local_scan_size(7e-9, 10e-9, 100e-6);
        assert!((size - 544e-9).abs() < 1e-21, "{size:e}");
        assert!((size / LOCAL_PIXELS as f64 - 4.25e-9).abs() < 1e-21);
        assert!(
            (4e-6 / LOCAL_PIXELS as f64 - 31e-9).abs() <= 0.5e-9,
            "31 nm to the digit docs/manipulation.md gives"
        );
        assert_eq!(local_scan_size(10e-6, 30e-9, 100e-6), 100e-6);
    }
}
