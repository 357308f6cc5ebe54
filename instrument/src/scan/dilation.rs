//! The image a tip records: the grey-scale dilation of the surface by the tip (Villarrubia).
//!
//! With the tip's apex at lateral position `x`, lowered until it first touches the surface, the
//! recorded height is
//!
//! ```text
//! I(x) = max_u [ S(x + u) − P(u) ]
//! ```
//!
//! where `S` is the surface height and `P(u) ≥ 0` the tip's profile above its apex
//! ([`super::tip::Tip::profile`]). This is the grey-scale dilation of Villarrubia, *Algorithms
//! for scanned probe microscope image simulation, surface reconstruction, and tip estimation*,
//! J. Res. Natl. Inst. Stand. Technol. 102, 425 (1997), Eq. 7, which Gwyddion implements for
//! height maps (`gwy_tip_dilation`). The image of a union is the max of the images, so the
//! substrate and each sphere are imaged apart and the highest wins ([`image_height`]):
//!
//! - a sphere, exactly ([`sphere_image`]): the tip touches a ball of radius `Rₐ` when the ball's
//!   centre lies on the tip grown by `Rₐ` (apex radius `Rₜ + Rₐ`, same cone, same sphere
//!   centre), so with the ball's centre at height `z_c` and lateral distance `d`,
//!   `I = z_c + Rₐ − P'(d)`. On the apex sphere this is the sphere-sphere contact
//!   `I = z_c − Rₜ + sqrt((Rₜ + Rₐ)² − d²)`, on the flank the sphere-cone contact.
//! - the substrate, numerically ([`substrate_image`]): for a smooth surface the maximum is where
//!   the slopes match, `∇P(u) = ∇z_s(x + u)`; on the apex sphere `∇P(u) = u/sqrt(Rₜ² − |u|²)`,
//!   so `u = Rₜ g/sqrt(1 + |g|²)` with `g = ∇z_s(x + u)`, solved by fixed-point iteration (exact
//!   for a plane, a contraction while `Rₜ` times the substrate's curvature is below 1).
//! - a height map by a tip map ([`grid_dilation`]), as Gwyddion does: the plain definition on
//!   pixels, used to check the other two.

use super::surface::{Sphere, Surface};
use super::tip::Tip;
use crate::physics::topography::Topography;

/// Fixed-point iterations of [`substrate_image`]: each multiplies the error in `u` by about
/// `Rₜ κ` (κ the substrate's curvature).
const SUBSTRATE_ITERATIONS: usize = 4;
/// Rings and directions of the coarse search of [`substrate_image`].
const RINGS: usize = 4;
const DIRECTIONS: usize = 12;
/// Halvings of the pattern search that refines the best coarse point.
const REFINEMENTS: usize = 10;

