//! The server's Prometheus exposition (`/metrics`), read one series at a time.

/// The value of series `series` in a Prometheus exposition: the line that starts with the name
/// and its labels exactly as the server writes them (`nanopush_loop_overruns_total`,
/// `nanopush_loop_compute_seconds_sum{phase="control"}`), then a space.
pub fn series(text: &str, series: &str) -> Option<f64> {
    text.lines()
        .find_map(|l| l.strip_prefix(series)?.strip_prefix(' '))
        .and_then(|v| v.trim().parse().ok())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_series_is_found_by_its_name_and_labels_not_by_a_prefix() {
        let text = "# TYPE a counter\na_total 3\na 1.5\nb{phase=\"x\"} 2e-3\n";
        assert_eq!(series(text, "a"), Some(1.5));
        assert_eq!(series(text, "a_total"), Some(3.0));
        assert_eq!(series(text, "b{phase=\"x\"}"), Some(2e-3));
        assert_eq!(series(text, "b"), None);
    }
}
