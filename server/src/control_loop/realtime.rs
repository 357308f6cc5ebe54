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
    let cpu = nanopush_rt::resolve_core(cpu);
    let core = match nanopush_rt::pin_to_core(Some(cpu)) {
        Ok(core) => {
            tracing::info!("control loop: pinned to core {core}");
            Some(core)
        }
        Err(e) => {
            tracing::warn!("control loop: CPU affinity to core {cpu} refused ({e}); running unpinned");
            None
        }
    };
    let fifo = match nanopush_rt::sched_fifo(LOOP_PRIORITY) {
        Ok(()) => {
            tracing::info!("control loop: SCHED_FIFO priority {LOOP_PRIORITY}");
            true
        }
        Err(e) => {
            tracing::warn!("control loop: SCHED_FIFO refused ({e}); running SCHED_OTHER with spin-sleep only");
            false
        }
    };
    Granted { fifo, core }
}
