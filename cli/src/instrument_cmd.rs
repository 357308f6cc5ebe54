//! `nanopush scan` and `nanopush push` on a real controller: `--instrument nanonis:HOST:PORT[,LOGPORT]`.
//!
//! A scan images the controller's own frame and buffer unless `--frame-um` gives one; read-only
//! (`--instrument-read-only`) it grabs the image the controller last recorded and sends nothing
//! that moves the tip or changes Z. A push scans, locates the particle near `--at-um`, runs the
//! held push (withdraw, travel, land on the controller's Z feedback, push, retract), scans again
//! and reports where the particle ended.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;
use std::time::Duration;

use anyhow::{Context, bail};
use clap::Args;
use nanopush_instrument::afm::{Microscope, ScanFrame};
use nanopush_instrument::control::{HeldOutcome, HeldPush, held_push};
use nanopush_instrument::scan::{HeightImage, Tip, find_particles, localize, write_gsf, write_png};
use nanopush_nanonis::{NanonisMicroscope, NanonisOptions, parse_instrument};

use crate::units::eng;

const UM: f64 = 1e-6;

/// Options for a real controller (with `--instrument`).
#[derive(Args, Debug, Default)]
pub struct InstrumentArgs {
    /// A real controller instead of the simulated AFM: `nanonis:HOST:PORT[,LOGPORT]` (the TCP
    /// Programming Interface's port and, for kHz signals, the TCP Logger's stream port).
    #[arg(long, value_name = "nanonis:HOST:PORT[,LOGPORT]")]
    pub instrument: Option<String>,
    /// Send nothing that moves the tip or changes Z: a scan grabs the controller's last image.
    #[arg(long)]
    pub instrument_read_only: bool,
    /// The signal that reads the normal deflection (its name or the start of it).
    #[arg(long, default_value = "Normal deflection", value_name = "NAME")]
    pub deflection_signal: String,
    /// The signal that reads the lateral deflection (`none` when there is none).
    #[arg(long, default_value = "Lateral deflection", value_name = "NAME")]
    pub lateral_signal: String,
    /// The signal the scan engine records heights in.
    #[arg(long, default_value = "Z", value_name = "NAME")]
    pub height_signal: String,
    /// Time-out of every call to the controller (s), in [0.1, 600].
    #[arg(long, default_value_t = 5.0, value_name = "S")]
    pub instrument_timeout_s: f64,
    /// The longest a scan may take before it is stopped and the tip withdrawn (s), in
    /// [1, 86400].
    #[arg(long, default_value_t = 3600.0, value_name = "S")]
    pub scan_timeout_s: f64,
    /// Your own XY limits within the controller's scan frame (µm): `XMIN,YMIN,XMAX,YMAX`; no
    /// move or frame outside them is sent.
    #[arg(long, value_name = "XMIN,YMIN,XMAX,YMAX", allow_hyphen_values = true)]
    pub xy_limits_um: Option<String>,
    /// Scan this frame instead of the controller's: centre and side (µm), e.g. `20,20,5`.
    #[arg(long, value_name = "CX,CY,SIDE", allow_hyphen_values = true)]
    pub frame_um: Option<String>,
    /// The tip's radius (nm) for locating particles in the image, in [1, 1000].
    #[arg(long, default_value_t = 20.0, value_name = "NM")]
    pub tip_radius_nm: f64,
    /// The tip's cone half-angle (degrees) for locating particles, in [1, 80].
    #[arg(long, default_value_t = 20.0, value_name = "DEG")]
    pub tip_half_angle_deg: f64,
}

