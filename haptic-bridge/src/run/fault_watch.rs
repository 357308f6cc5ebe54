//! The device's and the bridge's faults, said at most once a second, each by its side.

use std::sync::mpsc;

use nanopush_haptic::device::DeviceFaults;
use nanopush_proto::haptic::monotonic_ns;

/// Says, at most once a second, which faults were counted since the last time, by side.
pub struct FaultWatch {
    last: DeviceFaults,
    next_ns: u64,
}

impl FaultWatch {
    pub fn new(now: DeviceFaults) -> FaultWatch {
        FaultWatch {
            last: now,
            next_ns: monotonic_ns() + 1_000_000_000,
        }
    }

    pub fn every_second(&mut self, now_ns: u64, f: DeviceFaults, why: Option<&str>, log: &mpsc::SyncSender<String>) {
        if now_ns < self.next_ns {
            return;
        }
        self.next_ns = now_ns + 1_000_000_000;
        let d = |a: u64, b: u64| a.saturating_sub(b);
        let l = self.last;
        let device = [
            (d(f.bad_packets, l.bad_packets), "bad packets"),
            (d(f.timeouts, l.timeouts), "late answers (the device overran)"),
            (d(f.seq_gaps, l.seq_gaps), "sequence gaps"),
            (d(f.out_of_range, l.out_of_range), "states out of range"),
        ];
        let said: Vec<String> = device
            .iter()
            .filter(|(n, _)| *n > 0)
            .map(|(n, what)| format!("{n} {what}"))
            .collect();
        if !said.is_empty() {
            let reason = why.map(|w| format!("; the latest: {w}")).unwrap_or_default();
            let _ = log.try_send(format!(
                "nanopush-haptic: device fault: {} in the last second{reason}",
                said.join(", ")
            ));
        }
        let trips = d(f.watchdog_trips, l.watchdog_trips);
        let overruns = d(f.overruns, l.overruns);
        if overruns > 0 {
            let _ = log.try_send(format!(
                "nanopush-haptic: bridge fault: {overruns} late cycles in the last second"
            ));
        }
        if trips > 0 {
            let _ = log.try_send(format!(
                "nanopush-haptic: bridge fault: the device's watchdog zeroed its force {trips} times in the last second (it heard no valid packet for {} ms: the bridge stalled or packets were lost on the line); the force ramps in again",
                nanopush_haptic::serial::DEVICE_SILENCE_MS
            ));
        }
        self.last = f;
    }
}
