//! Gwyddion Simple Field (`.gsf`) files: write and read back.
//!
//! Format (<http://gwyddion.net/documentation/user-guide-en/gsf.html>): the magic line
//! `Gwyddion Simple Field 1.0\n`, then `Key = Value\n` lines (`XRes`, `YRes` required; `XReal`,
//! `YReal`, `XOffset`, `YOffset`, `XYUnits`, `ZUnits`, `Title` optional), then 1 to 4 NUL bytes
//! so that the header's length becomes a multiple of 4 (4 NULs when it already is), then
//! `XRes × YRes` little-endian IEEE `f32`, row-major. We write SI metres.

use std::io::{Read, Write};

use super::image::HeightImage;

const MAGIC: &str = "Gwyddion Simple Field 1.0\n";

/// Why a GSF file could not be read.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum GsfError {
    /// Reading or writing failed.
    #[error("GSF I/O: {0}")]
    Io(#[from] std::io::Error),
    /// The first line is not the GSF magic line.
    #[error("not a Gwyddion Simple Field file (the first line is not `Gwyddion Simple Field 1.0`)")]
    BadMagic,
    /// A header line or value is malformed, or a required key is missing.
    #[error("GSF header: {0}")]
    Header(String),
    /// The data size does not match `XRes × YRes`.
    #[error("GSF data: {found} bytes after the header, expected {expected} (XRes × YRes × 4)")]
    DataSize {
        /// Bytes expected.
        expected: usize,
        /// Bytes found.
        found: usize,
    },
}

/// The header text of `img` with its NUL padding, as written before the data.
pub fn header(img: &HeightImage, title: &str) -> Vec<u8> {
    // A newline in the title would end its header line early.
    let title: String = title.chars().map(|c| if c.is_control() { ' ' } else { c }).collect();
    let mut h = String::from(MAGIC);
    h += &format!("XRes = {}\nYRes = {}\n", img.xres, img.yres);
    h += &format!("XReal = {:e}\nYReal = {:e}\n", img.x_real, img.y_real);
    h += &format!("XOffset = {:e}\nYOffset = {:e}\n", img.x_offset, img.y_offset);
    h += &format!("XYUnits = m\nZUnits = m\nTitle = {title}\n");
    let mut bytes = h.into_bytes();
    let pad = 4 - bytes.len() % 4;
    bytes.extend(std::iter::repeat_n(0u8, pad));
    bytes
}

/// Writes `img` as GSF: header, padding, `f32` little-endian rows.
pub fn write_gsf(w: &mut impl Write, img: &HeightImage, title: &str) -> Result<(), GsfError> {
    w.write_all(&header(img, title))?;
    let mut buf = Vec::with_capacity(img.data.len() * 4);
    for &z in &img.data {
        buf.extend_from_slice(&(z as f32).to_le_bytes());
    }
    w.write_all(&buf)?;
    Ok(())
}

/// A GSF file read back: the image (heights widened to `f64`) and its title.
#[derive(Debug, Clone, PartialEq)]
pub struct GsfFile {
    /// The image.
    pub image: HeightImage,
    /// The `Title` key, empty when absent.
    pub title: String,
}

