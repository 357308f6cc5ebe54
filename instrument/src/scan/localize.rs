//! Particle localization from a scan: from a click near a blob to the particle's centre and
//! radius, corrected for tip dilation.
//!
//! 1. Level: a plane fitted to the image by least squares, refitted three times on the pixels
//!    within 3σ of it (σ from the median absolute deviation), so particles do not tilt it; the
//!    detection threshold is `max(6σ, 0.5 nm)` above that plane.
//! 2. Apex: of the above-threshold pixels within the search radius, the one nearest the click,
//!    then steepest ascent over the 8 neighbours to the blob's top, then the vertex of a
//!    quadratic fitted to the 3×3 pixels around it (sub-pixel).
//! 3. Substrate level: the median of the raw heights in a ring just outside the blob's base
//!    (a symmetric ring's median is the level at its centre on a plane; neighbours that poke
//!    into the ring are outliers the median ignores).
//! 4. Size: apparent height `H` = apex − level. A sphere's image is `2Rₐ` high whatever the tip
//!    ([`super::dilation`]: the apex touches the top), so `Rₐ = H/2`. The cross-check is the
//!    width: the apparent base width (where 16 radial profiles meet the level) against the
//!    tip model's ([`Tip::sphere_base_width`]: `4 sqrt(Rₐ Rₜ)` on the apex, wider on the cone's
//!    flank), and the width at half height inverted through the model into a second radius. (The
//!    base width is pixel-limited: the image meets the substrate at a kink, which interpolation
//!    between pixels rounds off outward by up to a pixel; at half height both neighbours of the
//!    crossing lie on the flank.)
//! 5. Fit: the centre and radius of the sphere whose exact tip image
//!    ([`Tip::sphere_image_height`]) best fits the blob's pixels on the local substrate plane
//!    (least squares, Nelder-Mead from the apex and `H/2`). The sphere rests on the substrate at
//!    its centre, so the model is the higher of the plane and the sphere's image lifted to the
//!    plane's height at the centre — not the image added to the sloping plane, which shears it
//!    and puts the centre `≈ θ (Rₐ + Rₜ)/2` downhill (46 nm for 1 µm at 100 mrad). This is the estimate: with only a
//!    few pixels across the apex the height alone is biased by where the pixels fall (7 % for a
//!    0.5 µm particle at 390 nm pixels), the fit uses every pixel of the blob. The sphere's
//!    image is symmetric about its centre; the centre's height is `level + Rₐ`.

use super::image::HeightImage;
use super::tip::Tip;

/// Why no particle was found.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum LocateError {
    /// The click is outside the image.
    #[error("the point ({x:e}, {y:e}) m is outside the image [{x0:e}, {x1:e}] × [{y0:e}, {y1:e}] m")]
    OutsideImage {
        /// Click x (m).
        x: f64,
        /// Click y (m).
        y: f64,
        /// Image left edge (m).
        x0: f64,
        /// Image right edge (m).
        x1: f64,
        /// Image first-row edge (m).
        y0: f64,
        /// Image last-row edge (m).
        y1: f64,
    },
    /// Nothing stands above the substrate near the click.
    #[error(
        "no particle within {:.3} µm of ({:.3}, {:.3}) µm: no pixel there is more than {:.1} nm above the substrate",
        .searched * 1e6, .x * 1e6, .y * 1e6, .threshold * 1e9
    )]
    NoBlob {
        /// Click x (m).
        x: f64,
        /// Click y (m).
        y: f64,
        /// Search radius (m).
        searched: f64,
        /// Detection threshold above the levelled substrate (m).
        threshold: f64,
    },
}

/// A located particle (SI, m).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Located {
    /// Centre x: the apex's lateral position.
    pub x: f64,
    /// Centre y.
    pub y: f64,
    /// Centre height: `substrate + radius`.
    pub z: f64,
    /// Height of the apex in the image.
    pub apex: f64,
    /// Local substrate level (ring median).
    pub substrate: f64,
    /// Apparent height `H = apex − substrate`.
    pub height: f64,
    /// Apparent base width (mean over 16 radial profiles).
    pub base_width: f64,
    /// The base width the tip model predicts for [`Located::radius`].
    pub expected_width: f64,
    /// Apparent width at half height (mean over 16 radial profiles).
    pub half_height_width: f64,
    /// The estimate: radius of the sphere whose tip image best fits the blob's pixels (least
    /// squares, with the centre).
    pub radius: f64,
    /// Radius from the apparent height alone, `H/2`.
    pub radius_from_height: f64,
    /// Radius from the half-height width, inverting the tip model (the cross-check).
    pub radius_from_width: Option<f64>,
    /// The substrate's slope under the image, `(∂z/∂x, ∂z/∂y)`: the gradient of the robust plane
    /// the image is levelled by (a tilt the tip follows in a push that follows the slope).
    pub slope: (f64, f64),
}