/// Options of a held push (with `--instrument`).
#[derive(Args, Debug, Default)]
pub struct HeldPushArgs {
    /// Where the particle is, roughly (µm): the scan before the push locates it near here.
    #[arg(long, value_name = "X_UM,Y_UM", allow_hyphen_values = true)]
    pub at_um: Option<String>,
    /// Normal deflection the controller holds during the push (V), in [-10, 10].
    #[arg(long, default_value_t = 0.1, allow_hyphen_values = true, value_name = "V")]
    pub setpoint_v: f64,
    /// A lateral deflection this far over its landing value is a contact (V), in (0, 10].
    #[arg(long, default_value_t = 0.1, value_name = "V")]
    pub lateral_contact_v: f64,
    /// The push stops when the normal deflection leaves the set point by more (V), in (0, 10].
    #[arg(long, default_value_t = 0.5, value_name = "V")]
    pub normal_limit_v: f64,
    /// Push speed (µm/s), in (0, max speed].
    #[arg(long, default_value_t = 1.0, value_name = "UM_PER_S")]
    pub push_speed_um_per_s: f64,
    /// Travel speed with the tip withdrawn (µm/s), in (0, max speed].
    #[arg(long, default_value_t = 5.0, value_name = "UM_PER_S")]
    pub travel_speed_um_per_s: f64,
    /// Longest the controller's feedback may take to land the tip at the set point (s), in
    /// [0.1, 600].
    #[arg(long, default_value_t = 10.0, value_name = "S")]
    pub land_timeout_s: f64,
    /// The fastest XY speed nanopush may ask the controller for (µm/s), in (0, 100].
    #[arg(long, default_value_t = 20.0, value_name = "UM_PER_S")]
    pub max_speed_um_per_s: f64,
}

fn in_range(flag: &str, v: f64, lo: f64, hi: f64, open_lo: bool, unit: &str) -> anyhow::Result<()> {
    let ok = v.is_finite() && (if open_lo { v > lo } else { v >= lo }) && v <= hi;
    if !ok {
        let l = if open_lo { "(" } else { "[" };
        bail!(
            "{flag} {} is out of range; allowed: {l}{lo}, {hi}] {unit}",
            crate::units::num(v)
        );
    }
    Ok(())
}

/// Set by SIGINT, SIGTERM or SIGHUP; made before the handler is installed.
static INTERRUPTED: std::sync::LazyLock<std::sync::Arc<AtomicBool>> = std::sync::LazyLock::new(Default::default);

extern "C" fn on_interrupt(_: libc::c_int) {
    // Async-signal-safe: the flag exists already (forced before the handler is installed), so
    // this is one atomic store.
    INTERRUPTED.store(true, std::sync::atomic::Ordering::Relaxed);
}

/// SIGINT, SIGTERM and SIGHUP no longer end the process: they set the returned flag, which the
/// backend's scans and the held push watch, so that the tip is withdrawn before nanopush exits.
fn catch_interrupts() -> std::sync::Arc<AtomicBool> {
    let flag = std::sync::Arc::clone(&INTERRUPTED);
    let handler = on_interrupt as extern "C" fn(libc::c_int) as libc::sighandler_t;
    // SAFETY: installs a handler that only stores to an atomic.
    unsafe {
        for sig in [libc::SIGINT, libc::SIGTERM, libc::SIGHUP] {
            libc::signal(sig, handler);
        }
    }
    flag
}

/// The slowest speed a push or a travel may ask for (µm/s): slower would take days, and rounds
/// to nothing in the controller's f32.
const MIN_SPEED_UM_PER_S: f64 = 1e-3;

