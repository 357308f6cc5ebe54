//! Fixed-bucket histograms of atomic counters, summed lock-free by the control loop (no
//! allocation, no lock) and rendered as Prometheus text off the loop.

use std::fmt::Write as _;
use std::sync::atomic::{AtomicU64, Ordering::Relaxed};

/// Bucket upper bounds (s) of the period-error and compute-time histograms: 0.5 µs to 10 ms.
pub const BUCKETS: [f64; 20] = [
    0.5e-6, 1e-6, 2e-6, 3e-6, 5e-6, 7.5e-6, 10e-6, 15e-6, 20e-6, 30e-6, 50e-6, 75e-6, 100e-6, 200e-6, 500e-6, 1e-3,
    2e-3, 5e-3, 10e-3, 100e-3,
];

/// A histogram of non-negative seconds with [`BUCKETS`].
#[derive(Debug, Default)]
pub struct Histogram {
    counts: [AtomicU64; BUCKETS.len() + 1],
    sum_ns: AtomicU64,
    max_ns: AtomicU64,
}

impl Histogram {
    /// Records one value (s); negative values count as 0.
    pub fn record(&self, seconds: f64) {
        if seconds.is_nan() {
            return;
        }
        let v = seconds.max(0.0);
        let i = BUCKETS.iter().position(|&b| v <= b).unwrap_or(BUCKETS.len());
        self.counts[i].fetch_add(1, Relaxed);
        let ns = (v * 1e9) as u64;
        self.sum_ns.fetch_add(ns, Relaxed);
        self.max_ns.fetch_max(ns, Relaxed);
    }

    /// Number of values.
    pub fn count(&self) -> u64 {
        self.counts.iter().map(|c| c.load(Relaxed)).sum()
    }

    /// Largest value (s).
    pub fn max(&self) -> f64 {
        self.max_ns.load(Relaxed) as f64 * 1e-9
    }

    /// The upper bound of the bucket holding quantile `q` (s): a bound, at bucket resolution.
    pub fn quantile_bound(&self, q: f64) -> f64 {
        let counts: Vec<u64> = self.counts.iter().map(|c| c.load(Relaxed)).collect();
        let total: u64 = counts.iter().sum();
        if total == 0 {
            return 0.0;
        }
        let target = (q * total as f64).ceil().max(1.0) as u64;
        let mut acc = 0;
        for (i, c) in counts.iter().enumerate() {
            acc += c;
            if acc >= target {
                return BUCKETS.get(i).copied().unwrap_or_else(|| self.max());
            }
        }
        self.max()
    }

    /// Appends the histogram in Prometheus text format.
    pub(crate) fn render(&self, out: &mut String, name: &str, help: &str, header: bool, label: Option<(&str, &str)>) {
        let lbl = |extra: &str| match (label, extra.is_empty()) {
            (Some((k, v)), true) => format!("{{{k}=\"{v}\"}}"),
            (Some((k, v)), false) => format!("{{{k}=\"{v}\",{extra}}}"),
            (None, true) => String::new(),
            (None, false) => format!("{{{extra}}}"),
        };
        if header {
            let _ = writeln!(out, "# HELP {name} {help}");
            let _ = writeln!(out, "# TYPE {name} histogram");
        }
        let mut acc = 0;
        for (i, b) in BUCKETS.iter().enumerate() {
            acc += self.counts[i].load(Relaxed);
            let _ = writeln!(out, "{name}_bucket{} {acc}", lbl(&format!("le=\"{b:e}\"")));
        }
        acc += self.counts[BUCKETS.len()].load(Relaxed);
        let _ = writeln!(out, "{name}_bucket{} {acc}", lbl("le=\"+Inf\""));
        let _ = writeln!(
            out,
            "{name}_sum{} {:e}",
            lbl(""),
            self.sum_ns.load(Relaxed) as f64 * 1e-9
        );
        let _ = writeln!(out, "{name}_count{} {acc}", lbl(""));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn histogram_buckets_are_cumulative_and_quantiles_bound_the_values() {
        let h = Histogram::default();
        for v in [0.2e-6, 0.8e-6, 4e-6, 4e-6, 12e-6, 0.5] {
            h.record(v);
        }
        assert_eq!(h.count(), 6);
        assert_eq!(h.quantile_bound(0.5), 5e-6);
        assert_eq!(h.quantile_bound(0.8), 15e-6);
        assert!((h.max() - 0.5).abs() < 1e-9);
        let mut s = String::new();
        h.render(&mut s, "x_seconds", "help", true, None);
        assert!(s.contains("x_seconds_bucket{le=\"5e-6\"} 4\n"), "{s}");
        assert!(s.contains("x_seconds_bucket{le=\"+Inf\"} 6\n"));
        assert!(s.contains("x_seconds_count 6\n"));
    }
}
