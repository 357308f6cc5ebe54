//! The link to the controller as the backend uses it: one call at a time on a connection that
//! is reopened when it fails (a call that only reads tried once more, unless the tip moves or
//! scans), and the recovery after a failure during a move or a scan: a new connection whose
//! first command is the withdraw.

use std::time::Duration;

use nanopush_instrument::afm::{Microscope, MicroscopeError};

use super::NanonisMicroscope;
use crate::client::Connection;

impl NanonisMicroscope {
    /// One call on the connection, reopening it first when it was lost.
    pub(super) fn call<T>(
        &mut self,
        name: &str,
        f: impl Fn(&mut Connection) -> Result<T, MicroscopeError>,
    ) -> Result<T, MicroscopeError> {
        let result = self.call_once(&f);
        // A connection left idle (the logger carries the readings) may have died with a
        // controller that restarted: a call that only reads is tried once more on a new one.
        // Never while the tip moves or scans: then the first command on a new link is the
        // withdraw.
        let busy = self.target.is_some() || self.scanning;
        match result {
            Err(MicroscopeError::Link { .. }) if name.ends_with("Get") && !busy => self.call_once(&f),
            other => other,
        }
    }

    fn call_once<T>(
        &mut self,
        f: &impl Fn(&mut Connection) -> Result<T, MicroscopeError>,
    ) -> Result<T, MicroscopeError> {
        if self.conn.is_none() {
            self.conn = Some(Connection::open(self.opts.addr, self.opts.timeout)?);
        }
        let conn = self.conn.as_mut().expect("opened above");
        let result = f(conn);
        if matches!(
            result,
            Err(MicroscopeError::Link { .. }) | Err(MicroscopeError::Controller { .. })
        ) {
            // A failed or mismatched reply leaves the connection's framing unknown.
            self.conn = None;
        }
        result
    }

    /// After an error during a move or a scan: reopen the link (a few tries) and withdraw on it
    /// before anything else, then return the error with what was done.
    pub fn recover(&mut self, error: MicroscopeError) -> MicroscopeError {
        self.target = None;
        if self.opts.read_only {
            return error;
        }
        let mut last = String::new();
        let mut tries = 0;
        for attempt in 0..self.opts.reconnect_tries.max(1) {
            // A stop or a shutdown waits for one try, not three.
            if attempt > 0 && self.cancelled() {
                break;
            }
            if attempt > 0 {
                std::thread::sleep(Duration::from_millis(200 * u64::from(attempt)));
            }
            tries += 1;
            self.conn = None;
            match self.withdraw() {
                Ok(()) => {
                    return annotate(error, "the tip was withdrawn");
                }
                Err(e) => last = e.to_string(),
            }
        }
        annotate(
            error,
            &format!("the tip could NOT be withdrawn after {tries} tries ({last}): withdraw it at the controller"),
        )
    }

    /// Whether a stop or a shutdown asked to end what runs.
    pub(crate) fn cancelled(&self) -> bool {
        self.cancel
            .as_ref()
            .is_some_and(|c| c.load(std::sync::atomic::Ordering::Relaxed))
    }
}

pub(super) fn annotate(error: MicroscopeError, note: &str) -> MicroscopeError {
    match error {
        MicroscopeError::Link { command, message } => MicroscopeError::Link {
            command,
            message: format!("{message}; {note}"),
        },
        MicroscopeError::Controller { command, message } => MicroscopeError::Controller {
            command,
            message: format!("{message}; {note}"),
        },
        other => MicroscopeError::Simulation(format!("{other}; {note}")),
    }
}
