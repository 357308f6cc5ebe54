//! What the control loop asks of the operating system to keep its ticks on time: SCHED_FIFO
//! priority and a core of its own (and, in [`super::no_halt`], a core that does not halt
//! between ticks).

/// The control loop's SCHED_FIFO priority, when the system grants it (the bridge's device loop
/// runs at 45, below it).
pub const LOOP_PRIORITY: i32 = 50;

/// What the system granted the calling thread.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Granted {
    /// SCHED_FIFO at [`LOOP_PRIORITY`].
    pub fifo: bool,
    /// The core it is pinned to.
    pub core: Option<usize>,
}

/// Asks for SCHED_FIFO priority [`LOOP_PRIORITY`] and pins the calling thread to `cpu` (the last
/// core when `None`); logs what was granted.
pub fn make_realtime(cpu: Option<usize>) -> Granted {
    // SAFETY: plain libc calls on the calling thread with valid, initialized arguments.
    unsafe {
        let ncpu = libc::sysconf(libc::_SC_NPROCESSORS_ONLN).max(1) as usize;
        let cpu = cpu.unwrap_or(ncpu - 1).min(ncpu - 1);
        let mut set: libc::cpu_set_t = std::mem::zeroed();
        libc::CPU_SET(cpu, &mut set);
        let core = if libc::sched_setaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &set) != 0 {
            tracing::warn!(
                "control loop: CPU affinity to core {cpu} refused ({}); running unpinned",
                std::io::Error::last_os_error()
            );
            None
        } else {
            tracing::info!("control loop: pinned to core {cpu}");
            Some(cpu)
        };
        let param = libc::sched_param {
            sched_priority: LOOP_PRIORITY,
        };
        let fifo = if libc::pthread_setschedparam(libc::pthread_self(), libc::SCHED_FIFO, &param) != 0 {
            tracing::warn!(
                "control loop: SCHED_FIFO refused ({}); running SCHED_OTHER with spin-sleep only",
                std::io::Error::last_os_error()
            );
            false
        } else {
            tracing::info!("control loop: SCHED_FIFO priority {LOOP_PRIORITY}");
            true
        };
        Granted { fifo, core }
    }
}
