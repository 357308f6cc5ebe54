//! `scan`: the square checked in the protocol's units, then a scan on its own thread
//! (`scan_job.rs`).

use std::sync::Arc;
use std::sync::atomic::Ordering::Relaxed;

use nanopush_proto::ws::{ClientMessage, ErrorCode};

use super::instrument::busy;
use super::{Accepted, Client, misrouted};
use crate::app_state::AppState;
use crate::command_checks::{Refusal, number};
use crate::scan_job::run_scan;
use crate::session::MIN_SCAN_UM;
use nanopush_instrument::scan::ScanParams;

/// `scan`: the scene's scan where a field is left out.
pub(super) fn run(st: &Arc<AppState>, c: &mut Client, msg: ClientMessage) -> Result<Accepted, Refusal> {
    super::instrument::simulated(st, "scan")?;
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
    st.activity.scanning.store(true, Relaxed);
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
