//! What the kernel says of a process and of the CPUs (`/proc`), for the benchmarks' accounts of
//! the server's footprint and of where the machine's time went.

/// A numeric line of `/proc/…/status` (`VmRSS:  1234 kB` gives 1234, `nonvoluntary_ctxt_switches:
/// 7` gives 7), None when the file or the key is missing.
pub fn status_field(path: &str, key: &str) -> Option<u64> {
    let s = std::fs::read_to_string(path).ok()?;
    s.lines().find_map(|l| {
        l.strip_prefix(key)?
            .trim_start_matches(':')
            .trim()
            .trim_end_matches("kB")
            .trim()
            .parse()
            .ok()
    })
}

/// The jiffies of one line of `/proc/stat` text `stat`: the machine's (`cpu`) for None, core
/// `n`'s (`cpuN`) for `Some(n)`; in the kernel's order: user nice system idle iowait irq softirq
/// steal guest guest_nice.
pub fn cpu_jiffies(stat: &str, cpu: Option<usize>) -> Option<Vec<u64>> {
    let label = cpu.map_or_else(|| "cpu ".to_string(), |c| format!("cpu{c} "));
    let line = stat.lines().find_map(|l| l.strip_prefix(label.as_str()))?;
    Some(line.split_whitespace().filter_map(|v| v.parse().ok()).collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_machines_line_and_a_cores_line_are_told_apart() {
        let stat = "cpu  10 0 5 100 1 2 3 4 0 0\ncpu0 6 0 2 50 0 1 1 2 0 0\ncpu1 4 0 3 50 1 1 2 2 0 0\nintr 1\n";
        assert_eq!(cpu_jiffies(stat, None), Some(vec![10, 0, 5, 100, 1, 2, 3, 4, 0, 0]));
        assert_eq!(cpu_jiffies(stat, Some(1)), Some(vec![4, 0, 3, 50, 1, 1, 2, 2, 0, 0]));
        assert_eq!(cpu_jiffies(stat, Some(2)), None);
    }

    #[test]
    fn status_fields_are_read_with_and_without_a_unit() {
        let pid = std::process::id();
        let path = format!("/proc/{pid}/status");
        assert!(status_field(&path, "VmRSS").is_some_and(|kb| kb > 0));
        assert!(status_field(&path, "nonvoluntary_ctxt_switches").is_some());
        assert_eq!(status_field(&path, "NoSuchKey"), None);
    }
}
