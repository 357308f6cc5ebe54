//! The sample as it is now: the substrate's topography and the spheres lying on it (SI, m).
//!
//! Positions are data: after a push the caller builds a new `Surface` (or edits `spheres`); the
//! scanner never reads particle positions from the scene.

use crate::physics::topography::Topography;
use crate::scene::Scene;

/// A spherical particle resting on the substrate: centre `(x, y)` (m), radius `r` (m). It sits on
/// the substrate height at its centre, so its centre is at `z_s(x, y) + r`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sphere {
    /// Centre x (m).
    pub x: f64,
    /// Centre y (m).
    pub y: f64,
    /// Radius (m).
    pub r: f64,
}

/// The sample surface: substrate plus spheres.
#[derive(Debug, Clone, PartialEq)]
pub struct Surface {
    /// The substrate's height `z_s(x, y)`.
    pub topography: Topography,
    /// The particles.
    pub spheres: Vec<Sphere>,
}

impl Surface {
    /// The scene's substrate and its particles at their scene positions.
    pub fn from_scene(scene: &Scene) -> Surface {
        Surface {
            topography: scene.topography(),
            spheres: scene
                .file
                .particles
                .iter()
                .map(|p| Sphere {
                    x: p.x_um * 1e-6,
                    y: p.y_um * 1e-6,
                    r: p.radius_nm * 1e-9,
                })
                .collect(),
        }
    }

    /// Height of a sphere's centre: it rests on the substrate at its centre (m).
    pub fn centre_z(&self, s: &Sphere) -> f64 {
        self.topography.height(s.x, s.y) + s.r
    }

    /// The true surface height `S(x, y)` (m): the highest of the substrate and the spheres'
    /// upper hemispheres. (What an infinitely sharp tip would record.)
    pub fn height(&self, x: f64, y: f64) -> f64 {
        let mut z = self.topography.height(x, y);
        for s in &self.spheres {
            let d2 = (x - s.x).powi(2) + (y - s.y).powi(2);
            if d2 < s.r * s.r {
                z = z.max(self.centre_z(s) + (s.r * s.r - d2).sqrt());
            }
        }
        z
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn from_scene_converts_units_and_spheres_rest_on_the_substrate() {
        let scene = Scene::default_scene();
        let s = Surface::from_scene(&scene);
        assert_eq!(s.spheres.len(), 1);
        let p = s.spheres[0];
        assert!((p.x - 50e-6).abs() < 1e-18 && (p.r - 1000e-9).abs() < 1e-20);
        let top = s.height(p.x, p.y);
        assert!((top - (s.topography.height(p.x, p.y) + 2.0 * p.r)).abs() < 1e-18);
        // Far from the particle, the substrate.
        assert_eq!(s.height(10e-6, 10e-6), s.topography.height(10e-6, 10e-6));
    }
}
