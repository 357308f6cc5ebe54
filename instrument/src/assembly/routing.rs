//! How an assembly's move finds its particle and routes its legs: a local scan around where
//! the map says it is, and the legs around every other particle of the map ([`PlanSettings`]'s
//! router), never an overview scan. Every local scan is kept, so that the map learns from it
//! where the particles around the move are now.

use crate::afm::Afm;
use crate::control::moves::DONE_WITHIN;
use crate::control::moves::locate::{MoveError, MoveRoute, MoveTarget, locate_near};
use crate::control::moves::run::MoveRouting;
use crate::control::route::{Leg, Obstacle, RouteError};
use crate::control::strategy::StrategyParams;
use crate::control::strategy::runner::{Prepared, RunError};
use crate::scan::{HeightImage, LocateError, Located, ScanParams, Tip, find_particles};
use crate::scene::Scene;

use super::plan::{PlanSettings, Seen};

/// One move's routing over the assembly's map.
pub struct MapRouting<'a> {
    /// The map: every particle as the scans last showed it.
    pub map: &'a [Seen],
    /// The particle moved (its index in the map).
    pub mover: usize,
    /// The plan's settings.
    pub settings: PlanSettings,
    /// The scene (tip, scan settings, stage).
    pub scene: &'a Scene,
    /// The model's prediction for this kind of particle, computed once for the assembly.
    pub prepared: &'a mut Option<Prepared>,
    /// Every local scan the move took.
    pub images: Vec<HeightImage>,
}

impl MapRouting<'_> {
    fn scan_params(&self) -> ScanParams {
        ScanParams::from_scene(self.scene)
    }
}

impl MoveRouting for MapRouting<'_> {
    fn route(
        &mut self,
        afm: &Afm,
        near: (f64, f64),
        radius_hint: f64,
        target: MoveTarget,
    ) -> Result<MoveRoute, MoveError> {
        let (local, located) = self.locate(self.scene, afm, near, radius_hint);
        let located = located.map_err(|cause| MoveError::NotFound { near, cause })?;
        let to = target.point((located.x, located.y));
        let legs = legs_on_map(
            self.map,
            self.mover,
            &self.settings,
            (located.x, located.y, located.radius),
            radius_hint,
            to,
        )?;
        Ok(MoveRoute {
            local,
            located,
            target: to,
            legs,
        })
    }

    fn prepare(&mut self, scene: &Scene, id: u32, radius: f64, params: &StrategyParams) -> Result<Prepared, RunError> {
        if let Some(p) = self.prepared.as_ref() {
            return Ok(p.clone());
        }
        let p = Prepared::new(scene, id, radius, params)?;
        *self.prepared = Some(p.clone());
        Ok(p)
    }

    fn locate(
        &mut self,
        scene: &Scene,
        afm: &Afm,
        estimate: (f64, f64),
        radius: f64,
    ) -> (HeightImage, Result<Located, LocateError>) {
        let (img, located) = locate_near(
            &afm.surface(),
            Tip::from_scene(scene),
            self.scan_params(),
            estimate,
            radius,
            scene.file.stage.range_um * 1e-6,
        );
        self.images.push(img.clone());
        (img, located)
    }
}

/// The legs that take the map's particle `mover`, located at `(x, y)` with radius `r` (m), to
/// `to`, around every other particle of the map; none when it is there already. The target keeps
/// a particle of `radius_hint` on the stage.
pub fn legs_on_map(
    map: &[Seen],
    mover: usize,
    settings: &PlanSettings,
    (x, y, r): (f64, f64, f64),
    radius_hint: f64,
    to: (f64, f64),
) -> Result<Vec<Leg>, RouteError> {
    if (to.0 - x).hypot(to.1 - y) < DONE_WITHIN {
        return Ok(Vec::new());
    }
    let obstacles: Vec<Obstacle> = map
        .iter()
        .enumerate()
        .filter(|&(k, _)| k != mover)
        .map(|(_, p)| Obstacle {
            x: p.x,
            y: p.y,
            radius: p.radius,
        })
        .collect();
    let mut router = settings.router(r);
    router.edge_radius = radius_hint;
    router.route((x, y), to, &obstacles)
}

