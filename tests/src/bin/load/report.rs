//! The report: tables in Markdown (the default) or one JSON document (`--json`).

use serde_json::{Value, json};

use crate::Opts;
use crate::level::{Level, Second};

/// Seconds in µs / ms / s, up to two decimals, trailing zeros dropped.
fn dur(s: f64) -> String {
    let (v, unit) = if !s.is_finite() {
        return "∞".into();
    } else if s < 1e-3 {
        (s * 1e6, "µs")
    } else if s < 1.0 {
        (s * 1e3, "ms")
    } else {
        (s, "s")
    };
    let t = format!("{v:.2}");
    let t = t.trim_end_matches('0').trim_end_matches('.');
    format!("{t} {unit}")
}

/// [`dur`] of a bound; "> 100 ms" for the histogram's last, unbounded bucket, "-" for none.
fn opt_dur(s: Option<f64>) -> String {
    match s {
        Some(s) if s.is_finite() => dur(s),
        Some(_) => "> 100 ms".into(),
        None => "-".into(),
    }
}

/// A bucket `(lower, upper]` as "lower-upper", or "> lower" for the last one.
fn bucket(b: Option<(f64, f64)>) -> String {
    match b {
        Some((lo, hi)) if hi.is_finite() => format!("{}-{}", dur(lo), dur(hi)),
        Some((lo, _)) => format!("> {}", dur(lo)),
        None => "-".into(),
    }
}

/// The tables: the loop's period error, the telemetry delivered and the shutdown, the CPU; then
/// each level's timeline and the notes.
pub fn print_tables(o: &Opts, cpus: usize, levels: &[Level]) {
    print_intro(o, cpus);
    println!();
    print_loop_table(levels);
    println!();
    print_delivery_table(levels);
    println!();
    print_cpu_table(cpus, levels);
    println!();
    for l in levels {
        println!("{}", timeline_summary(l));
    }
    let notes = notes(levels);
    if !notes.is_empty() {
        println!();
        for n in notes {
            println!("note: {n}");
        }
    }
}

/// What was run, on how many CPUs.
fn print_intro(o: &Opts, cpus: usize) {
    println!(
        "nanopush-load: {cpus} CPUs; control loop at {} Hz; {} s window per level; a fresh server per level.",
        o.rate_hz, o.seconds
    );
    println!(
        "The viewers run in this process (one tokio current-thread runtime) on the same {cpus} cores as the server."
    );
}

/// The loop's period error over the window, a row per level.
fn print_loop_table(levels: &[Level]) {
    println!(
        "Loop period error over the window (from the /metrics difference). p50 and p99 are bucket upper bounds \
         (nanopush_loop_period_error_seconds resolution); \"max, window\" is the bucket holding the largest value; \
         \"max, life\" is /api/status loop.period_error_max_s, the server's whole life, connection setup included."
    );
    println!();
    println!(
        "| viewers | p50 ≤ | p99 ≤ | max, window | max, life | mean | ticks > 20 µs | overruns | ticks | realtime |"
    );
    println!("|---:|---:|---:|---:|---:|---:|---:|---:|---:|:---:|");
    for l in levels {
        println!(
            "| {} | {} | {} | {} | {} | {} | {} | {} | {} | {} |",
            l.viewers,
            opt_dur(l.p50),
            opt_dur(l.p99),
            bucket(l.max_bucket),
            opt_dur(l.max_life),
            opt_dur(l.mean),
            l.over_goal,
            l.overruns,
            l.ticks,
            match l.realtime {
                Some(1.0) => "SCHED_FIFO",
                Some(_) => "no",
                None => "?",
            }
        );
    }
}

