//! The plan's picture: the first full frame, levelled (its plane taken off), in viridis (row 0
//! at the top, as `final.png` and `nanopush scan` draw it), the particles the plan found outlined in white, each site a cyan
//! ring, and each move's route: orange for a fill, grey for a particle moved aside.

use nanopush_instrument::assembly::{Pattern, Plan, Purpose, Seen};
use nanopush_instrument::scan::{HeightImage, levelled, viridis};

/// An RGB canvas.
struct Canvas {
    w: usize,
    h: usize,
    rgb: Vec<u8>,
}

impl Canvas {
    fn put(&mut self, x: i64, y: i64, c: [u8; 3]) {
        if x >= 0 && y >= 0 && (x as usize) < self.w && (y as usize) < self.h {
            let i = 3 * (y as usize * self.w + x as usize);
            self.rgb[i..i + 3].copy_from_slice(&c);
        }
    }

    /// A line `width` pixels wide.
    fn line(&mut self, a: (f64, f64), b: (f64, f64), c: [u8; 3], width: i64) {
        let n = (b.0 - a.0).abs().max((b.1 - a.1).abs()).ceil().max(1.0) as usize;
        for k in 0..=n {
            let t = k as f64 / n as f64;
            let (x, y) = (a.0 + t * (b.0 - a.0), a.1 + t * (b.1 - a.1));
            for dx in -(width / 2)..=(width / 2) {
                for dy in -(width / 2)..=(width / 2) {
                    self.put(x.round() as i64 + dx, y.round() as i64 + dy, c);
                }
            }
        }
    }

    /// A ring of radius `r` pixels.
    fn ring(&mut self, centre: (f64, f64), r: f64, c: [u8; 3], width: i64) {
        let n = (std::f64::consts::TAU * r).ceil().max(16.0) as usize;
        let mut prev = (centre.0 + r, centre.1);
        for k in 1..=n {
            let a = std::f64::consts::TAU * k as f64 / n as f64;
            let p = (centre.0 + r * a.cos(), centre.1 + r * a.sin());
            self.line(prev, p, c, width);
            prev = p;
        }
    }
}

const WHITE: [u8; 3] = [255, 255, 255];
const CYAN: [u8; 3] = [0, 229, 255];
const ORANGE: [u8; 3] = [255, 140, 0];
const GREY: [u8; 3] = [170, 170, 170];

/// The picture as PNG bytes.
pub fn plan_png(img: &HeightImage, map: &[Seen], pattern: &Pattern, plan: &Plan) -> anyhow::Result<Vec<u8>> {
    // Large enough to see a route: the longer side near 1024 pixels.
    let img = &levelled(img);
    let scale = (1024 / img.xres.max(img.yres).max(1)).max(1);
    let (w, h) = (img.xres * scale, img.yres * scale);
    let (lo, hi) = img.z_range();
    let span = if hi > lo { hi - lo } else { 1.0 };
    let mut canvas = Canvas {
        w,
        h,
        rgb: vec![0; 3 * w * h],
    };
    for y in 0..h {
        for x in 0..w {
            let z = img.data[(y / scale) * img.xres + x / scale];
            let c = viridis((z - lo) / span);
            canvas.put(x as i64, y as i64, c.map(|v| (v * 255.0).round() as u8));
        }
    }
    let px = |p: (f64, f64)| {
        (
            (p.0 - img.x_offset) / img.x_real * w as f64,
            (p.1 - img.y_offset) / img.y_real * h as f64,
        )
    };
    let per_metre = w as f64 / img.x_real;
    for p in map {
        canvas.ring(px((p.x, p.y)), (p.radius * per_metre).max(3.0), WHITE, 1);
    }
    let site_r = pattern
        .radius
        .or_else(|| map.iter().map(|p| p.radius).reduce(f64::max))
        .unwrap_or(0.5e-6);
    for s in &pattern.sites {
        canvas.ring(px((s.x, s.y)), (1.4 * site_r * per_metre).max(5.0), CYAN, 2);
    }
    for m in &plan.moves {
        let colour = match m.purpose {
            Purpose::Fill { .. } => ORANGE,
            Purpose::Clear | Purpose::Park => GREY,
        };
        for leg in &m.legs {
            canvas.line(px(leg.from), px(leg.to), colour, 2);
        }
    }
    let mut out = Vec::new();
    {
        let mut enc = png::Encoder::new(&mut out, w as u32, h as u32);
        enc.set_color(png::ColorType::Rgb);
        enc.set_depth(png::BitDepth::Eight);
        enc.write_header()?.write_image_data(&canvas.rgb)?;
    }
    Ok(out)
}
