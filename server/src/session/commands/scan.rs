//! `scan`: the square checked in the protocol's units, then a scan on its own thread
//! (`scan_job.rs`).

use std::sync::Arc;
use std::sync::atomic::Ordering::Relaxed;

use nanopush_proto::ws::{ClientMessage, ErrorCode};

use super::instrument::busy;
use super::{Accepted, Client, misrouted};
use crate::app_state::AppState;
use crate::command_checks::{Refusal, number};
use crate::scan_job::{run_real_scan, run_scan};
use crate::session::MIN_SCAN_UM;
use nanopush_instrument::afm::ScanFrame;
use nanopush_instrument::scan::ScanParams;

/// Takes the scanner for this scan: refused `busy` when another command took it since `busy`
/// looked.
fn claim(st: &AppState) -> Result<(), Refusal> {
    st.activity
        .scanning
        .compare_exchange(false, true, Relaxed, Relaxed)
        .map(|_| ())
        .map_err(|_| Refusal::new(ErrorCode::Busy, "a scan is running; send stop first"))
}

/// A real controller's frame: none of the square's fields for the controller's own frame and
/// pixels, or all three (the pixels optional, 256 by default); the controller checks it against
/// its range.
fn real_frame(
    centre_x_um: Option<f64>,
    centre_y_um: Option<f64>,
    size_um: Option<f64>,
    pixels: Option<u32>,
) -> Result<Option<ScanFrame>, Refusal> {
    let (cx, cy, size) = match (centre_x_um, centre_y_um, size_um) {
        (None, None, None) if pixels.is_none() => return Ok(None),
        (Some(cx), Some(cy), Some(size)) => (cx, cy, size),
        _ => {
            return Err(Refusal::new(
                ErrorCode::Invalid,
                "on a real controller give centre_x_um, centre_y_um and size_um together (pixels with them), or none for the controller's own frame",
            ));
        }
    };
    let size = number("size_um", size, MIN_SCAN_UM, 1000.0, false, "µm")?;
    let cx = number("centre_x_um", cx, -1000.0, 1000.0, false, "µm")?;
    let cy = number("centre_y_um", cy, -1000.0, 1000.0, false, "µm")?;
    let px = number("pixels", pixels.map_or(256.0, f64::from), 16.0, 512.0, false, "pixels")? as usize;
    Ok(Some(ScanFrame {
        centre_x: cx * 1e-6,
        centre_y: cy * 1e-6,
        width: size * 1e-6,
        height: size * 1e-6,
        pixels: px,
        lines: px,
    }))
}

/// `scan`: the scene's scan where a field is left out.
pub(super) fn run(st: &Arc<AppState>, c: &mut Client, msg: ClientMessage) -> Result<Accepted, Refusal> {
    let ClientMessage::Scan {
        centre_x_um,
        centre_y_um,
        size_um,
        pixels,
        ..
    } = msg
    else {
        return Err(misrouted(&msg));
    };
    if let Some(real) = &st.cfg.instrument {
        let frame = real_frame(centre_x_um, centre_y_um, size_um, pixels)?;
        if let (Some(f), Some(l)) = (&frame, &real.limits) {
            let (x0, x1) = (f.centre_x - 0.5 * f.width, f.centre_x + 0.5 * f.width);
            let (y0, y1) = (f.centre_y - 0.5 * f.height, f.centre_y + 0.5 * f.height);
            if !(l.contains_xy(x0, y0) && l.contains_xy(x1, y1)) {
                return Err(Refusal::new(
                    ErrorCode::OutOfRange,
                    format!(
                        "the scan square must lie within the controller's frame, {}",
                        l.xy_text()
                    ),
                ));
            }
        }
        busy(st)?;
        claim(st)?;
        st.activity.scan_cancel.store(false, Relaxed);
        // Cleared here, before the reply: a stop this client sends after it ends this scan.
        real.cancel.store(false, Relaxed);
        let (st2, real, by) = (st.clone(), real.clone(), c.person.name.clone());
        std::thread::spawn(move || {
            let scan = || run_real_scan(&st2, &real, frame, &by);
            if std::panic::catch_unwind(std::panic::AssertUnwindSafe(scan)).is_err() {
                tracing::error!("scan failed (internal error)");
                st2.activity.scanning.store(false, Relaxed);
            }
        });
        return Ok(Accepted::PLAIN);
    }
    let f = &st.scene.file;
    let range = f.stage.range_um;
    let base = ScanParams::from_scene(&st.scene);
    // Checked in the protocol's units (µm), converted once: the rounding of a µm → m → µm round
    // trip would refuse a full-range square about the default centre. The side is at least
    // 10 nm (below that a pixel is a fraction of an atom).
    let size_um = number(
        "size_um",
        size_um.unwrap_or(base.size * 1e6),
        MIN_SCAN_UM,
        range,
        false,
        "µm",
    )?;
    let cx_um = number(
        "centre_x_um",
        centre_x_um.unwrap_or(base.centre_x * 1e6),
        0.0,
        range,
        false,
        "µm",
    )?;
    let cy_um = number(
        "centre_y_um",
        centre_y_um.unwrap_or(base.centre_y * 1e6),
        0.0,
        range,
        false,
        "µm",
    )?;
    let px = number(
        "pixels",
        pixels.map_or(base.pixels.min(256) as f64, f64::from),
        8.0,
        512.0,
        false,
        "",
    )? as usize;
    let eps = 1e-9 * range;
    let half = size_um / 2.0;
    if cx_um - half < -eps || cy_um - half < -eps || cx_um + half > range + eps || cy_um + half > range + eps {
        return Err(Refusal::new(
            ErrorCode::OutOfRange,
            format!(
                "the scan square (centre ({cx_um}, {cy_um}) µm, side {size_um} µm) must lie within the stage, [0, {range}] µm"
            ),
        ));
    }
    let (size, cx, cy) = (size_um * 1e-6, cx_um * 1e-6, cy_um * 1e-6);
    busy(st)?;
    claim(st)?;
    st.activity.scan_cancel.store(false, Relaxed);
    let params = ScanParams {
        centre_x: cx,
        centre_y: cy,
        size,
        pixels: px,
        line_rate: st.cfg.scan_line_hz,
        ..base
    };
    let st2 = st.clone();
    let by = c.person.name.clone();
    std::thread::spawn(move || {
        if std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| run_scan(&st2, params, &by))).is_err() {
            tracing::error!("scan failed (internal error)");
            st2.activity.scanning.store(false, Relaxed);
        }
    });
    Ok(Accepted::PLAIN)
}