/// Telemetry delivered per client and the shutdown, a row per level.
fn print_delivery_table(levels: &[Level]) {
    println!(
        "Telemetry delivered per client over the window (counted by the viewers; the server sends ~60 Hz). \
         \"server sent\" is nanopush_telemetry_sent_total per client; skipped is the sum of lagged.skipped. \
         After the window the server gets SIGTERM with every viewer connected: how many were sent `shutdown` \
         and a close frame, and how long the server took to exit."
    );
    println!();
    println!(
        "| viewers | subscribed | connect s | mean Hz | min Hz | max Hz | server sent Hz | skipped | clients lagged | closed early | shutdown told | close frame | exit s |"
    );
    println!("|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|");
    for l in levels {
        println!(
            "| {} | {} | {:.1} | {:.2} | {:.2} | {:.2} | {:.2} | {} | {} | {} | {}/{} | {}/{} | {:.2}{} |",
            l.viewers,
            l.connected,
            l.connect_s,
            l.rate_mean,
            l.rate_min,
            l.rate_max,
            l.server_sent_rate,
            l.skipped,
            l.lagged_clients,
            l.closed_in_window,
            l.got_shutdown,
            l.connected,
            l.got_close,
            l.connected,
            l.stop_s,
            if l.killed { " (killed)" } else { "" }
        );
    }
}

/// CPU over the window, a row per level.
fn print_cpu_table(cpus: usize, levels: &[Level]) {
    println!(
        "CPU over the window, in cores (of {cpus}): the server, its control-loop thread, this benchmark, everything \
         else; hypervisor steal (ms, all cores), and steal and irq+softirq time (ms) on the loop's core (/proc/stat, \
         10 ms resolution); the loop thread's involuntary context switches; compute-time p99 bounds per phase."
    );
    println!();
    println!(
        "| viewers | server | loop thread | bench | other | steal ms | loop core | its steal ms | its irq ms | loop preempted | control p99 ≤ | physics p99 ≤ | publish p99 ≤ |"
    );
    println!("|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|");
    for l in levels {
        println!(
            "| {} | {:.2} | {:.2} | {:.2} | {:.2} | {:.0} | {} | {:.0} | {:.0} | {} | {} | {} | {} |",
            l.viewers,
            l.cpu_server,
            l.cpu_loop,
            l.cpu_bench,
            l.cpu_other,
            l.cpu_steal * l.window_s * 1e3,
            l.loop_core.map_or("?".to_string(), |c| c.to_string()),
            l.core_steal_ms,
            l.core_irq_ms,
            l.loop_nvcsw,
            opt_dur(l.compute_p99[0]),
            opt_dur(l.compute_p99[1]),
            opt_dur(l.compute_p99[2]),
        );
    }
}

/// What went wrong at any level: viewers that failed to connect, other real-time processes, the
/// server's WARN/ERROR lines, an exit other than 0.
fn notes(levels: &[Level]) -> Vec<String> {
    let mut notes = Vec::new();
    for l in levels {
        if !l.connect_errors.is_empty() {
            notes.push(format!(
                "{} viewers: {} failed to connect, e.g. {}",
                l.viewers,
                l.connect_errors.len(),
                l.connect_errors[0]
            ));
        }
        if !l.other_rt.is_empty() {
            notes.push(format!(
                "{} viewers: other real-time (SCHED_FIFO/RR) processes were running: {}",
                l.viewers,
                l.other_rt.join(", ")
            ));
        }
        if l.log_problems.0 > 0 {
            notes.push(format!(
                "{} viewers: the server logged {} WARN/ERROR lines, e.g. {}",
                l.viewers,
                l.log_problems.0,
                l.log_problems.1.join(" | ")
            ));
        }
        if l.exit_code != Some(0) {
            notes.push(format!(
                "{} viewers: the server exited with {:?}",
                l.viewers, l.exit_code
            ));
        }
    }
    notes
}

