//! PNG preview of a height image: viridis colours (perceptually uniform, readable in grey and
//! by colour-blind readers) from the lowest to the highest height; row 0 at the top, as
//! Gwyddion shows it.

use std::io::Write;

use super::image::HeightImage;

/// Viridis at `t ∈ [0, 1]` as linear-looking sRGB in `[0, 1]`: the degree-6 polynomial fit of
/// matplotlib's viridis by Matt Zucker (Shadertoy "Colormap polynomials", CC0), within about
/// 0.01 of the published table.
pub fn viridis(t: f64) -> [f64; 3] {
    const C: [[f64; 3]; 7] = [
        [
            0.277_727_327_223_417_7,
            0.005_407_344_544_966_578,
            0.334_099_805_335_306_1,
        ],
        [0.105_093_043_108_577_4, 1.404_613_529_898_575, 1.384_590_162_594_685],
        [
            -0.330_861_828_725_556_3,
            0.214_847_559_468_213,
            0.095_095_163_028_236_59,
        ],
        [-4.634_230_498_983_486, -5.799_100_973_351_585, -19.332_440_956_279_87],
        [6.228_269_936_347_081, 14.179_933_366_805_09, 56.690_552_600_681_05],
        [4.776_384_997_670_288, -13.745_145_377_746_01, -65.353_032_633_372_34],
        [-5.435_455_855_934_631, 4.645_852_612_178_535, 26.312_435_249_583_2],
    ];
    let t = t.clamp(0.0, 1.0);
    let mut rgb = [0.0; 3];
    for (k, out) in rgb.iter_mut().enumerate() {
        *out = C.iter().rev().fold(0.0, |acc, c| acc * t + c[k]).clamp(0.0, 1.0);
    }
    rgb
}

/// Writes `img` as an 8-bit RGB PNG, the lowest height dark blue, the highest yellow.
pub fn write_png(w: impl Write, img: &HeightImage) -> Result<(), png::EncodingError> {
    let (lo, hi) = img.z_range();
    let span = if hi > lo { hi - lo } else { 1.0 };
    let mut rgb = Vec::with_capacity(img.data.len() * 3);
    for &z in &img.data {
        for c in viridis((z - lo) / span) {
            rgb.push((c * 255.0).round() as u8);
        }
    }
    let mut enc = png::Encoder::new(w, img.xres as u32, img.yres as u32);
    enc.set_color(png::ColorType::Rgb);
    enc.set_depth(png::BitDepth::Eight);
    let mut writer = enc.write_header()?;
    writer.write_image_data(&rgb)?;
    writer.finish()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn viridis_matches_the_published_table() {
        // matplotlib's _viridis_data at 0, 0.5 and 1.
        let table = [
            (0.0, [0.267_004, 0.004_874, 0.329_415]),
            (0.5, [0.127_568, 0.566_949, 0.550_556]),
            (1.0, [0.993_248, 0.906_157, 0.143_936]),
        ];
        for (t, want) in table {
            let got = viridis(t);
            for k in 0..3 {
                assert!((got[k] - want[k]).abs() < 0.015, "t = {t}: {got:?} vs {want:?}");
            }
        }
        // Lightness (a luma proxy) rises monotonically: a height map reads as a height map.
        let luma = |c: [f64; 3]| 0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2];
        for k in 0..100 {
            assert!(luma(viridis((k + 1) as f64 / 100.0)) > luma(viridis(k as f64 / 100.0)));
        }
    }

    #[test]
    fn png_decodes_to_the_image_size() {
        let img = HeightImage {
            xres: 7,
            yres: 3,
            x_real: 1.0,
            y_real: 1.0,
            x_offset: 0.0,
            y_offset: 0.0,
            data: (0..21).map(|k| k as f64).collect(),
        };
        let mut buf = Vec::new();
        write_png(&mut buf, &img).unwrap();
        let dec = png::Decoder::new(std::io::Cursor::new(buf));
        let reader = dec.read_info().unwrap();
        let info = reader.info();
        assert_eq!((info.width, info.height), (7, 3));
        assert_eq!(info.color_type, png::ColorType::Rgb);
    }
}