/// Connects to the controller the arguments name.
pub fn connect(a: &InstrumentArgs, spec: &str, max_speed: f64) -> anyhow::Result<NanonisMicroscope> {
    in_range("--instrument-timeout-s", a.instrument_timeout_s, 0.1, 600.0, false, "s")?;
    let (addr, logger_port) = parse_instrument(spec).map_err(anyhow::Error::msg)?;
    let mut o = NanonisOptions::new(addr);
    o.logger_port = logger_port;
    o.read_only = a.instrument_read_only;
    o.timeout = Duration::from_secs_f64(a.instrument_timeout_s);
    o.deflection_signal = a.deflection_signal.clone();
    o.lateral_signal = (a.lateral_signal != "none").then(|| a.lateral_signal.clone());
    o.height_signal = a.height_signal.clone();
    o.max_speed = max_speed;
    in_range("--scan-timeout-s", a.scan_timeout_s, 1.0, 86_400.0, false, "s")?;
    o.scan_timeout = Duration::from_secs_f64(a.scan_timeout_s);
    if let Some(spec) = &a.xy_limits_um {
        let usage =
            "expected four numbers XMIN,YMIN,XMAX,YMAX in µm with XMIN < XMAX and YMIN < YMAX, e.g. 40,40,60,60";
        let v: Vec<f64> = spec
            .split(',')
            .map(|s| s.trim().parse::<f64>())
            .collect::<Result<_, _>>()
            .map_err(|_| anyhow::anyhow!("--xy-limits-um {spec:?}: {usage}"))?;
        let [x0, y0, x1, y1] = v[..] else {
            bail!("--xy-limits-um {spec:?}: {usage}");
        };
        if !(v.iter().all(|x| x.is_finite()) && x0 < x1 && y0 < y1) {
            bail!("--xy-limits-um {spec:?}: {usage}");
        }
        o.xy_limits = Some([[x0 * UM, x1 * UM], [y0 * UM, y1 * UM]]);
    }
    NanonisMicroscope::connect(o).with_context(|| format!("connecting to the controller at {addr}"))
}

/// The tip for locating particles, its values checked.
pub fn tip(a: &InstrumentArgs) -> anyhow::Result<Tip> {
    in_range("--tip-radius-nm", a.tip_radius_nm, 1.0, 1000.0, false, "nm")?;
    in_range(
        "--tip-half-angle-deg",
        a.tip_half_angle_deg,
        1.0,
        80.0,
        false,
        "degrees",
    )?;
    Ok(Tip {
        radius: a.tip_radius_nm * 1e-9,
        half_angle: a.tip_half_angle_deg.to_radians(),
    })
}

