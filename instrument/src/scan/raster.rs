//! The raster: a tapping-mode scan of a [`Surface`], one trace line at a time.
//!
//! Line `i` of `N` is traced left to right in the first half of its period `1/f_line` (the
//! retrace, not recorded, takes the second half); pixel `j` is recorded at
//! `t = (i + ½ (j + ½)/N) / f_line` from the start of the frame. The commanded position is the
//! pixel centre `(x_j, y_i)`; the tip actually stands at
//!
//! ```text
//! x = x_j − (h S / 2) sin(π (j + ½)/N) + v_x t
//! y = y_i − (h S / 2) sin(π (i + ½)/N) + v_y t
//! ```
//!
//! - hysteresis: on a sweep the piezo lags its command by up to half the hysteresis loop's width
//!   `h S` (`h` the hysteresis as a fraction of the travel `S`, the figure piezo data sheets
//!   quote: 0.1 % for the paper's closed-loop P-762.3L, 10-15 % open loop), largest mid-sweep and
//!   zero at the turning points: a half-sine, the simplest loop with those properties;
//! - drift: thermal drift and creep move the tip relative to the sample at a constant `v`;
//!
//! and records the tip image ([`super::dilation::image_height`]) there, plus the z drift
//! `v_z t` and white Gaussian noise of RMS `σ`. Tapping never moves particles: the scanner only
//! borrows the surface.

use rand::SeedableRng;
use rand::rngs::SmallRng;
use rand_distr::{Distribution, Normal};

use super::dilation::image_height;
use super::image::HeightImage;
use super::surface::Surface;
use super::tip::Tip;
use crate::scene::Scene;
use crate::scene::file::ScanFile;

/// Scan settings, SI. The defaults equal the scene's `[scan]` defaults (tested).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ScanParams {
    /// Centre of the scanned square, x (m). Default 50 µm, the middle of the paper's 100 µm stage.
    pub centre_x: f64,
    /// Centre, y (m). Default 50 µm.
    pub centre_y: f64,
    /// Side of the scanned square `S` (m). Default 50 µm.
    pub size: f64,
    /// Pixels per line and lines `N`. Default 256.
    pub pixels: usize,
    /// Lines per second `f_line` (Hz). Default 1 Hz, a usual tapping-mode rate.
    pub line_rate: f64,
    /// RMS of the height noise `σ` (m). Default 0.2 nm (tapping-mode z noise is 0.05-0.3 nm).
    pub noise_rms: f64,
    /// Seed of the noise. Default 1.
    pub noise_seed: u64,
    /// Drift of the tip relative to the sample along x (m/s). Default 0.
    pub drift_x: f64,
    /// Drift along y (m/s). Default 0.
    pub drift_y: f64,
    /// Drift of the recorded height (m/s). Default 0.
    pub drift_z: f64,
    /// Hysteresis `h` as a fraction of the scan size. Default 0 (a closed-loop stage; the
    /// paper's P-762.3L quotes 0.001).
    pub hysteresis: f64,
}

impl Default for ScanParams {
    /// The scene's defaults ([`ScanFile::default`]) in SI.
    fn default() -> ScanParams {
        ScanParams::from_file(&ScanFile::default())
    }
}

impl ScanParams {
    /// The scene's `[scan]` section in SI.
    pub fn from_scene(scene: &Scene) -> ScanParams {
        ScanParams::from_file(&scene.file.scan)
    }

    /// A `[scan]` section in SI.
    pub fn from_file(s: &ScanFile) -> ScanParams {
        ScanParams {
            centre_x: s.centre_x_um * 1e-6,
            centre_y: s.centre_y_um * 1e-6,
            size: s.size_um * 1e-6,
            pixels: s.pixels as usize,
            line_rate: s.line_rate_hz,
            noise_rms: s.noise_rms_nm * 1e-9,
            noise_seed: s.noise_seed,
            drift_x: s.drift_x_nm_per_s * 1e-9,
            drift_y: s.drift_y_nm_per_s * 1e-9,
            drift_z: s.drift_z_nm_per_s * 1e-9,
            hysteresis: s.hysteresis_percent * 1e-2,
        }
    }

    /// Pixel pitch `S/N` (m).
    pub fn pixel(&self) -> f64 {
        self.size / self.pixels as f64
    }

    /// Time of a whole frame `N/f_line` (s).
    pub fn frame_time(&self) -> f64 {
        self.pixels as f64 / self.line_rate
    }