/// Plane `z = a + b·col + c·row` and the residuals' robust σ.
#[derive(Debug, Clone, Copy)]
struct Level {
    a: f64,
    b: f64,
    c: f64,
    sigma: f64,
}

impl Level {
    fn at(&self, row: f64, col: f64) -> f64 {
        self.a + self.b * col + self.c * row
    }

    fn threshold(&self) -> f64 {
        (6.0 * self.sigma).max(0.5e-9)
    }
}

fn median(v: &mut [f64]) -> f64 {
    v.sort_by(|a, b| a.total_cmp(b));
    let n = v.len();
    if n == 0 {
        f64::NAN
    } else if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

/// The image with its substrate's plane taken off (the robust plane of [`find_particles`]): a
/// tilted sample's particles stand out in a picture.
pub fn levelled(img: &HeightImage) -> HeightImage {
    let lv = level(img);
    let mut out = img.clone();
    for (k, z) in out.data.iter_mut().enumerate() {
        *z -= lv.at((k / img.xres) as f64, (k % img.xres) as f64);
    }
    out
}

/// Robust plane: least squares on the pixels kept, keep those within 3σ, three times.
fn level(img: &HeightImage) -> Level {
    let mut keep = vec![true; img.data.len()];
    let mut lv = Level {
        a: 0.0,
        b: 0.0,
        c: 0.0,
        sigma: 0.0,
    };
    for _ in 0..4 {
        // Normal equations of z = a + b j + c i, centred coordinates.
        let (ci, cj) = (0.5 * (img.yres as f64 - 1.0), 0.5 * (img.xres as f64 - 1.0));
        let (mut n, mut sz, mut sjz, mut siz, mut sjj, mut sii, mut sij, mut sj, mut si) =
            (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0);
        for i in 0..img.yres {
            for j in 0..img.xres {
                if !keep[i * img.xres + j] {
                    continue;
                }
                let (u, v, z) = (j as f64 - cj, i as f64 - ci, img.at(i, j));
                n += 1.0;
                sz += z;
                sjz += u * z;
                siz += v * z;
                sjj += u * u;
                sii += v * v;
                sij += u * v;
                sj += u;
                si += v;
            }
        }
        // Solve the 3×3 system [n sj si; sj sjj sij; si sij sii] [a b c] = [sz sjz siz].
        let m = nalgebra::Matrix3::new(n, sj, si, sj, sjj, sij, si, sij, sii);
        let rhs = nalgebra::Vector3::new(sz, sjz, siz);
        let Some(sol) = m.lu().solve(&rhs) else { break };
        lv.a = sol[0] - sol[1] * cj - sol[2] * ci;
        lv.b = sol[1];
        lv.c = sol[2];
        let mut res: Vec<f64> = (0..img.data.len())
            .map(|k| (img.data[k] - lv.at((k / img.xres) as f64, (k % img.xres) as f64)).abs())
            .collect();
        let mut sorted = res.clone();
        lv.sigma = 1.4826 * median(&mut sorted);
        for (k, r) in res.iter_mut().enumerate() {
            keep[k] = *r <= 3.0 * lv.sigma.max(1e-15);
        }
    }
    lv
}

/// Steepest ascent over the 8 neighbours from `(i, j)` to a local maximum.
fn climb(img: &HeightImage, mut i: usize, mut j: usize) -> (usize, usize) {
    loop {
        let (mut bi, mut bj) = (i, j);
        for di in -1i64..=1 {
            for dj in -1i64..=1 {
                let (ni, nj) = (i as i64 + di, j as i64 + dj);
                if ni < 0 || nj < 0 || ni >= img.yres as i64 || nj >= img.xres as i64 {
                    continue;
                }
                if img.at(ni as usize, nj as usize) > img.at(bi, bj) {
                    (bi, bj) = (ni as usize, nj as usize);
                }
            }
        }
        if (bi, bj) == (i, j) {
            return (i, j);
        }
        (i, j) = (bi, bj);
    }
}

/// Vertex of the quadratic `z = a + b x + c y + d x² + e xy + f y²` fitted to the 3×3 pixels
/// around `(i, j)`: `(row, col, height)`. The pixel itself on the border or when the fit has no
/// maximum within a pixel.
fn refine(img: &HeightImage, i: usize, j: usize) -> (f64, f64, f64) {
    let z0 = img.at(i, j);
    if i == 0 || j == 0 || i + 1 >= img.yres || j + 1 >= img.xres {
        return (i as f64, j as f64, z0);
    }
    // Least squares on {-1, 0, 1}²; the basis 1, x, y, x² − ⅔, y² − ⅔, xy is orthogonal there.
    let (mut m, mut b, mut c, mut d, mut e, mut f) = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0);
    for di in -1i64..=1 {
        for dj in -1i64..=1 {
            let z = img.at((i as i64 + di) as usize, (j as i64 + dj) as usize);
            let (x, y) = (dj as f64, di as f64);
            m += z / 9.0;
            b += x * z / 6.0;
            c += y * z / 6.0;
            d += (x * x - 2.0 / 3.0) * z / 2.0;
            f += (y * y - 2.0 / 3.0) * z / 2.0;
            e += x * y * z / 4.0;
        }
    }
    let a = m - 2.0 / 3.0 * (d + f);
    // ∇ = 0: [2d e; e 2f] [x y] = −[b c]; a maximum needs d < 0 and det > 0.
    let det = 4.0 * d * f - e * e;
    if !(d < 0.0 && det > 0.0) {
        return (i as f64, j as f64, z0);
    }
    let x = (-b * 2.0 * f + c * e) / det;
    let y = (-c * 2.0 * d + b * e) / det;
    if x.abs() > 1.0 || y.abs() > 1.0 {
        return (i as f64, j as f64, z0);
    }
    let z = a + b * x + c * y + d * x * x + e * x * y + f * y * y;
    (i as f64 + y, j as f64 + x, z.max(z0))
}

