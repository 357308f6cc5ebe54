//! SIGINT and SIGTERM end the run: the handler raises a flag the loops read.

use std::sync::atomic::{AtomicBool, Ordering};

static STOP: AtomicBool = AtomicBool::new(false);

extern "C" fn on_signal(_: libc::c_int) {
    STOP.store(true, Ordering::SeqCst);
}

/// SIGINT and SIGTERM end the loop (the force is zeroed before the process exits). The bridge's
/// iceoryx2 node installs no handlers of its own (`SignalHandlingMode::Disabled`).
pub fn catch_signals() {
    // SAFETY: the handler only stores to an atomic, which is async-signal-safe.
    unsafe {
        libc::signal(libc::SIGINT, on_signal as *const () as libc::sighandler_t);
        libc::signal(libc::SIGTERM, on_signal as *const () as libc::sighandler_t);
    }
}

/// Whether SIGINT or SIGTERM came.
pub fn stopped() -> bool {
    STOP.load(Ordering::SeqCst)
}
