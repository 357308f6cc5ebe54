//! The soak's figures: per-second readings of the loop's counters and of the CPUs, their
//! windows (idle before, loaded, idle after; in an alternating run each split into the seconds
//! of its three regimes), the operator's telemetry gaps, and the test of whether the loaded window's
//! overrun rate is above the idle one's.

use std::time::Instant;

/// One second's reading: the loop's counters so far, and the jiffies each CPU spent stolen by
/// the hypervisor, and in interrupts and softirqs, so far (`/proc/stat`).
#[derive(Debug, Clone)]
pub struct Sample {
    pub at: Instant,
    pub overruns: f64,
    /// Ticks that started more than 0.5 ms after their deadline so far.
    pub late: f64,
    /// Ticks in which a phase (control, physics, publish) computed for more than 0.2 ms so far.
    pub slow: f64,
    /// Per CPU: (steal, irq + softirq) jiffies.
    pub cpus: Vec<(u64, u64)>,
}

/// Per CPU, the jiffies stolen and spent in interrupts and softirqs so far.
pub fn cpu_jiffies(ncpu: usize) -> Vec<(u64, u64)> {
    let stat = std::fs::read_to_string("/proc/stat").unwrap_or_default();
    (0..ncpu)
        .map(|cpu| {
            let f = nanopush_e2e::procfs::cpu_jiffies(&stat, Some(cpu)).unwrap_or_default();
            // user nice system idle iowait irq softirq steal
            let at = |i: usize| f.get(i).copied().unwrap_or(0);
            (at(7), at(5) + at(6))
        })
        .collect()
}

/// What the samples of a window add up to.
#[derive(Debug, Clone, Default)]
pub struct Window {
    /// The time the kept seconds cover.
    pub minutes: f64,
    pub overruns: f64,
    /// Ticks that woke more than 0.5 ms late, and ticks with a phase computing over 0.2 ms.
    pub late: f64,
    pub slow: f64,
    /// Overruns in seconds when the loop's CPU was stolen from, and how many such seconds.
    pub in_stolen_seconds: f64,
    pub stolen_seconds: usize,
    /// Per CPU: steal and interrupt time (ms a minute).
    pub steal_ms: Vec<f64>,
    pub irq_ms: Vec<f64>,
    /// Overruns in each whole minute from the window's start (seconds not kept count nowhere).
    pub per_minute: Vec<f64>,
}

impl Window {
    /// Overruns a minute.
    pub fn rate(&self) -> f64 {
        self.overruns / self.minutes
    }
}

/// Sums the seconds between consecutive samples that lie in `[from, to]` and that `keep` accepts
/// (given the second's start and end); `loop_cpu`'s steal decides the stolen seconds.
pub fn window(
    samples: &[Sample],
    from: Instant,
    to: Instant,
    loop_cpu: usize,
    keep: impl Fn(Instant, Instant) -> bool,
) -> Window {
    let jiffy_ms = 1e3 / unsafe { libc::sysconf(libc::_SC_CLK_TCK) } as f64;
    let inside: Vec<&Sample> = samples.iter().filter(|s| s.at >= from && s.at <= to).collect();
    let ncpu = inside.first().map_or(0, |s| s.cpus.len());
    let mut w = Window {
        per_minute: vec![0.0; ((to - from).as_secs_f64() / 60.0).floor() as usize],
        steal_ms: vec![0.0; ncpu],
        irq_ms: vec![0.0; ncpu],
        ..Window::default()
    };
    for p in inside.windows(2) {
        let (a, b) = (p[0], p[1]);
        if !keep(a.at, b.at) {
            continue;
        }
        let d = b.overruns - a.overruns;
        w.minutes += (b.at - a.at).as_secs_f64() / 60.0;
        w.overruns += d;
        w.late += b.late - a.late;
        w.slow += b.slow - a.slow;
        if let Some(m) = w.per_minute.get_mut(((b.at - from).as_secs_f64() / 60.0) as usize) {
            *m += d;
        }
        if b.cpus.get(loop_cpu).map(|c| c.0) > a.cpus.get(loop_cpu).map(|c| c.0) {
            w.in_stolen_seconds += d;
            w.stolen_seconds += 1;
        }
        for (c, (x, y)) in a.cpus.iter().zip(&b.cpus).enumerate() {
            w.steal_ms[c] += (y.0 - x.0) as f64 * jiffy_ms;
            w.irq_ms[c] += (y.1 - x.1) as f64 * jiffy_ms;
        }
    }
    for v in w.steal_ms.iter_mut().chain(w.irq_ms.iter_mut()) {
        *v /= w.minutes;
    }
    w
}

/// What the idle cores may do, in an alternating run.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Regime {
    /// Every core may halt (`nanopush serve --allow-cpu-halt` alone).
    Halt,
    /// The loop's core polls (its PM QoS resume latency `n/a`), as the server keeps it.
    CorePolls,
    /// Every core polls (`/dev/cpu_dma_latency` = 0 held, as `cyclictest` holds it).
    AllPoll,
}