/// Radius (pixels, along 16 directions) where `z − base(row, col)` first drops below `cut`,
/// linearly interpolated between samples a quarter pixel apart; the image edge ends a walk.
fn base_radii(img: &HeightImage, row: f64, col: f64, base: impl Fn(f64, f64) -> f64, cut: f64) -> Vec<f64> {
    let max_r = (img.xres.max(img.yres)) as f64;
    let step = 0.25;
    (0..16)
        .filter_map(|k| {
            let a = k as f64 * std::f64::consts::TAU / 16.0;
            let (sr, sc) = (a.sin(), a.cos());
            let mut prev = (0.0, img.sample(row, col) - base(row, col));
            let mut r = step;
            while r < max_r {
                let (rr, cc) = (row + r * sr, col + r * sc);
                if rr < 0.0 || cc < 0.0 || rr > (img.yres - 1) as f64 || cc > (img.xres - 1) as f64 {
                    return None;
                }
                let v = img.sample(rr, cc) - base(rr, cc);
                if v < cut {
                    let frac = if prev.1 > v { (prev.1 - cut) / (prev.1 - v) } else { 1.0 };
                    return Some(prev.0 + frac * step);
                }
                prev = (r, v);
                r += step;
            }
            None
        })
        .collect()
}

/// Measures the blob whose apex pixel is `(i, j)`.
fn measure(img: &HeightImage, tip: &Tip, lv: &Level, i: usize, j: usize) -> Located {
    let (row, col, apex) = refine(img, i, j);
    // Base from the levelled image, then the ring just outside it.
    let radii = base_radii(img, row, col, |r, c| lv.at(r, c), lv.threshold());
    let r_base = if radii.is_empty() {
        1.0
    } else {
        median(&mut radii.clone())
    };
    let inner = r_base + 2.0;
    let outer = inner + (0.5 * r_base).max(3.0);
    let mut ring = Vec::new();
    let (i0, i1) = (
        (row - outer).floor().max(0.0) as usize,
        ((row + outer).ceil() as usize).min(img.yres - 1),
    );
    let (j0, j1) = (
        (col - outer).floor().max(0.0) as usize,
        ((col + outer).ceil() as usize).min(img.xres - 1),
    );
    for ii in i0..=i1 {
        for jj in j0..=j1 {
            let d = ((ii as f64 - row).powi(2) + (jj as f64 - col).powi(2)).sqrt();
            if d >= inner && d <= outer {
                ring.push(img.at(ii, jj));
            }
        }
    }
    let substrate = if ring.is_empty() {
        lv.at(row, col)
    } else {
        median(&mut ring)
    };
    let height = apex - substrate;
    let radius = 0.5 * height;
    // The base width against the local level (the fitted plane's tilt, the ring's offset).
    let offset = substrate - lv.at(row, col);
    let cut = (3.0 * lv.sigma).max(0.01 * height).max(0.1e-9);
    let pitch = 0.5 * (img.dx() + img.dy());
    let mean_width = |cut: f64| {
        let radii = base_radii(img, row, col, |r, c| lv.at(r, c) + offset, cut);
        if radii.is_empty() {
            f64::NAN
        } else {
            2.0 * pitch * radii.iter().sum::<f64>() / radii.len() as f64
        }
    };
    let base_width = mean_width(cut);
    let half_height_width = mean_width(0.5 * height);
    // Model fit: centre and radius of the sphere whose tip image best matches the pixels of
    // the blob, on the local substrate plane.
    let reach = 0.5 * base_width.max(pitch) / pitch + 1.0;
    let mut pixels = Vec::new();
    for ii in (row - reach).floor().max(0.0) as usize..=((row + reach).ceil() as usize).min(img.yres - 1) {
        for jj in (col - reach).floor().max(0.0) as usize..=((col + reach).ceil() as usize).min(img.xres - 1) {
            if (ii as f64 - row).hypot(jj as f64 - col) <= reach {
                let local = lv.at(ii as f64, jj as f64) + offset;
                pixels.push((ii as f64, jj as f64, img.at(ii, jj) - local));
            }
        }
    }
    let (dx, dy) = (img.dx(), img.dy());
    // The sphere rests on the substrate at its centre, its top above its centre: the image is
    // the higher of the substrate and the sphere's image raised to the substrate's height at
    // the centre (not the sphere's image added to the sloping plane, which shears it: its top
    // would lie θ (Rₐ + Rₜ) uphill of its centre, and the fit would put the centre that far
    // downhill, 46 nm for 1 µm at 100 mrad).
    let cost = |v: &[f64; 3]| -> f64 {
        let (r0, c0, ra) = (v[0], v[1], v[2] * radius);
        if ra <= 0.0 {
            return f64::INFINITY;
        }
        let at_centre = lv.at(r0, c0);
        pixels
            .iter()
            .map(|&(r, c, z)| {
                let d = ((c - c0) * dx).hypot((r - r0) * dy);
                let rise = at_centre - lv.at(r, c);
                let m = (rise + tip.sphere_image_height(ra, d)).max(0.0);
                (z - m).powi(2)
            })
            .sum()
    };
    let fit = nelder_mead(cost, [row, col, 1.0], [0.3, 0.3, 0.03]);
    let (row_fit, col_fit, ra_fit) = (fit[0], fit[1], fit[2] * radius);
    // Trust the fit only where it stays on this blob (within a pixel of the apex).
    let (row, col, radius) = if (row_fit - row).hypot(col_fit - col) <= 1.0 && ra_fit > 0.0 {
        (row_fit, col_fit, ra_fit)
    } else {
        (row, col, radius)
    };
    Located {
        x: img.x_at(col),
        y: img.y_at(row),
        z: substrate + radius,
        apex,
        substrate,
        height,
        base_width,
        expected_width: tip.sphere_base_width(radius),
        half_height_width,
        radius,
        radius_from_height: 0.5 * height,
        radius_from_width: tip.radius_from_width(half_height_width, 0.5),
        slope: (lv.b / img.dx(), lv.c / img.dy()),
    }
}

