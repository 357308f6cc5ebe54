//! The server's Prometheus exposition, scraped whole: series by name and labels, and the
//! difference of two scrapes of a histogram over a window.

/// One scrape: (metric name, label text inside the braces, value).
pub struct Scrape(pub Vec<(String, String, f64)>);

impl Scrape {
    pub fn parse(text: &str) -> Scrape {
        let mut v = Vec::new();
        for line in text.lines() {
            let line = line.trim();
            if line.is_empty() || line.starts_with('#') {
                continue;
            }
            let Some((series, value)) = line.rsplit_once(' ') else {
                continue;
            };
            let value = match value {
                "+Inf" => f64::INFINITY,
                "-Inf" => f64::NEG_INFINITY,
                x => match x.parse() {
                    Ok(x) => x,
                    Err(_) => continue,
                },
            };
            let (name, labels) = match series.split_once('{') {
                Some((n, l)) => (n, l.trim_end_matches('}')),
                None => (series, ""),
            };
            v.push((name.to_string(), labels.to_string(), value));
        }
        Scrape(v)
    }

    /// An unlabelled series.
    pub fn value(&self, name: &str) -> Option<f64> {
        self.0.iter().find(|(n, l, _)| n == name && l.is_empty()).map(|s| s.2)
    }

    /// A histogram's cumulative buckets `(le, count)`, in exposition order; `phase` selects the
    /// series of a labelled family.
    pub fn buckets(&self, base: &str, phase: Option<&str>) -> Vec<(f64, f64)> {
        let name = format!("{base}_bucket");
        self.0
            .iter()
            .filter(|(n, l, _)| *n == name && phase.is_none_or(|p| label(l, "phase").as_deref() == Some(p)))
            .filter_map(|(_, l, v)| {
                let le = label(l, "le")?;
                let le = if le == "+Inf" { f64::INFINITY } else { le.parse().ok()? };
                Some((le, *v))
            })
            .collect()
    }
}

/// The value of label `key` in a series' label text.
fn label(labels: &str, key: &str) -> Option<String> {
    labels.split(',').find_map(|kv| {
        let (k, v) = kv.split_once('=')?;
        (k.trim() == key).then(|| v.trim().trim_matches('"').to_string())
    })
}

/// A histogram over the window: counts per bucket (not cumulative), with the buckets' upper
/// bounds; bucket `i` holds values in `(bounds[i-1], bounds[i]]`.
#[derive(Debug, Default)]
pub struct Window {
    bounds: Vec<f64>,
    counts: Vec<u64>,
}

impl Window {
    /// The difference of two scrapes of the same histogram.
    pub fn between(start: &[(f64, f64)], end: &[(f64, f64)]) -> Window {
        let mut w = Window::default();
        let mut prev = 0.0;
        for (i, &(le, cum)) in end.iter().enumerate() {
            let before = start.get(i).filter(|s| s.0 == le).map_or(0.0, |s| s.1);
            let d = (cum - before).max(0.0);
            w.bounds.push(le);
            w.counts.push((d - prev).max(0.0).round() as u64);
            prev = d;
        }
        w
    }

    /// Values in the window.
    pub fn total(&self) -> u64 {
        self.counts.iter().sum()
    }

    /// Upper bound of the bucket holding quantile `q`.
    pub fn quantile_bound(&self, q: f64) -> Option<f64> {
        let total = self.total();
        if total == 0 {
            return None;
        }
        let target = ((q * total as f64).ceil() as u64).max(1);
        let mut acc = 0;
        for (c, b) in self.counts.iter().zip(&self.bounds) {
            acc += c;
            if acc >= target {
                return Some(*b);
            }
        }
        self.bounds.last().copied()
    }

    /// The bucket holding the largest value: (lower bound, upper bound].
    pub fn max_bucket(&self) -> Option<(f64, f64)> {
        let i = self.counts.iter().rposition(|&c| c > 0)?;
        let lo = if i == 0 { 0.0 } else { self.bounds[i - 1] };
        Some((lo, self.bounds[i]))
    }

    /// Values above `x` (a bucket bound).
    pub fn above(&self, x: f64) -> u64 {
        self.counts
            .iter()
            .zip(&self.bounds)
            .filter(|(_, b)| **b > x * (1.0 + 1e-9))
            .map(|(c, _)| c)
            .sum()
    }
}
