//! What the control loop asks of the operating system to keep its ticks on time: SCHED_FIFO
//! priority, its own core, and a core that does not halt between ticks.
//!
//! Why the last one (issue 12's soak, traced with ftrace on the loop's core of the 2-vCPU VM):
//! between two ticks the loop sleeps about 0.9 ms and its core has nothing else to run, so the
//! kernel halts it (`HLT`, the `haltpoll idle` state). A halted virtual CPU runs again when the
//! hypervisor delivers its timer interrupt, and with the other core busy that came late: of the 40
//! overruns of a 180 s soak (3 minutes loaded, 2 idle), 26 were a core that nothing ran on while
//! its timer came 1.2-13 ms after the loop went to sleep. With the loop's core polling instead
//! (the `POLL` state: the core spins in the kernel, checking for work), the same soak had 8
//! overruns in all, one of that kind; the rest were the virtual CPU stopped by the host while it ran, which no setting in
//! the guest changes. On bare metal the same request keeps the cores out of deep C-states, whose
//! exit latency (tens to hundreds of µs) would otherwise come on top of a tick's wake-up.
//!
//! The request is the kernel's CPU latency QoS (`Documentation/power/pm_qos_interface.rst`): a
//! zero written to `/dev/cpu_dma_latency`, held as long as the file stays open, as `cyclictest`
//! does. The kernel drops it when the file is closed, also when the process is killed: nothing
//! is left to restore after a crash. The price: while the server runs, idle cores poll instead of
//! resting (power and heat on a lab PC, a busy virtual CPU for a hypervisor).

use std::io::Write as _;

/// The control loop's SCHED_FIFO priority, when the system grants it (the bridge's device loop
/// runs at 45, below it).
pub const LOOP_PRIORITY: i32 = 50;

/// The kernel's CPU latency QoS device.
pub const CPU_LATENCY_DEVICE: &str = "/dev/cpu_dma_latency";

/// Asks for SCHED_FIFO priority [`LOOP_PRIORITY`] and pins the calling thread to `cpu` (the last
/// core when `None`); logs what was granted. True when SCHED_FIFO was granted.
pub fn make_realtime(cpu: Option<usize>) -> bool {
    // SAFETY: plain libc calls on the calling thread with valid, initialized arguments.
    unsafe {
        let ncpu = libc::sysconf(libc::_SC_NPROCESSORS_ONLN).max(1) as usize;
        let cpu = cpu.unwrap_or(ncpu - 1).min(ncpu - 1);
        let mut set: libc::cpu_set_t = std::mem::zeroed();
        libc::CPU_SET(cpu, &mut set);
        if libc::sched_setaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &set) != 0 {
            tracing::warn!(
                "control loop: CPU affinity to core {cpu} refused ({}); running unpinned",
                std::io::Error::last_os_error()
            );
        } else {
            tracing::info!("control loop: pinned to core {cpu}");
        }
        let param = libc::sched_param {
            sched_priority: LOOP_PRIORITY,
        };
        if libc::pthread_setschedparam(libc::pthread_self(), libc::SCHED_FIFO, &param) != 0 {
            tracing::warn!(
                "control loop: SCHED_FIFO refused ({}); running SCHED_OTHER with spin-sleep only",
                std::io::Error::last_os_error()
            );
            false
        } else {
            tracing::info!("control loop: SCHED_FIFO priority {LOOP_PRIORITY}");
            true
        }
    }
}

/// A held request for zero CPU wake-up latency: while it lives, the cpuidle governor lets idle
/// cores use only their polling state, never a halt (see the module docs). Dropping it (or the
/// process ending in any way) withdraws the request.
#[derive(Debug)]
pub struct NoHalt {
    _device: std::fs::File,
}

impl NoHalt {
    /// Opens [`CPU_LATENCY_DEVICE`] and asks for 0 µs. Fails where the device is missing (a
    /// kernel without PM QoS, a container) or not writable (it is root's alone).
    pub fn request() -> std::io::Result<NoHalt> {
        let mut device = std::fs::OpenOptions::new().write(true).open(CPU_LATENCY_DEVICE)?;
        // The value is a native-endian s32 in µs (a 4-byte write; text is taken too).
        device.write_all(&0i32.to_ne_bytes())?;
        Ok(NoHalt { _device: device })
    }

    /// The latency the kernel enforces now (µs): the least of every holder's request, or its
    /// default (2 000 000 000) when nobody holds one.
    pub fn current_us() -> std::io::Result<i32> {
        let b = std::fs::read(CPU_LATENCY_DEVICE)?;
        let b: [u8; 4] = b.get(..4).and_then(|s| s.try_into().ok()).ok_or_else(|| {
            std::io::Error::new(
                std::io::ErrorKind::InvalidData,
                format!("{CPU_LATENCY_DEVICE} read {} bytes", b.len()),
            )
        })?;
        Ok(i32::from_ne_bytes(b))
    }
}

/// Does this process hold [`CPU_LATENCY_DEVICE`] open (one of its file descriptors)?
pub fn holds_cpu_latency_device(pid: u32) -> bool {
    std::fs::read_dir(format!("/proc/{pid}/fd")).is_ok_and(|fds| {
        fds.flatten()
            .any(|fd| std::fs::read_link(fd.path()).is_ok_and(|p| p.as_os_str() == CPU_LATENCY_DEVICE))
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_held_request_sets_zero_latency_and_is_withdrawn_with_the_file() {
        let me = std::process::id();
        let held = match NoHalt::request() {
            Ok(h) => h,
            Err(e) => {
                // Not root, or no PM QoS: the server logs the same and goes on.
                eprintln!("{CPU_LATENCY_DEVICE} not available here ({e}): nothing to check");
                assert!(!holds_cpu_latency_device(me));
                return;
            }
        };
        assert!(holds_cpu_latency_device(me));
        // Others (a server started by another test) may hold a request too, never a lower one.
        assert_eq!(NoHalt::current_us().unwrap(), 0);
        drop(held);
        assert!(!holds_cpu_latency_device(me), "the file is closed with the request");
    }

    #[test]
    fn a_process_that_never_asked_does_not_hold_the_device() {
        let mut child = std::process::Command::new("sleep").arg("5").spawn().unwrap();
        assert!(!holds_cpu_latency_device(child.id()));
        let _ = child.kill();
        let _ = child.wait();
    }
}