/// Nelder-Mead minimisation of `f` from `x0` with initial steps `step` (Lagarias et al., SIAM
/// J. Optim. 9, 112 (1998): reflection 1, expansion 2, contraction ½, shrink ½), 400 steps at
/// most or until the simplex's values agree to 1e-12 relative.
fn nelder_mead(f: impl Fn(&[f64; 3]) -> f64, x0: [f64; 3], step: [f64; 3]) -> [f64; 3] {
    let mut pts: Vec<([f64; 3], f64)> = (0..4)
        .map(|k| {
            let mut p = x0;
            if k > 0 {
                p[k - 1] += step[k - 1];
            }
            (p, f(&p))
        })
        .collect();
    let along = |a: &[f64; 3], b: &[f64; 3], t: f64| -> [f64; 3] { std::array::from_fn(|k| a[k] + t * (b[k] - a[k])) };
    for _ in 0..400 {
        pts.sort_by(|a, b| a.1.total_cmp(&b.1));
        if (pts[3].1 - pts[0].1).abs() <= 1e-12 * pts[0].1.abs() + 1e-300 {
            break;
        }
        let centroid: [f64; 3] = std::array::from_fn(|k| (pts[0].0[k] + pts[1].0[k] + pts[2].0[k]) / 3.0);
        let worst = pts[3].0;
        let refl = along(&centroid, &worst, -1.0);
        let fr = f(&refl);
        if fr < pts[0].1 {
            let exp = along(&centroid, &worst, -2.0);
            let fe = f(&exp);
            pts[3] = if fe < fr { (exp, fe) } else { (refl, fr) };
        } else if fr < pts[2].1 {
            pts[3] = (refl, fr);
        } else {
            let con = if fr < pts[3].1 {
                along(&centroid, &worst, -0.5)
            } else {
                along(&centroid, &worst, 0.5)
            };
            let fc = f(&con);
            if fc < fr.min(pts[3].1) {
                pts[3] = (con, fc);
            } else {
                let best = pts[0].0;
                for p in pts.iter_mut().skip(1) {
                    p.0 = along(&best, &p.0, 0.5);
                    p.1 = f(&p.0);
                }
            }
        }
    }
    pts.sort_by(|a, b| a.1.total_cmp(&b.1));
    pts[0].0
}