    /// The image's geometry with no data yet.
    pub fn empty_image(&self) -> HeightImage {
        HeightImage {
            xres: self.pixels,
            yres: self.pixels,
            x_real: self.size,
            y_real: self.size,
            x_offset: self.centre_x - 0.5 * self.size,
            y_offset: self.centre_y - 0.5 * self.size,
            data: Vec::with_capacity(self.pixels * self.pixels),
        }
    }
}

impl Tip {
    /// The scene's tip: `[tip] radius_nm` on a cone of `[scan] tip_half_angle_deg`.
    pub fn from_scene(scene: &Scene) -> Tip {
        Tip {
            radius: scene.file.tip.radius_nm * 1e-9,
            half_angle: scene.file.scan.tip_half_angle_deg.to_radians(),
        }
    }
}

/// One recorded trace line.
#[derive(Debug, Clone, PartialEq)]
pub struct ScanLine {
    /// Row index, from 0.
    pub index: usize,
    /// Commanded y of the row (m).
    pub y: f64,
    /// Time of the line's first pixel from the start of the frame (s).
    pub t: f64,
    /// Recorded heights (m), left to right.
    pub heights: Vec<f64>,
}

/// A scan in progress: an iterator of [`ScanLine`]s, so lines can be streamed as they finish.
#[derive(Debug)]
pub struct Scanner<'a> {
    surface: &'a Surface,
    tip: Tip,
    p: ScanParams,
    row: usize,
    rng: SmallRng,
    noise: Option<Normal<f64>>,
}

impl<'a> Scanner<'a> {
    /// A scan of `surface` with `tip`, starting at the first line.
    pub fn new(surface: &'a Surface, tip: Tip, p: ScanParams) -> Scanner<'a> {
        Scanner {
            surface,
            tip,
            p,
            row: 0,
            rng: SmallRng::seed_from_u64(p.noise_seed),
            noise: (p.noise_rms > 0.0).then(|| Normal::new(0.0, p.noise_rms).expect("σ > 0 is finite")),
        }
    }

    /// The settings.
    pub fn params(&self) -> &ScanParams {
        &self.p
    }

    /// Scans the next line; `None` after the last.
    pub fn next_line(&mut self) -> Option<ScanLine> {
        let p = self.p;
        let n = p.pixels;
        if self.row >= n {
            return None;
        }
        let i = self.row;
        self.row += 1;
        let (dx, lag) = (p.pixel(), 0.5 * p.hysteresis * p.size);
        let x0 = p.centre_x - 0.5 * p.size;
        let y_cmd = p.centre_y - 0.5 * p.size + (i as f64 + 0.5) * dx;
        let s_y = (i as f64 + 0.5) / n as f64;
        let y_lagged = y_cmd - lag * (std::f64::consts::PI * s_y).sin();
        let mut heights = Vec::with_capacity(n);
        for j in 0..n {
            let s_x = (j as f64 + 0.5) / n as f64;
            let t = (i as f64 + 0.5 * s_x) / p.line_rate;
            let x = x0 + (j as f64 + 0.5) * dx - lag * (std::f64::consts::PI * s_x).sin() + p.drift_x * t;
            let y = y_lagged + p.drift_y * t;
            let mut z = image_height(self.surface, &self.tip, x, y) + p.drift_z * t;
            if let Some(noise) = &self.noise {
                z += noise.sample(&mut self.rng);
            }
            heights.push(z);
        }
        Some(ScanLine {
            index: i,
            y: y_cmd,
            t: i as f64 / p.line_rate,
            heights,
        })
    }

    /// Scans the remaining lines into an image of those lines (on a fresh scanner: the frame).
    pub fn finish(mut self) -> HeightImage {
        let mut img = self.p.empty_image();
        let taken = self.row;
        while let Some(line) = self.next_line() {
            img.data.extend_from_slice(&line.heights);
        }
        img.yres = self.p.pixels - taken;
        img.y_offset += taken as f64 * self.p.pixel();
        img.y_real = img.yres as f64 * self.p.pixel();
        img
    }
}

impl Iterator for Scanner<'_> {
    type Item = ScanLine;
    fn next(&mut self) -> Option<ScanLine> {
        self.next_line()
    }
}

/// A whole frame: `Scanner::new(surface, tip, p).finish()`.
pub fn scan(surface: &Surface, tip: Tip, p: ScanParams) -> HeightImage {
    Scanner::new(surface, tip, p).finish()
}