fn frame(a: &InstrumentArgs, pixels: Option<u64>, m: &mut NanonisMicroscope) -> anyhow::Result<Option<ScanFrame>> {
    let Some(spec) = &a.frame_um else {
        if let Some(n) = pixels {
            let mut f = m.current_frame()?;
            f.pixels = n as usize;
            f.lines = n as usize;
            return Ok(Some(f));
        }
        return Ok(None);
    };
    let parts: Vec<f64> = spec
        .split(',')
        .map(|s| s.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .map_err(|_| anyhow::anyhow!("--frame-um {spec:?}: expected three numbers CX,CY,SIDE in µm, e.g. 20,20,5"))?;
    let [cx, cy, side] = parts[..] else {
        bail!("--frame-um {spec:?}: expected three numbers CX,CY,SIDE in µm, e.g. 20,20,5");
    };
    in_range("--frame-um side", side, 0.01, 1000.0, false, "µm")?;
    if !(cx.is_finite() && cy.is_finite()) {
        bail!("--frame-um {spec:?}: the centre must be finite");
    }
    let n = pixels.unwrap_or(256) as usize;
    Ok(Some(ScanFrame {
        centre_x: cx * UM,
        centre_y: cy * UM,
        width: side * UM,
        height: side * UM,
        pixels: n,
        lines: n,
    }))
}

fn write_image(out: &Path, img: &HeightImage, title: &str) -> anyhow::Result<PathBuf> {
    let mut gsf = Vec::new();
    write_gsf(&mut gsf, img, title)?;
    crate::units::write_file(out, &gsf)?;
    let png_path = out.with_extension("png");
    let mut png = Vec::new();
    write_png(&mut png, img)?;
    crate::units::write_file(&png_path, &png)?;
    Ok(png_path)
}

/// `nanopush scan --instrument ...`.
pub fn scan(a: &InstrumentArgs, spec: &str, pixels: Option<u64>, out: &Path) -> anyhow::Result<String> {
    let tip = tip(a)?;
    if let Some(n) = pixels
        && !(16..=4096).contains(&n)
    {
        bail!("--size {n} pixels is out of range for a controller's scan buffer; allowed: [16, 4096] pixels");
    }
    let mut m = connect(a, spec, 20e-6)?;
    m.set_cancel(catch_interrupts());
    let frame = frame(a, pixels, &mut m)?;
    let img = m.scan(frame.as_ref())?;
    let caps = m.capabilities();
    let png = write_image(out, &img, &format!("nanopush scan on {}", caps.backend))?;
    let found = find_particles(&img, &tip);
    let (z_min, z_max) = img.z_range();
    let mut s = String::new();
    writeln!(
        s,
        "Scan on {}{}: {} × {} frame at ({:.4}, {:.4}) µm, {} × {} pixels",
        caps.backend,
        if caps.read_only {
            " (read-only: the controller's last image)"
        } else {
            ""
        },
        eng(img.x_real, "m"),
        eng(img.y_real, "m"),
        (img.x_offset + 0.5 * img.x_real) / UM,
        (img.y_offset + 0.5 * img.y_real) / UM,
        img.xres,
        img.yres
    )?;
    writeln!(s, "  z range: {} to {}", eng(z_min, "m"), eng(z_max, "m"))?;
    writeln!(
        s,
        "  wrote {} (Gwyddion Simple Field) and {} (preview)",
        out.display(),
        png.display()
    )?;
    writeln!(s, "  particles found in the image: {}", found.len())?;
    for l in &found {
        writeln!(
            s,
            "    at ({:.4}, {:.4}) µm, height {}",
            l.x / UM,
            l.y / UM,
            eng(l.height, "m")
        )?;
    }
    Ok(s)
}

/// `nanopush push --instrument ...`: `target` gives the particle's destination from where it is
/// located.
pub fn push(
    a: &InstrumentArgs,
    h: &HeldPushArgs,
    spec: &str,
    target: impl Fn((f64, f64)) -> (f64, f64),
    tolerance: f64,
    out: Option<&Path>,
) -> anyhow::Result<(String, bool)> {
    if a.instrument_read_only {
        bail!("--instrument-read-only: a push moves the tip; scan read-only first, then push without it");
    }
    let Some(at) = &h.at_um else {
        bail!("--at-um X_UM,Y_UM is needed with --instrument: where the particle is, roughly");
    };
    let (ax, ay) = crate::units::parse_point_um("--at-um", at, "20,20")?;
    in_range("--setpoint-v", h.setpoint_v, -10.0, 10.0, false, "V")?;
    in_range("--lateral-contact-v", h.lateral_contact_v, 0.0, 10.0, true, "V")?;
    in_range("--normal-limit-v", h.normal_limit_v, 0.0, 10.0, true, "V")?;
    in_range(
        "--max-speed-um-per-s",
        h.max_speed_um_per_s,
        MIN_SPEED_UM_PER_S,
        100.0,
        false,
        "µm/s",
    )?;
    let max = h.max_speed_um_per_s;
    let min = MIN_SPEED_UM_PER_S;
    in_range("--push-speed-um-per-s", h.push_speed_um_per_s, min, max, false, "µm/s")?;
    in_range(
        "--travel-speed-um-per-s",
        h.travel_speed_um_per_s,
        min,
        max,
        false,
        "µm/s",
    )?;
    in_range("--land-timeout-s", h.land_timeout_s, 0.1, 600.0, false, "s")?;
    // The place for the results first: a push whose summary cannot be written is not started.
    if let Some(dir) = out {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    let tip = tip(a)?;
    let mut m = connect(a, spec, max * UM)?;
    let stop = catch_interrupts();
    m.set_cancel(stop.clone());
    let frame = frame(a, None, &mut m)?;
    // A target outside the limits (the particle taken as where --at-um says) is refused before
    // anything moves; the held push checks the exact points again before it sends any.
    let rough = target((ax * UM, ay * UM));
    let l = m.limits()?;
    if !l.contains_xy(rough.0, rough.1) {
        bail!(
            "the target ({:.4}, {:.4}) µm is outside the limits, {} (the controller's scan frame and --xy-limits-um); nothing was sent",
            rough.0 / UM,
            rough.1 / UM,
            l.xy_text()
        );
    }
    let search = 2.0 * UM;
    let before = m.scan(frame.as_ref())?;
    let located = localize(&before, &tip, ax * UM, ay * UM, search)
        .with_context(|| format!("--at-um {ax},{ay}: no particle located within 2 µm in the scan before the push"))?;
    let to = target((located.x, located.y));
    let p = HeldPush {
        from: [located.x, located.y],
        to: [to.0, to.1],
        radius: located.radius,
        tip_radius: tip.radius,
        approach_gap: 0.1 * UM,
        travel_speed: h.travel_speed_um_per_s * UM,
        push_speed: h.push_speed_um_per_s * UM,
        setpoint: h.setpoint_v,
        land_tolerance: 0.05 * h.setpoint_v.abs().max(0.01),
        settle_samples: 5,
        lateral_contact: h.lateral_contact_v,
        normal_limit: h.normal_limit_v,
        land_timeout: h.land_timeout_s,
    };
    let r = held_push(&mut m, &p, &stop)?;
    if r.outcome == HeldOutcome::Stopped {
        bail!(
            "interrupted during the push ({}): the tip was withdrawn",
            r.phases.iter().rev().nth(1).map_or("", |(p, _)| p.as_str())
        );
    }
    // The scan after needs the tip on the surface: the controller's feedback lands it.
    m.hold_force(h.setpoint_v)?;
    let after = m.scan(frame.as_ref());
    m.withdraw()
        .context("withdrawing after the scan that followed the push: the tip may still be on the surface; withdraw it at the controller")?;
    let after = after?;
    let ended = localize(&after, &tip, to.0, to.1, search).ok();
    let caps = m.capabilities();
    let mut s = String::new();
    writeln!(
        s,
        "Held push on {} (its own Z feedback; signals at {:.0} Hz)",
        caps.backend, caps.feed_rate_hz
    )?;
    writeln!(
        s,
        "  particle located at ({:.4}, {:.4}) µm, radius {}",
        located.x / UM,
        located.y / UM,
        eng(located.radius, "m")
    )?;
    writeln!(s, "  target ({:.4}, {:.4}) µm", to.0 / UM, to.1 / UM)?;
    let phases: Vec<&str> = r.phases.iter().map(|(p, _)| p.as_str()).collect();
    writeln!(s, "  phases: {}; push {}", phases.join(" → "), r.outcome.as_str())?;
    if let Some(c) = r.contact_at {
        writeln!(s, "  contact at ({:.4}, {:.4}) µm", c[0] / UM, c[1] / UM)?;
    }
    let ok = match &ended {
        Some(e) => {
            let miss = (e.x - to.0).hypot(e.y - to.1);
            let ok = r.outcome == HeldOutcome::Pushed && miss <= tolerance;
            writeln!(
                s,
                "  after: particle at ({:.4}, {:.4}) µm, {} from the target: {} (tolerance {})",
                e.x / UM,
                e.y / UM,
                eng(miss, "m"),
                if ok { "ok" } else { "missed" },
                eng(tolerance, "m")
            )?;
            ok
        }
        None => {
            writeln!(s, "  after: no particle found within 2 µm of the target: missed")?;
            false
        }
    };
    writeln!(s, "  the tip is withdrawn")?;
    if let Some(dir) = out {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
        write_image(&dir.join("scan-before.gsf"), &before, "nanopush: before the push")?;
        write_image(&dir.join("scan-after.gsf"), &after, "nanopush: after the push")?;
        writeln!(s, "  wrote scan-before/after.gsf/png in {}", dir.display())?;
    }
    Ok((s, ok))
}
