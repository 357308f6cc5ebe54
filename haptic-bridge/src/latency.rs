//! A latency histogram with 0.1 µs buckets up to 20 ms (and one bucket beyond), allocated once:
//! recording is O(1) and allocation-free, so it runs inside a real-time loop.

/// Bucket width (ns).
const BUCKET_NS: u64 = 100;
/// Buckets below the overflow one.
const BUCKETS: usize = 200_000;

/// Latencies seen so far.
#[derive(Debug, Clone, PartialEq)]
pub struct Histogram {
    counts: Vec<u64>,
    n: u64,
    max: u64,
}

impl Default for Histogram {
    fn default() -> Histogram {
        Histogram {
            counts: vec![0; BUCKETS + 1],
            n: 0,
            max: 0,
        }
    }
}

impl Histogram {
    /// Records one latency (ns).
    pub fn record(&mut self, ns: u64) {
        let i = ((ns / BUCKET_NS) as usize).min(BUCKETS);
        self.counts[i] += 1;
        self.n += 1;
        self.max = self.max.max(ns);
    }

    /// Samples recorded.
    pub fn count(&self) -> u64 {
        self.n
    }

    /// Largest latency (ns).
    pub fn max(&self) -> u64 {
        self.max
    }

    /// The `q` quantile (0..1) as the upper edge of its bucket (ns); 0 when empty. Beyond 20 ms
    /// it is the maximum.
    pub fn quantile(&self, q: f64) -> u64 {
        if self.n == 0 {
            return 0;
        }
        let rank = ((q.clamp(0.0, 1.0) * self.n as f64).ceil() as u64).max(1);
        let mut seen = 0;
        for (i, &c) in self.counts.iter().enumerate() {
            seen += c;
            if seen >= rank {
                return if i == BUCKETS {
                    self.max
                } else {
                    ((i as u64 + 1) * BUCKET_NS).min(self.max)
                };
            }
        }
        self.max
    }

    /// `p50 … p99 … p99.9 … max` in µs, for a report line.
    pub fn summary(&self) -> String {
        let us = |ns: u64| ns as f64 / 1e3;
        format!(
            "p50 {:.1} µs, p99 {:.1} µs, p99.9 {:.1} µs, max {:.1} µs ({} samples)",
            us(self.quantile(0.5)),
            us(self.quantile(0.99)),
            us(self.quantile(0.999)),
            us(self.max),
            self.n
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quantiles_are_bucket_upper_edges_of_the_ranked_sample() {
        let mut h = Histogram::default();
        assert_eq!(h.quantile(0.5), 0);
        for us in 1..=100u64 {
            h.record(us * 1000 - 50);
        }
        assert_eq!(h.count(), 100);
        assert_eq!(h.quantile(0.5), 50_000);
        assert_eq!(h.quantile(0.99), 99_000);
        assert_eq!(h.quantile(1.0), 99_950);
        assert_eq!(h.max(), 99_950);
        h.record(1_000_000_000);
        assert_eq!(h.quantile(1.0), 1_000_000_000);
        assert!(
            h.summary().contains("max 1000000.0 µs (101 samples)"),
            "{}",
            h.summary()
        );
    }
}
