//! The end of a run: the line said on stderr, the `--json` summary and the device's faults by
//! name.

use nanopush_haptic::device::DeviceFaults;

use super::device_loop::Tally;

/// The line said on stderr at the end of a run: cycles, the rate, drops, overruns, the
/// end-to-end latency, the device's faults by kind, the watchdog's trips and the cable's losses.
pub fn end_line(t: &Tally, dropped_samples: u64, rate_hz: f64, f: &DeviceFaults) -> String {
    format!(
        "nanopush-haptic: {} cycles at {rate_hz} Hz, {} samples dropped, {} overruns (the bridge's own), {} trace rows dropped; end-to-end latency {}; device faults: {} bad packets, {} late answers, {} sequence gaps, {} out of range; {} watchdog trips (the device heard nothing for 10 ms); cable: {} losses, {} reopens",
        t.cycles,
        dropped_samples,
        f.overruns,
        t.dropped_rows,
        t.hist.summary(),
        f.bad_packets,
        f.timeouts,
        f.seq_gaps,
        f.out_of_range,
        f.watchdog_trips,
        f.losses,
        f.reopens
    )
}

/// The `--json` summary: cycles, the rate, drops, overruns, the largest force, the latency
/// quantiles, the device's faults by side, and whether the device was lost at the end.
pub fn summary_json(t: &Tally, dropped_samples: u64, rate_hz: f64, f: &DeviceFaults, lost: Option<&str>) -> String {
    format!(
        "{}\n",
        serde_json::json!({
            "cycles": t.cycles,
            "rate_hz": rate_hz,
            "dropped_samples": dropped_samples,
            "overruns": f.overruns,
            "dropped_rows": t.dropped_rows,
            "max_force_n": t.max_force_seen,
            "latency_ns": {
                "samples": t.hist.count(),
                "p50": t.hist.quantile(0.5),
                "p99": t.hist.quantile(0.99),
                "p999": t.hist.quantile(0.999),
                "max": t.hist.max(),
            },
            "device_faults": faults_json(f),
            "device_lost": lost,
        })
    )
}

/// The device's faults as JSON by name, with each name's side (as `/api/status` shows them).
pub fn faults_json(f: &DeviceFaults) -> serde_json::Value {
    let mut out = serde_json::Map::new();
    for ((name, _), n) in DeviceFaults::KINDS.iter().zip(f.counts()) {
        out.insert((*name).into(), n.into());
    }
    let sides = DeviceFaults::KINDS.iter().map(|(n, s)| ((*n).to_string(), (*s).into()));
    out.insert("side".into(), serde_json::Map::from_iter(sides).into());
    out.into()
}