/// Image of the bare substrate at `(x, y)` (m): `max_u [z_s(x + u) − P(u)]` over the apex
/// sphere `|u| ≤ Rₜ cos θ` (substrate slopes are below the cone's, `|∇z_s| < cot θ`).
///
/// A flat substrate is its own image. Otherwise the candidates are the slope-matching fixed
/// point (exact on a plane), `u = 0`, and the best of a coarse polar search (4 rings × 12
/// directions) refined by a pattern search: roughness whose curvature radius is below `Rₜ`
/// has several local maxima, which the fixed point alone can miss.
pub fn substrate_image(topo: &Topography, tip: &Tip, x: f64, y: f64) -> f64 {
    let z0 = topo.height(x, y);
    if topo.is_flat() {
        return z0;
    }
    let rt = tip.radius;
    let r_max = tip.apex_edge();
    let value = |ux: f64, uy: f64| -> f64 {
        let r = (ux * ux + uy * uy).sqrt();
        if r > r_max {
            f64::NEG_INFINITY
        } else {
            topo.height(x + ux, y + uy) - tip.profile(r)
        }
    };
    let (mut ux, mut uy) = (0.0, 0.0);
    for _ in 0..SUBSTRATE_ITERATIONS {
        let (gx, gy) = topo.gradient(x + ux, y + uy);
        let n = (1.0 + gx * gx + gy * gy).sqrt();
        ux = rt * gx / n;
        uy = rt * gy / n;
    }
    let mut best = (ux, uy, value(ux, uy));
    if z0 > best.2 {
        best = (0.0, 0.0, z0);
    }
    // A surface curved less than the tip (`Rₜ κ < 1/2`, roughness much wider than the apex)
    // makes `z_s(x + u) − P(u)` strictly concave over the apex: its one maximum is the fixed
    // point, found to `(Rₜ κ)⁴` of its error, and there is nothing to search for.
    if rt * topo.curvature_bound() < 0.5 {
        return best.2;
    }
    // The coarse search finds the basin of the global maximum; the pattern search climbs it.
    // A point whose plane plus the roughness's largest excursion, less the tip's profile, is
    // no higher than the best so far cannot beat it, and is not evaluated.
    let rough = topo.roughness_bound();
    let cannot_beat = |ux: f64, uy: f64, best: f64| {
        let r = (ux * ux + uy * uy).sqrt();
        r > r_max || topo.plane(x + ux, y + uy) + rough - tip.profile(r) <= best
    };
    let (mut cx, mut cy, mut cz) = (0.0, 0.0, z0);
    for k in 1..=RINGS {
        let r = r_max * k as f64 / RINGS as f64;
        for d in 0..DIRECTIONS {
            let a = d as f64 * std::f64::consts::TAU / DIRECTIONS as f64;
            let (px, py) = (r * a.cos(), r * a.sin());
            if cannot_beat(px, py, cz) {
                continue;
            }
            let v = value(px, py);
            if v > cz {
                (cx, cy, cz) = (px, py, v);
            }
        }
    }
    let mut step = 0.5 * r_max / RINGS as f64;
    for _ in 0..REFINEMENTS {
        for (sx, sy) in [(1.0, 0.0), (-1.0, 0.0), (0.0, 1.0), (0.0, -1.0)] {
            let (px, py) = (cx + sx * step, cy + sy * step);
            if cannot_beat(px, py, cz) {
                continue;
            }
            let v = value(px, py);
            if v > cz {
                (cx, cy, cz) = (px, py, v);
            }
        }
        step *= 0.5;
    }
    best.2.max(cz)
}

/// Image of one sphere whose centre is at height `zc` (m), at lateral `(x, y)`:
/// `z_c + Rₐ − P'(d)`, `P'` the profile of the tip grown by `Rₐ`. `−∞` where the tip cannot
/// touch it (a cylinder-sided tip, `θ = 0`, beyond `Rₜ + Rₐ`).
pub fn sphere_image(tip: &Tip, s: &Sphere, zc: f64, x: f64, y: f64) -> f64 {
    let d = ((x - s.x).powi(2) + (y - s.y).powi(2)).sqrt();
    zc + s.r - tip.grown(s.r).profile(d)
}

/// The recorded height at `(x, y)` (m): the max of the substrate's and every sphere's image.
pub fn image_height(surface: &Surface, tip: &Tip, x: f64, y: f64) -> f64 {
    let mut z = substrate_image(&surface.topography, tip, x, y);
    for s in &surface.spheres {
        z = z.max(sphere_image(tip, s, surface.centre_z(s), x, y));
    }
    z
}

/// The tip as a height map on a square grid of pitch `dx` (m), `2h + 1` pixels a side, apex at
/// the centre: `P` at each pixel centre, row-major.
pub fn tip_map(tip: &Tip, dx: f64, h: usize) -> Vec<f64> {
    let n = 2 * h + 1;
    let mut m = Vec::with_capacity(n * n);
    for i in 0..n {
        for j in 0..n {
            let (u, v) = ((j as f64 - h as f64) * dx, (i as f64 - h as f64) * dx);
            m.push(tip.profile((u * u + v * v).sqrt()));
        }
    }
    m
}

