//! How an assembly's move finds its particle and routes its legs: a local scan around where
//! the map says it is, and the legs around every other particle of the map ([`PlanSettings`]'s
//! router), never an overview scan. Every local scan is kept, so that the map learns from it
//! where the particles around the move are now.

use crate::afm::Afm;
use crate::control::moves::DONE_WITHIN;
use crate::control::moves::locate::{MoveError, MoveRoute, MoveTarget, locate_near};
use crate::control::moves::run::MoveRouting;
use crate::control::route::Obstacle;
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
        let from = (located.x, located.y);
        let to = target.point(from);
        let legs = if (to.0 - from.0).hypot(to.1 - from.1) < DONE_WITHIN {
            Vec::new()
        } else {
            let obstacles: Vec<Obstacle> = self
                .map
                .iter()
                .enumerate()
                .filter(|&(k, _)| k != self.mover)
                .map(|(_, p)| Obstacle {
                    x: p.x,
                    y: p.y,
                    radius: p.radius,
                })
                .collect();
            let mut router = self.settings.router(located.radius);
            router.edge_radius = radius_hint;
            router.route(from, to, &obstacles)?
        };
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

/// The map updated from a move's local scans: each particle found in them moves to where it
/// was found (the one nearest it, within its radius or two pixels); a particle found that the
/// map does not hold is added (the overview's pixels may have hidden it). The mover must be
/// placed first where the move says it ended: a find near there is the mover, and stays as the
/// move measured it.
pub fn update_map(map: &mut Vec<Seen>, mover: usize, images: &[HeightImage], tip: &Tip, noise_rms: f64) {
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