/// Per level: the seconds of the window with an overrun or a tick late by more than 1 ms, and
/// whether the loop's core saw steal in them.
fn timeline_summary(l: &Level) -> String {
    let late = |s: &Second| s.max_bucket.is_some_and(|(lo, _)| lo >= 1e-3);
    let bad: Vec<&Second> = l.timeline.iter().filter(|s| s.overruns > 0.0 || late(s)).collect();
    let stolen = bad.iter().filter(|s| s.core_steal_ms > 0.0).count();
    let stolen_all = l.timeline.iter().filter(|s| s.core_steal_ms > 0.0).count();
    let worst = l
        .timeline
        .iter()
        .max_by(|a, b| {
            let x = a.max_bucket.map_or(0.0, |m| m.0);
            let y = b.max_bucket.map_or(0.0, |m| m.0);
            x.total_cmp(&y)
        })
        .map_or(String::new(), |s| {
            format!(
                "; the worst in the second ending at {:.0} s ({}, {} over 20 µs)",
                s.t,
                bucket(s.max_bucket),
                s.over_goal
            )
        });
    format!(
        "{} viewers: {} of {} seconds had an overrun or a tick > 1 ms late, {} of them with steal on the loop's core \
         (steal in {} seconds in all){worst}.",
        l.viewers,
        bad.len(),
        l.timeline.len(),
        stolen,
        stolen_all,
    )
}

/// One level as JSON, for `--json`.
pub fn level_json(l: &Level) -> Value {
    json!({
        "viewers": l.viewers,
        "subscribed": l.connected,
        "connect_errors": l.connect_errors,
        "connect_s": l.connect_s,
        "window_s": l.window_s,
        "realtime": l.realtime,
        "other_realtime_processes": l.other_rt,
        "period_error": {
            "note": "p50/p99 are bucket upper bounds over the window; max_bucket_s is the (lower, upper] bucket of the window's largest; max_life_s is /api/status over the whole server life",
            "p50_bound_s": l.p50,
            "p99_bound_s": l.p99,
            "max_bucket_s": l.max_bucket.map(|(lo, hi)| json!([lo, hi.is_finite().then_some(hi)])),
            "max_life_s": l.max_life,
            "mean_s": l.mean,
            "ticks_over_20us": l.over_goal,
            "ticks": l.hist_ticks,
        },
        "overruns": l.overruns,
        "ticks": l.ticks,
        "compute_p99_bound_s": {"control": l.compute_p99[0], "physics": l.compute_p99[1], "publish": l.compute_p99[2]},
        "telemetry_per_client_hz": {"mean": l.rate_mean, "min": l.rate_min, "max": l.rate_max},
        "server_sent_per_client_hz": l.server_sent_rate,
        "skipped": l.skipped,
        "server_dropped_frames": l.server_dropped,
        "clients_lagged": l.lagged_clients,
        "closed_in_window": l.closed_in_window,
        "cpu_cores": {"server": l.cpu_server, "loop_thread": l.cpu_loop, "bench": l.cpu_bench, "other": l.cpu_other, "steal": l.cpu_steal},
        "loop_involuntary_switches": l.loop_nvcsw,
        "loop_core": l.loop_core,
        "loop_core_steal_ms": l.core_steal_ms,
        "loop_core_irq_softirq_ms": l.core_irq_ms,
        "timeline": l.timeline.iter().map(|s| json!({
            "t_s": s.t,
            "overruns": s.overruns,
            "ticks_over_20us": s.over_goal,
            "max_bucket_s": s.max_bucket.map(|(lo, hi)| json!([lo, hi.is_finite().then_some(hi)])),
            "loop_core_steal_ms": s.core_steal_ms,
            "loop_core_irq_softirq_ms": s.core_irq_ms,
        })).collect::<Vec<_>>(),
        "shutdown": {"exit_s": l.stop_s, "exit_code": l.exit_code, "killed": l.killed, "clients_told": l.got_shutdown, "clients_closed_cleanly": l.got_close},
        "server_log_problems": {"count": l.log_problems.0, "examples": l.log_problems.1},
    })
}