impl Regime {
    /// In the order an alternating run takes them.
    pub const ALL: [Regime; 3] = [Regime::Halt, Regime::CorePolls, Regime::AllPoll];

    /// As the report names it.
    pub fn name(self) -> &'static str {
        match self {
            Regime::Halt => "cores may halt",
            Regime::CorePolls => "the loop's core polls",
            Regime::AllPoll => "every core polls",
        }
    }
}

/// The regimes of an alternating run over time.
#[derive(Debug, Clone, Default)]
pub struct Regimes {
    /// (when, the regime from then on), in time order.
    pub switches: Vec<(Instant, Regime)>,
}

impl Regimes {
    /// The regime at `t` (None before the first switch).
    pub fn at(&self, t: Instant) -> Option<Regime> {
        self.switches.iter().rev().find(|(s, _)| *s <= t).map(|(_, r)| *r)
    }

    /// Whether the whole of `[a, b]` lies in one regime, and that regime is `r`.
    pub fn within(&self, a: Instant, b: Instant, r: Regime) -> bool {
        self.at(a) == Some(r) && !self.switches.iter().any(|(s, _)| *s > a && *s < b)
    }
}

/// The gaps between consecutive arrivals (s) whose later arrival `keep` accepts, sorted.
pub fn gaps(arrivals: &[Instant], keep: impl Fn(Instant, Instant) -> bool) -> Vec<f64> {
    let mut g: Vec<f64> = arrivals
        .windows(2)
        .filter(|w| keep(w[0], w[1]))
        .map(|w| (w[1] - w[0]).as_secs_f64())
        .collect();
    g.sort_by(f64::total_cmp);
    g
}

/// Quantile `p` of sorted values (the value at rank floor(n p)); NaN when empty.
pub fn quantile(sorted: &[f64], p: f64) -> f64 {
    sorted
        .get(((sorted.len() as f64 * p) as usize).min(sorted.len().saturating_sub(1)))
        .copied()
        .unwrap_or(f64::NAN)
}

/// P(X >= k) for X ~ Binomial(n, p): under equal overrun rates, each of the `n` overruns falls in
/// the loaded window with probability `p`, its share of the observed time (a conditional test of
/// two Poisson rates). Summed in logs, so that (1 - p)^n does not underflow for large `n`.
pub fn upper_tail(n: u64, k: u64, p: f64) -> f64 {
    if k == 0 {
        return 1.0;
    }
    if k > n || p <= 0.0 {
        return 0.0;
    }
    if p >= 1.0 {
        return 1.0;
    }
    let (lp, lq) = (p.ln(), (1.0 - p).ln());
    // ln C(n, i), from i = 0 up.
    let mut ln_choose = 0.0;
    let mut tail = 0.0;
    for i in 0..=n {
        if i > 0 {
            ln_choose += ((n - i + 1) as f64).ln() - (i as f64).ln();
        }
        if i >= k {
            tail += (ln_choose + i as f64 * lp + (n - i) as f64 * lq).exp();
        }
    }
    tail.min(1.0)
}

