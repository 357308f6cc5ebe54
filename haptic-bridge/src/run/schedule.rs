//! The device cycle's timing: SCHED_FIFO and a core of its own when the system grants them, an
//! absolute-deadline schedule (sleep, then spin the last stretch) locked to the server's tick.

use std::time::Duration;

use nanopush_proto::haptic::monotonic_ns;

/// The device loop's SCHED_FIFO priority, when granted: below the server's control loop (50).
const DEVICE_LOOP_PRIORITY: i32 = 45;

/// Asks for SCHED_FIFO priority [`DEVICE_LOOP_PRIORITY`] on `cpu` (clamped to the online cores);
/// says what was granted.
pub fn make_realtime(cpu: usize) {
    let core = nanopush_rt::resolve_core(Some(cpu));
    let pinned = nanopush_rt::pin_to_core(Some(cpu)).is_ok();
    let fifo = nanopush_rt::sched_fifo(DEVICE_LOOP_PRIORITY).is_ok();
    eprintln!(
        "nanopush-haptic: device loop {} core {core}, {}",
        if pinned { "pinned to" } else { "not pinned to" },
        if fifo {
            format!("SCHED_FIFO {DEVICE_LOOP_PRIORITY}")
        } else {
            "SCHED_OTHER (SCHED_FIFO refused)".to_string()
        }
    );
}

/// How long after the server's force sample the device cycle runs (ns): the bridge reads the
/// handle just after the server has ticked, so its sample waits one server period, not two.
pub const PHASE_LEAD_NS: u64 = 30_000;

/// The next cycle's deadline (monotonic ns) after the one at `prev`: one period on, nudged
/// toward the server's tick when a server is live — a quarter of the phase error per cycle, at
/// most a tenth of a period — so that the device cycle settles `PHASE_LEAD_NS` after the server's
/// force sample. The period never changes by more than that nudge: a late server sample never
/// makes the bridge skip a cycle. Without the lock the handle's sample waits up to a server
/// period before the server reads it and the force up to a device period before it is
/// rendered: 1-2 ms end to end at 1 kHz instead of ~1 ms.
pub fn next_deadline(prev: u64, server: Option<nanopush_proto::haptic::ForceFeedback>, step_ns: u64) -> u64 {
    let free = prev + step_ns;
    let Some(f) = server else { return free };
    let step = step_ns as i64;
    let want = ((f.time_ns + PHASE_LEAD_NS) % step_ns) as i64;
    let have = (free % step_ns) as i64;
    // The phase error wrapped to [−step/2, step/2).
    let err = (want - have + step + step / 2).rem_euclid(step) - step / 2;
    let nudge = (err / 4).clamp(-step / 10, step / 10);
    (free as i64 + nudge) as u64
}

/// Sleeps (then spins) until `deadline`. Returns whether the cycle started more than a period
/// late (an overrun), in which case the schedule starts again from now.
pub fn wait_for(sleeper: &spin_sleep::SpinSleeper, deadline: &mut u64, step_ns: u64) -> bool {
    let now = monotonic_ns();
    if *deadline > now {
        sleeper.sleep(Duration::from_nanos(*deadline - now));
    } else if now - *deadline > step_ns {
        *deadline = now;
        return true;
    }
    false
}

#[cfg(test)]
mod tests {
    use super::*;
    use nanopush_proto::haptic::ForceFeedback;

    /// The lock pulls the device cycle to 30 µs after the server's tick within a few dozen
    /// cycles, keeps the period within a tenth of itself, and never skips a cycle.
    #[test]
    fn the_cycle_locks_to_the_servers_tick_without_skipping() {
        let step = 1_000_000u64;
        // The server publishes at 0.6 ms past each millisecond (plus jitter).
        let server = |k: u64| ForceFeedback {
            time_ns: k * step + 600_000 + (k % 7) * 5_000,
            ..Default::default()
        };
        let mut d = 0u64;
        for k in 0..100u64 {
            let next = next_deadline(d, Some(server(k)), step);
            let period = next - d;
            assert!((900_000..=1_100_000).contains(&period), "period {period} at {k}");
            d = next;
        }
        let phase = d % step;
        assert!((600_000..700_000).contains(&phase), "phase {phase}");
        // Without a server, the free clock.
        assert_eq!(next_deadline(5, None, step), 5 + step);
    }

    /// docs/benchmarks.md, "Haptic latency (`nanopush-haptic-latency`)": "the device cycle locks 30 µs after the server's tick". A server
    /// publishing at 0.6 ms past each millisecond, without jitter: the cycle settles at 0.63 ms
    /// (to the nanosecond the quarter-step nudge leaves), at 1, 2 and 4 kHz.
    #[test]
    fn the_cycle_settles_the_phase_lead_after_the_servers_tick() {
        assert_eq!(PHASE_LEAD_NS, 30_000);
        for step in [1_000_000u64, 500_000, 250_000] {
            let server = |k: u64| ForceFeedback {
                time_ns: k * 1_000_000 + 600_000,
                ..Default::default()
            };
            let mut d = 123_456u64;
            for k in 0..200u64 {
                d = next_deadline(d, Some(server(k * step / 1_000_000)), step);
            }
            let phase = (d % step) as i64;
            let want = ((600_000 + PHASE_LEAD_NS) % step) as i64;
            assert!(
                (phase - want).abs() < 10,
                "phase {phase} ns at a {step} ns cycle, want {want}"
            );
        }
    }
}