/// The map updated from a move's local scans: each particle found in them moves to where it
/// was found (the one nearest it, within its radius or two pixels); a particle found that the
/// map does not hold is added (the overview's pixels may have hidden it). The mover must be
/// placed first where the move says it ended: a find near there is the mover, and stays as the
/// move measured it; so is a find anywhere along the mover's `path` (its start, its legs, its
/// end), which scans taken before or during the move show it on.
pub fn update_map(
    map: &mut Vec<Seen>,
    mover: usize,
    path: &[(f64, f64)],
    images: &[HeightImage],
    tip: &Tip,
    noise_rms: f64,
) {
    let least_height = 2.0 * (6.0 * noise_rms).max(0.5e-9);
    for img in images {
        let pixel = img.dx().max(img.x_real / img.xres.max(1) as f64);
        // A particle cut by the image's edge is placed wrongly: only those whole inside count.
        for l in find_particles(img, tip) {
            let inside = l.x - l.radius >= img.x_offset
                && l.x + l.radius <= img.x_offset + img.x_real
                && l.y - l.radius >= img.y_offset
                && l.y + l.radius <= img.y_offset + img.y_real;
            if !inside || l.height < least_height {
                continue;
            }
            let r = map.get(mover).map_or(l.radius, |m| m.radius);
            if near_path(path, (l.x, l.y), r + 2.0 * pixel) {
                continue;
            }
            let nearest = map
                .iter()
                .enumerate()
                .map(|(k, p)| (k, (p.x - l.x).hypot(p.y - l.y), p.radius))
                .min_by(|a, b| a.1.total_cmp(&b.1));
            // The mover, placed where the move left it, may be a little off: it matches within
            // a wider reach.
            let reach = |k: usize, r: f64| {
                if k == mover {
                    3.0 * r + 2.0 * pixel
                } else {
                    r.max(2.0 * pixel)
                }
            };
            match nearest {
                Some((k, d, r)) if d < reach(k, r) => {
                    if k != mover {
                        map[k] = Seen {
                            x: l.x,
                            y: l.y,
                            radius: l.radius,
                        };
                    }
                }
                _ => map.push(Seen {
                    x: l.x,
                    y: l.y,
                    radius: l.radius,
                }),
            }
        }
    }
}

/// Whether `p` lies within `reach` of the polyline `path`.
fn near_path(path: &[(f64, f64)], p: (f64, f64), reach: f64) -> bool {
    let seg = |a: (f64, f64), b: (f64, f64)| {
        let (dx, dy) = (b.0 - a.0, b.1 - a.1);
        let len2 = dx * dx + dy * dy;
        let t = if len2 > 0.0 {
            (((p.0 - a.0) * dx + (p.1 - a.1) * dy) / len2).clamp(0.0, 1.0)
        } else {
            0.0
        };
        (p.0 - a.0 - t * dx).hypot(p.1 - a.1 - t * dy)
    };
    match path {
        [] => false,
        [a] => seg(*a, *a) < reach,
        _ => path.windows(2).any(|w| seg(w[0], w[1]) < reach),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::physics::topography::Topography;
    use crate::scan::{Sphere, Surface, scan};

    const UM: f64 = 1e-6;

    /// A 128-pixel, 8 µm local scan of `spheres` centred at `c` (µm).
    fn local(spheres: &[(f64, f64)], c: (f64, f64)) -> HeightImage {
        let surface = Surface {
            topography: Topography::flat(),
            spheres: spheres
                .iter()
                .map(|&(x, y)| Sphere {
                    x: x * UM,
                    y: y * UM,
                    r: 0.5 * UM,
                })
                .collect(),
        };
        let p = ScanParams {
            centre_x: c.0 * UM,
            centre_y: c.1 * UM,
            size: 8.0 * UM,
            pixels: 128,
            noise_rms: 0.0,
            ..ScanParams::default()
        };
        scan(
            &surface,
            Tip {
                radius: 30e-9,
                half_angle: 0.3,
            },
            p,
        )
    }

    fn seen(x: f64, y: f64) -> Seen {
        Seen {
            x: x * UM,
            y: y * UM,
            radius: 0.5 * UM,
        }
    }

    /// The scan taken before a move shows the mover where it started: that is not a new particle.
    #[test]
    fn the_mover_seen_where_it_started_is_not_a_new_particle() {
        let before = local(&[(50.0, 50.0), (52.0, 51.0)], (50.0, 50.0));
        let after = local(&[(47.0, 50.0), (52.0, 51.0)], (47.0, 50.0));
        // The mover, placed where the move ended; its neighbour where the overview saw it.
        let mut map = vec![seen(47.0, 50.0), seen(52.1, 51.05)];
        let path = [(50.0 * UM, 50.0 * UM), (47.0 * UM, 50.0 * UM)];
        update_map(
            &mut map,
            0,
            &path,
            &[before, after],
            &Tip {
                radius: 30e-9,
                half_angle: 0.3,
            },
            0.0,
        );
        assert_eq!(map.len(), 2, "{map:?}");
        // The neighbour moved to where the scans found it.
        assert!(
            (map[1].x - 52.0 * UM).abs() < 30e-9 && (map[1].y - 51.0 * UM).abs() < 30e-9,
            "{:?}",
            map[1]
        );
        // A particle the overview missed, found beside the route, is added.
        let extra = local(&[(47.0, 50.0), (45.0, 52.5)], (47.0, 50.0));
        update_map(
            &mut map,
            0,
            &path,
            &[extra],
            &Tip {
                radius: 30e-9,
                half_angle: 0.3,
            },
            0.0,
        );
        assert_eq!(map.len(), 3, "{map:?}");
    }
}