/// The particle nearest the click `(x, y)` (m) within `search_radius` (m) of it.
pub fn localize(img: &HeightImage, tip: &Tip, x: f64, y: f64, search_radius: f64) -> Result<Located, LocateError> {
    let (x0, y0) = (img.x_offset, img.y_offset);
    let (x1, y1) = (x0 + img.x_real, y0 + img.y_real);
    if !(x >= x0 && x <= x1 && y >= y0 && y <= y1) {
        return Err(LocateError::OutsideImage { x, y, x0, x1, y0, y1 });
    }
    let lv = level(img);
    let (row, col) = (img.row_of(y), img.col_of(x));
    let (rr, rc) = (search_radius / img.dy(), search_radius / img.dx());
    let lo_i = (row - rr).floor().max(0.0) as usize;
    let hi_i = ((row + rr).ceil().max(0.0) as usize).min(img.yres - 1);
    let lo_j = (col - rc).floor().max(0.0) as usize;
    let hi_j = ((col + rc).ceil().max(0.0) as usize).min(img.xres - 1);
    let mut best: Option<(f64, usize, usize)> = None;
    for i in lo_i..=hi_i {
        for j in lo_j..=hi_j {
            let d = (img.x_at(j as f64) - x).hypot(img.y_at(i as f64) - y);
            if d > search_radius || img.at(i, j) - lv.at(i as f64, j as f64) <= lv.threshold() {
                continue;
            }
            if best.is_none_or(|(bd, _, _)| d < bd) {
                best = Some((d, i, j));
            }
        }
    }
    let Some((_, i, j)) = best else {
        return Err(LocateError::NoBlob {
            x,
            y,
            searched: search_radius,
            threshold: lv.threshold(),
        });
    };
    let (i, j) = climb(img, i, j);
    Ok(measure(img, tip, &lv, i, j))
}

/// Every particle in the image: each local maximum above the threshold, measured, with the
/// lower of two apexes closer than the higher one's base radius dropped (noise on one top).
pub fn find_particles(img: &HeightImage, tip: &Tip) -> Vec<Located> {
    let lv = level(img);
    let th = lv.threshold();
    let mut found: Vec<Located> = Vec::new();
    for i in 0..img.yres {
        for j in 0..img.xres {
            let z = img.at(i, j);
            if z - lv.at(i as f64, j as f64) <= th || climb(img, i, j) != (i, j) {
                continue;
            }
            found.push(measure(img, tip, &lv, i, j));
        }
    }
    found.sort_by(|a, b| b.height.total_cmp(&a.height));
    let mut kept: Vec<Located> = Vec::new();
    for p in found {
        if kept
            .iter()
            .all(|k| (k.x - p.x).hypot(k.y - p.y) > 0.5 * k.base_width.max(0.0))
        {
            kept.push(p);
        }
    }
    kept
}