/// The loaded window's overruns against the idle windows': the rates and the verdict on the
/// goal "no more overruns under load than idle".
pub fn compare(loaded: &Window, idle: &[&Window]) -> String {
    let idle_n: f64 = idle.iter().map(|w| w.overruns).sum();
    let idle_min: f64 = idle.iter().map(|w| w.minutes).sum();
    let n = idle_n + loaded.overruns;
    let p = upper_tail(
        n.round() as u64,
        loaded.overruns.round() as u64,
        loaded.minutes / (loaded.minutes + idle_min),
    );
    let (idle_rate, loaded_rate) = (idle_n / idle_min, loaded.rate());
    format!(
        "{loaded_rate:.2} against {idle_rate:.2} a minute ({:.0} in {:.1} min against {idle_n:.0} in {idle_min:.1} min); \
         were the rates equal, {:.0} or more of the {n:.0} would fall in the loaded window with probability {p:.3}: {}",
        loaded.overruns,
        loaded.minutes,
        loaded.overruns,
        if loaded_rate <= idle_rate {
            "no more than idle (goal met)"
        } else if p >= 0.05 {
            "above idle by no more than chance (p >= 0.05)"
        } else {
            "more than idle (p < 0.05: goal not met)"
        }
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Duration;

    #[test]
    fn the_binomial_tail_against_sums_by_hand() {
        assert_eq!(upper_tail(10, 0, 0.5), 1.0);
        assert!((upper_tail(10, 10, 0.5) - 1.0 / 1024.0).abs() < 1e-15);
        // C(4,2) + C(4,3) + C(4,4) = 11 of 16.
        assert!((upper_tail(4, 2, 0.5) - 11.0 / 16.0).abs() < 1e-12);
        // 1 - (2/3)^3 with p = 1/3: at least one of three.
        assert!((upper_tail(3, 1, 1.0 / 3.0) - (1.0 - 8.0 / 27.0)).abs() < 1e-12);
        assert_eq!(upper_tail(3, 4, 0.5), 0.0);
        // 3000 trials: (1/2)^3000 underflows, the tail does not. Symmetry: P(X >= 1500) =
        // 1/2 + P(X = 1500)/2, and P(X = 1500) ~ 1/sqrt(pi * 1500) = 0.01457.
        let t = upper_tail(3000, 1500, 0.5);
        assert!((t - (0.5 + 0.5 * 0.014566)).abs() < 1e-4, "{t}");
    }

    fn sample(at: Instant, overruns: f64, steal: u64) -> Sample {
        Sample {
            at,
            overruns,
            late: overruns,
            slow: 0.0,
            cpus: vec![(0, 0), (steal, 0)],
        }
    }

    #[test]
    fn a_window_keeps_only_the_seconds_of_its_regime() {
        let t0 = Instant::now();
        let s = |i: u64| t0 + Duration::from_secs(i);
        // Overruns so far at each second: 1 in the second 0-1, 2 in 1-2, 4 in 2-3, 8 in 3-4.
        let samples: Vec<Sample> = [0.0, 1.0, 3.0, 7.0, 15.0]
            .iter()
            .enumerate()
            .map(|(i, &o)| sample(s(i as u64), o, i as u64 / 3))
            .collect();
        // Polling from 0 s, halting from 2 s on.
        let (poll, halt) = (Regime::CorePolls, Regime::Halt);
        let r = Regimes {
            switches: vec![(s(0), poll), (s(2), halt)],
        };
        assert_eq!(
            (r.at(s(1)), r.at(s(2)), r.at(s(3))),
            (Some(poll), Some(halt), Some(halt))
        );
        assert!(r.within(s(0), s(1), poll) && r.within(s(1), s(2), poll));
        assert!(!r.within(s(1), s(3), poll) && !r.within(s(1), s(3), halt));
        assert!(!r.within(s(0), s(1), Regime::AllPoll));
        let all = window(&samples, s(0), s(4), 1, |_, _| true);
        assert_eq!((all.overruns, all.late), (15.0, 15.0));
        assert!((all.minutes - 4.0 / 60.0).abs() < 1e-9);
        // The loop's CPU was stolen from once, in the second 2-3 (steal 0, 0, 0, 1, 1).
        assert_eq!((all.stolen_seconds, all.in_stolen_seconds), (1, 4.0));
        let poll = window(&samples, s(0), s(4), 1, |a, b| r.within(a, b, Regime::CorePolls));
        let halt = window(&samples, s(0), s(4), 1, |a, b| r.within(a, b, Regime::Halt));
        assert_eq!((poll.overruns, halt.overruns), (3.0, 12.0));
        assert!((poll.rate() - 90.0).abs() < 1e-9 && (halt.rate() - 360.0).abs() < 1e-9);
        // 1 jiffy of steal in 2 s of halting: 10 ms (at 100 Hz) over 1/30 min.
        let jiffy_ms = 1e3 / unsafe { libc::sysconf(libc::_SC_CLK_TCK) } as f64;
        assert!((halt.steal_ms[1] - jiffy_ms * 30.0).abs() < 1e-9, "{:?}", halt.steal_ms);
    }

    #[test]
    fn gaps_and_quantiles() {
        let t0 = Instant::now();
        let at: Vec<Instant> = [0, 10, 30, 60]
            .iter()
            .map(|&ms| t0 + Duration::from_millis(ms))
            .collect();
        let g = gaps(&at, |_, _| true);
        assert_eq!(g, vec![0.01, 0.02, 0.03]);
        assert_eq!(quantile(&g, 0.5), 0.02);
        assert_eq!(quantile(&g, 0.99), 0.03);
        assert!(quantile(&[], 0.5).is_nan());
        let late = gaps(&at, |_, b| b > t0 + Duration::from_millis(20));
        assert_eq!(late, vec![0.02, 0.03]);
    }

    #[test]
    fn the_verdict_follows_the_rates_and_the_tail() {
        let w = |overruns: f64, minutes: f64| Window {
            overruns,
            minutes,
            ..Window::default()
        };
        assert!(compare(&w(11.0, 10.0), &[&w(66.0, 5.0), &w(10.0, 5.0)]).ends_with("(goal met)"));
        // 12 against 10 in equal time: above, but well within chance.
        assert!(compare(&w(12.0, 10.0), &[&w(5.0, 5.0), &w(5.0, 5.0)]).contains("no more than chance"));
        assert!(compare(&w(943.0, 10.0), &[&w(20.0, 5.0), &w(85.0, 5.0)]).contains("goal not met"));
    }
}