/// Grey-scale dilation of a height map (`nx × ny`, row-major) by a tip map of side `2h + 1`
/// with its apex at the centre: `I[i, j] = max_{k,l} S[i + k, j + l] − T[k, l]` over the tip
/// pixels that fall inside the map (Villarrubia Eq. 7 on pixels; Gwyddion's `gwy_tip_dilation`).
pub fn grid_dilation(surface: &[f64], nx: usize, ny: usize, tip: &[f64], h: usize) -> Vec<f64> {
    let n = 2 * h + 1;
    assert_eq!(surface.len(), nx * ny, "surface map size");
    assert_eq!(tip.len(), n * n, "tip map size");
    let mut out = vec![f64::NEG_INFINITY; nx * ny];
    for i in 0..ny {
        for j in 0..nx {
            let mut best = f64::NEG_INFINITY;
            for k in 0..n {
                let si = i as isize + k as isize - h as isize;
                if si < 0 || si >= ny as isize {
                    continue;
                }
                let row = &surface[si as usize * nx..(si as usize + 1) * nx];
                let trow = &tip[k * n..(k + 1) * n];
                for (l, t) in trow.iter().enumerate() {
                    let sj = j as isize + l as isize - h as isize;
                    if sj >= 0 && sj < nx as isize {
                        best = best.max(row[sj as usize] - t);
                    }
                }
            }
            out[i * nx + j] = best;
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    const NM: f64 = 1e-9;

    fn tip() -> Tip {
        Tip {
            radius: 30.0 * NM,
            half_angle: 20f64.to_radians(),
        }
    }

    /// Analytic image of a sphere on a flat substrate against the pixel dilation of its sampled
    /// height map, in the apex regime (10 nm) and the flank regime (40 nm).
    #[test]
    fn sphere_image_agrees_with_grid_dilation() {
        let t = tip();
        let dx = 1.0 * NM;
        let half = 90usize;
        let n = 2 * half + 1;
        for ra_nm in [10.0, 40.0] {
            let surface = Surface {
                topography: Topography::flat(),
                spheres: vec![Sphere {
                    x: 0.0,
                    y: 0.0,
                    r: ra_nm * NM,
                }],
            };
            let coord = |k: usize| (k as f64 - half as f64) * dx;
            let mut s = Vec::with_capacity(n * n);
            for i in 0..n {
                for j in 0..n {
                    s.push(surface.height(coord(j), coord(i)));
                }
            }
            // Tip pixels out to where P exceeds the sphere's height 2Rₐ: they never win.
            let h = (1..).find(|&k| t.profile(k as f64 * dx) > 2.0 * ra_nm * NM).unwrap();
            let img = grid_dilation(&s, n, n, &tip_map(&t, dx, h), h);
            let mut worst: f64 = 0.0;
            for i in h..n - h {
                for j in h..n - h {
                    let exact = image_height(&surface, &t, coord(j), coord(i));
                    worst = worst.max((img[i * n + j] - exact).abs());
                    // The pixel dilation maximises over fewer points: never above the exact.
                    assert!(img[i * n + j] <= exact + 1e-15);
                }
            }
            // Pixel sampling of the sphere's steep rim: within half a pixel's height change.
            assert!(worst < 0.5 * dx, "Rₐ = {ra_nm} nm: worst {:.3} nm", worst / NM);
            // Apparent height 2Rₐ and base width from geometry.
            let c = half * n + half;
            assert!((img[c] - 2.0 * ra_nm * NM).abs() < 1e-15);
            let w = t.sphere_base_width(ra_nm * NM);
            let edge = |k: usize| img[half * n + half + k] > 1e-12;
            let k_in = ((0.5 * w / dx).floor() as usize).min(half - 1);
            assert!(
                edge(k_in - 1) && !edge(k_in + 2),
                "Rₐ = {ra_nm}: base half-width {:.2} nm",
                0.5 * w / NM
            );
        }
    }

    #[test]
    fn tilted_plane_image_is_exact() {
        // A plane of slope t under a sphere of radius Rₜ is touched where the normals match:
        // I = z_s(x) + Rₜ (sqrt(1 + t²) − 1).
        let t = tip();
        let topo = Topography::new(0.08, -0.05, 0.0, 1e-6, 1);
        let (x, y) = (3e-6, 4e-6);
        let g2: f64 = 0.08f64.powi(2) + 0.05f64.powi(2);
        let exact = topo.height(x, y) + t.radius * ((1.0 + g2).sqrt() - 1.0);
        assert!((substrate_image(&topo, &t, x, y) - exact).abs() < 1e-18);
    }

    #[test]
    fn rough_substrate_image_matches_brute_force() {
        // The strongest roughness the scene allows at its shortest wavelength.
        let t = tip();
        let topo = Topography::new(0.02, 0.0, 5.0 * NM, 0.1e-6, 3);
        let du = 0.25 * NM;
        for (x, y) in [(1e-6, 2e-6), (1.37e-6, 0.4e-6), (0.0, 0.0)] {
            let mut best = f64::NEG_INFINITY;
            for i in -60i32..=60 {
                for j in -60i32..=60 {
                    let (u, v) = (j as f64 * du, i as f64 * du);
                    best = best.max(topo.height(x + u, y + v) - t.profile((u * u + v * v).sqrt()));
                }
            }
            let fast = substrate_image(&topo, &t, x, y);
            // Brute force on a 0.25 nm grid is below the true max by < P's change over a
            // quarter pixel near the optimum: a few fm.
            assert!(fast >= best - 1e-14 && fast - best < 1e-12, "{:e} vs {:e}", fast, best);
        }
    }
}