/// Reads a GSF file (any keys; `XRes`, `YRes` required; lengths default to 1, offsets to 0).
pub fn read_gsf(r: &mut impl Read) -> Result<GsfFile, GsfError> {
    let mut all = Vec::new();
    r.read_to_end(&mut all)?;
    if !all.starts_with(MAGIC.as_bytes()) {
        return Err(GsfError::BadMagic);
    }
    let nul = all
        .iter()
        .position(|&b| b == 0)
        .ok_or_else(|| GsfError::Header("no NUL padding after the header".into()))?;
    let text =
        std::str::from_utf8(&all[MAGIC.len()..nul]).map_err(|_| GsfError::Header("the header is not UTF-8".into()))?;
    let data_start = nul + (4 - nul % 4);
    if all.len() < data_start || all[nul..data_start].iter().any(|&b| b != 0) {
        return Err(GsfError::Header(format!(
            "expected {} NUL bytes of padding after a {nul}-byte header",
            data_start - nul
        )));
    }
    let (mut xres, mut yres, mut title) = (None, None, String::new());
    let (mut x_real, mut y_real, mut x_offset, mut y_offset) = (1.0, 1.0, 0.0, 0.0);
    for line in text.lines().filter(|l| !l.trim().is_empty()) {
        let (k, v) = line
            .split_once('=')
            .ok_or_else(|| GsfError::Header(format!("line without `=`: {line:?}")))?;
        let (k, v) = (k.trim(), v.trim());
        let num = |v: &str| {
            v.parse::<f64>()
                .map_err(|_| GsfError::Header(format!("{k} = {v:?} is not a number")))
        };
        let res = |v: &str| {
            v.parse::<usize>()
                .ok()
                .filter(|&n| n > 0)
                .ok_or_else(|| GsfError::Header(format!("{k} = {v:?} is not a positive integer")))
        };
        match k {
            "XRes" => xres = Some(res(v)?),
            "YRes" => yres = Some(res(v)?),
            "XReal" => x_real = num(v)?,
            "YReal" => y_real = num(v)?,
            "XOffset" => x_offset = num(v)?,
            "YOffset" => y_offset = num(v)?,
            "Title" => title = v.to_string(),
            _ => {}
        }
    }
    let xres = xres.ok_or_else(|| GsfError::Header("XRes is missing".into()))?;
    let yres = yres.ok_or_else(|| GsfError::Header("YRes is missing".into()))?;
    let expected = xres * yres * 4;
    let found = all.len() - data_start;
    if found != expected {
        return Err(GsfError::DataSize { expected, found });
    }
    let data = all[data_start..]
        .chunks_exact(4)
        .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]) as f64)
        .collect();
    Ok(GsfFile {
        image: HeightImage {
            xres,
            yres,
            x_real,
            y_real,
            x_offset,
            y_offset,
            data,
        },
        title,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn img(xres: usize, yres: usize) -> HeightImage {
        HeightImage {
            xres,
            yres,
            x_real: 50e-6,
            y_real: 25e-6,
            x_offset: 25e-6,
            y_offset: 37.5e-6,
            data: (0..xres * yres).map(|k| k as f64 * 1e-9 - 3e-9).collect(),
        }
    }

    #[test]
    fn round_trip() {
        let a = img(5, 3);
        let mut buf = Vec::new();
        write_gsf(&mut buf, &a, "scan of\nparticles").unwrap();
        let back = read_gsf(&mut buf.as_slice()).unwrap();
        assert_eq!(back.title, "scan of particles");
        let b = back.image;
        assert_eq!((b.xres, b.yres), (5, 3));
        assert_eq!(
            (b.x_real, b.y_real, b.x_offset, b.y_offset),
            (a.x_real, a.y_real, a.x_offset, a.y_offset)
        );
        for (x, y) in a.data.iter().zip(&b.data) {
            // f32 keeps 24 bits: relative 6e-8.
            assert!((x - y).abs() <= 1e-7 * x.abs(), "{x:e} {y:e}");
        }
    }

    #[test]
    fn padding_is_one_to_four_nuls_to_a_multiple_of_four() {
        // Titles of every length modulo 4 cover both the aligned case (4 NULs) and the others.
        let mut seen = [false; 5];
        for n in 0..8 {
            let title = "t".repeat(n);
            let h = header(&img(2, 2), &title);
            assert_eq!(h.len() % 4, 0);
            let text_len = h.iter().position(|&b| b == 0).unwrap();
            let pad = h.len() - text_len;
            assert!((1..=4).contains(&pad), "pad {pad}");
            assert!(h[text_len..].iter().all(|&b| b == 0));
            if text_len % 4 == 0 {
                assert_eq!(pad, 4, "an aligned header still gets 4 NULs");
            }
            seen[pad] = true;
            let mut buf = Vec::new();
            write_gsf(&mut buf, &img(2, 2), &title).unwrap();
            assert_eq!(read_gsf(&mut buf.as_slice()).unwrap().title, title);
        }
        assert!(seen[1..].iter().all(|&s| s), "every padding length occurred: {seen:?}");
    }

    #[test]
    fn bad_files_are_rejected() {
        let mut buf = Vec::new();
        write_gsf(&mut buf, &img(3, 3), "x").unwrap();
        let short = &buf[..buf.len() - 4];
        assert!(matches!(
            read_gsf(&mut &short[..]),
            Err(GsfError::DataSize {
                expected: 36,
                found: 32
            })
        ));
        assert!(matches!(
            read_gsf(&mut &b"Gwyddion Simple Field 2.0\n\0\0"[..]),
            Err(GsfError::BadMagic)
        ));
        let no_xres = b"Gwyddion Simple Field 1.0\nYRes = 1\n\0\0\0\0\0\0";
        assert!(matches!(read_gsf(&mut &no_xres[..]), Err(GsfError::Header(m)) if m.contains("XRes")));
    }
}
