//! `nanopush scan`.

use std::fmt::Write as _;
use std::path::PathBuf;

use anyhow::{Context, bail};
use clap::Args;
use nanopush_instrument::scan::{
    HeightImage, LocateError, Located, ScanParams, Scanner, Surface, Tip, find_particles, localize, write_gsf,
    write_png,
};
use nanopush_instrument::scene::{MAX_SCAN_PIXELS, MIN_SCAN_PIXELS};
use nanopush_proto::scan::{LocatedParticle, ParticleCheck, ScanReport};

use crate::units::eng;

/// Arguments of `nanopush scan`.
#[derive(Args, Debug)]
pub struct ScanArgs {
    /// Scene file (TOML); the embedded paper scene when absent. Its `[scan]` section sets the
    /// region, noise, drift and hysteresis.
    #[arg(long)]
    scene: Option<PathBuf>,
    /// Pixels per line and lines, in [8, 4096]; the scene's `scan.pixels` when absent.
    #[arg(long, value_name = "N")]
    size: Option<u64>,
    /// The Gwyddion Simple Field file to write (`.gsf`); the PNG preview goes next to it.
    #[arg(long, value_name = "FILE.gsf")]
    out: PathBuf,
    /// Locate the particle nearest this point (µm), e.g. `--locate 50,50`.
    #[arg(long, value_name = "X_UM,Y_UM", allow_hyphen_values = true)]
    locate: Option<String>,
    /// How far from the point to look for a particle (µm), in (0, scan size].
    #[arg(long, default_value_t = 2.0, value_name = "UM")]
    search_um: f64,
    /// Print one JSON object (SI units) instead of a summary.
    #[arg(long)]
    json: bool,
    #[command(flatten)]
    instrument: crate::instrument_cmd::InstrumentArgs,
}

const UM: f64 = 1e-6;

fn to_proto(l: &Located) -> LocatedParticle {
    LocatedParticle {
        x: l.x,
        y: l.y,
        z: l.z,
        height: l.height,
        radius: l.radius,
        radius_from_width: l.radius_from_width,
        base_width: l.base_width,
        expected_base_width: l.expected_width,
    }
}

/// Runs `nanopush scan`; returns what to print on stdout.
pub fn run(a: &ScanArgs) -> anyhow::Result<String> {
    if let Some(n) = a.size
        && !(MIN_SCAN_PIXELS as u64..=MAX_SCAN_PIXELS as u64).contains(&n)
    {
        bail!("--size {n} pixels is out of range; allowed: [{MIN_SCAN_PIXELS}, {MAX_SCAN_PIXELS}] pixels");
    }
    if a.out.extension().is_none_or(|e| e != "gsf") {
        bail!(
            "--out {}: the file name must end in .gsf (the PNG preview is written next to it)",
            a.out.display()
        );
    }
    if let Some(spec) = &a.instrument.instrument {
        if a.scene.is_some() || a.locate.is_some() || a.json {
            bail!(
                "--scene, --locate and --json are for the simulated AFM; with --instrument the sample is the controller's"
            );
        }
        return crate::instrument_cmd::scan(&a.instrument, spec, a.size, &a.out);
    }
    let point = a
        .locate
        .as_deref()
        .map(|p| crate::units::parse_point_um("--locate", p, "50,50"))
        .transpose()?;
    let scene = crate::load_scene(a.scene.as_ref())?;
    let mut p = ScanParams::from_scene(&scene);
    if let Some(n) = a.size {
        p.pixels = n as usize;
    }
    let size_um = p.size / UM;
    if !(a.search_um.is_finite() && a.search_um > 0.0 && a.search_um <= size_um) {
        bail!(
            "--search-um {} is out of range; allowed: (0, {size_um}] µm (the scan size)",
            a.search_um
        );
    }
    let (x0, y0) = ((p.centre_x - 0.5 * p.size) / UM, (p.centre_y - 0.5 * p.size) / UM);
    if let Some((x, y)) = point
        && !(x >= x0 && x <= x0 + size_um && y >= y0 && y <= y0 + size_um)
    {
        bail!(
            "--locate {x},{y} µm is outside the scan; allowed: x in [{x0}, {}] µm, y in [{y0}, {}] µm",
            x0 + size_um,
            y0 + size_um
        );
    }

    let surface = Surface::from_scene(&scene);
    let tip = Tip::from_scene(&scene);
    let mut img: HeightImage = p.empty_image();
    for line in Scanner::new(&surface, tip, p) {
        img.data.extend_from_slice(&line.heights);
    }
    let title = format!("nanopush scan of {}", scene.file.name);
    let mut gsf = Vec::new();
    write_gsf(&mut gsf, &img, &title)?;
    crate::units::write_file(&a.out, &gsf)?;
    let png_path = a.out.with_extension("png");
    let mut png = Vec::new();
    write_png(&mut png, &img)?;
    crate::units::write_file(&png_path, &png)?;

    let search = a.search_um * UM;
    let located = match point {
        Some((x, y)) => match localize(&img, &tip, x * UM, y * UM, search) {
            Ok(l) => Some(to_proto(&l)),
            Err(LocateError::NoBlob { threshold, .. }) => bail!(
                "--locate {x},{y}: no particle within {} µm (--search-um): no pixel there is more than {:.2} nm above the substrate",
                a.search_um,
                threshold * 1e9
            ),
            Err(e) => return Err(e).with_context(|| format!("--locate {x},{y}")),
        },
        None => None,
    };
    let found: Vec<LocatedParticle> = find_particles(&img, &tip).iter().map(to_proto).collect();
    let inside = |x: f64, y: f64| (x - p.centre_x).abs() <= 0.5 * p.size && (y - p.centre_y).abs() <= 0.5 * p.size;
    let particles: Vec<ParticleCheck> = scene
        .file
        .particles
        .iter()
        .zip(&surface.spheres)
        .filter(|(_, s)| inside(s.x, s.y))
        .map(|(pf, s)| {
            let r = localize(&img, &tip, s.x, s.y, search);
            ParticleCheck {
                id: pf.id,
                x: s.x,
                y: s.y,
                radius: s.r,
                located: r.as_ref().ok().map(to_proto),
                error: r.err().map(|e| e.to_string()),
            }
        })
        .collect();
    let (z_min, z_max) = img.z_range();
    let report = ScanReport {
        schema: "nanopush.scan".into(),
        version: nanopush_proto::VERSION,
        scene: scene.file.name.clone(),
        gsf: a.out.display().to_string(),
        png: png_path.display().to_string(),
        pixels: p.pixels,
        size: p.size,
        pixel: p.pixel(),
        centre_x: p.centre_x,
        centre_y: p.centre_y,
        z_min,
        z_max,
        frame_time: p.frame_time(),
        tip_radius: tip.radius,
        tip_half_angle: tip.half_angle,
        found,
        particles,
        located,
    };
    let mut out = String::new();
    if a.json {
        writeln!(out, "{}", serde_json::to_string(&report)?)?;
        return Ok(out);
    }
    summary(&mut out, &report, &p)?;
    Ok(out)
}

