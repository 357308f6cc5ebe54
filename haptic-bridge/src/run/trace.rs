//! The `--trace` CSV: one row per device cycle, written by a thread of its own.

use std::io::Write;
use std::path::PathBuf;
use std::sync::mpsc;

use anyhow::Context;
use nanopush_haptic::bridge::CycleRow;

/// The trace's header.
const TRACE_HEADER: &str =
    "t_s,handle_m,handle_force_n,tip_z_m,tip_force_n,link,pc_damping,port_energy_j,raw_port_energy_j,holding\n";

fn trace_line(r: &CycleRow) -> String {
    format!(
        "{:.6},{:.9e},{:.6},{:.6e},{:.6e},{},{:.6},{:.6e},{:.6e},{}\n",
        r.t,
        r.handle,
        r.force,
        r.tip_z,
        r.tip_force,
        if r.link { "up" } else { "down" },
        r.pc_damping,
        r.port_energy,
        r.raw_port_energy,
        u8::from(r.holding)
    )
}

/// Starts the trace writer thread: rows arrive through a bounded channel (the device loop never
/// blocks on the disk; a full channel drops the row and counts it).
pub fn trace_writer(
    path: PathBuf,
) -> anyhow::Result<(mpsc::SyncSender<CycleRow>, std::thread::JoinHandle<std::io::Result<()>>)> {
    let file = std::fs::File::create(&path).with_context(|| format!("creating the trace {}", path.display()))?;
    let (tx, rx) = mpsc::sync_channel::<CycleRow>(1 << 14);
    let handle = std::thread::spawn(move || {
        let mut w = std::io::BufWriter::new(file);
        w.write_all(TRACE_HEADER.as_bytes())?;
        for row in rx {
            w.write_all(trace_line(&row).as_bytes())?;
        }
        w.flush()
    });
    Ok((tx, handle))
}