fn summary(out: &mut String, r: &ScanReport, p: &ScanParams) -> anyhow::Result<()> {
    writeln!(
        out,
        "Scan of scene \"{}\": {} square centred at ({}, {}) µm, {} × {} pixels of {}",
        r.scene,
        eng(r.size, "m"),
        r.centre_x / UM,
        r.centre_y / UM,
        r.pixels,
        r.pixels,
        eng(r.pixel, "m")
    )?;
    writeln!(
        out,
        "  tip: Rₜ = {} on a {:.1}° cone; noise {} RMS; frame time {} at a line rate of {} Hz",
        eng(r.tip_radius, "m"),
        r.tip_half_angle.to_degrees(),
        eng(p.noise_rms, "m"),
        eng(r.frame_time, "s"),
        p.line_rate
    )?;
    writeln!(out, "  z range: {} to {}", eng(r.z_min, "m"), eng(r.z_max, "m"))?;
    writeln!(out, "  wrote {} (Gwyddion Simple Field) and {} (preview)", r.gsf, r.png)?;
    writeln!(out, "  particles found in the image: {}", r.found.len())?;
    let row = |l: &LocatedParticle| {
        format!(
            "({:.3}, {:.3}) µm, R = H/2 = {}, R from width = {}, base width {} (model {})",
            l.x / UM,
            l.y / UM,
            eng(l.radius, "m"),
            l.radius_from_width.map_or("n/a".into(), |w| eng(w, "m")),
            eng(l.base_width, "m"),
            eng(l.expected_base_width, "m")
        )
    };
    for c in &r.particles {
        match (&c.located, &c.error) {
            (Some(l), _) => writeln!(
                out,
                "  particle {} (true ({:.3}, {:.3}) µm, R = {}): located at {}",
                c.id,
                c.x / UM,
                c.y / UM,
                eng(c.radius, "m"),
                row(l)
            )?,
            (None, e) => writeln!(
                out,
                "  particle {} (true ({:.3}, {:.3}) µm): not located: {}",
                c.id,
                c.x / UM,
                c.y / UM,
                e.as_deref().unwrap_or("?")
            )?,
        }
    }
    if let Some(l) = &r.located {
        writeln!(out, "  --locate: {}", row(l))?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use crate::Command;

    /// docs/manipulation.md, "Scans": a `--locate` click looks for a particle within `--search-um`,
    /// default 2 µm.
    #[test]
    fn a_locate_click_searches_within_the_documented_radius() {
        let Command::Scan(a) = crate::parse(&["scan", "--out", "x.gsf"]) else {
            unreachable!()
        };
        assert_eq!(a.search_um, 2.0);
    }
}
