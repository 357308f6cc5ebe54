//! The control loop's iceoryx2 ports to the bridge, the link's states and what makes a handle
//! sample believable.

use nanopush_proto::haptic::{
    ForceFeedback, HapticState, IpcNode, SERVER_NODE_NAME, force_service, ipc_node, is_publisher_taken, state_service,
};

type Ipc = iceoryx2::service::ipc::Service;

/// The default link time-out (ms, `--haptic-timeout-ms`): a silent bridge is declared down
/// within this long of its last sample.
pub const DEFAULT_TIMEOUT_MS: f64 = 5.0;

/// The age of the newest sample — since the bridge read the handle, on the clock both
/// processes share — at which a loop ticking every `tick` seconds declares the link down (ns):
/// the tick that first sees `timeout − tick` is at most one tick later, within the time-out.
pub fn down_after_ns(timeout: std::time::Duration, tick: f64) -> u64 {
    ((timeout.as_secs_f64() - tick).max(tick) * 1e9) as u64
}
/// Largest handle position a bridge may report (m): beyond it a sample is rejected.
pub const MAX_HANDLE_M: f64 = 0.5;
/// Largest device force limit a bridge may report (N).
pub const MAX_DEVICE_FORCE_N: f64 = 50.0;
/// Largest stiffness a bridge may say its device renders (N/m): the renderable region is
/// computed from it (a serial device's info packet has the same bound).
pub const MAX_DEVICE_STIFFNESS: f64 = 100_000.0;
/// Largest rate a device's limits may be declared for (Hz).
pub const MAX_SPEC_RATE_HZ: f64 = 20_000.0;

/// Link state codes in [`super::HapticMetrics::link`].
pub const LINK_OFF: u64 = 0;
/// No sample within the time-out.
pub const LINK_DOWN: u64 = 1;
/// Samples arrive.
pub const LINK_UP: u64 = 2;

/// Whether a sample from a bridge can be believed: finite, the handle within ±0.5 m, a device
/// force limit in (0, 50] N, a declared stiffness in (0, 100] kN/m at a rate in (0, 20] kHz,
/// a finite passivity damper and cap.
pub fn believable(s: &HapticState) -> bool {
    let within = |v: f64, hi: f64| v.is_finite() && v > 0.0 && v <= hi;
    within(s.max_stiffness, MAX_DEVICE_STIFFNESS)
        && within(s.spec_rate_hz, MAX_SPEC_RATE_HZ)
        && s.pc_damping.is_finite()
        && s.pc_cap.is_finite()
        && s.position.is_finite()
        && s.velocity.is_finite()
        && s.position.abs() <= MAX_HANDLE_M
        && s.max_force.is_finite()
        && s.max_force > 0.0
        && s.max_force <= MAX_DEVICE_FORCE_N
        && s.force.is_finite()
}

/// The control loop's two ports.
pub struct ServerLink {
    _node: IpcNode,
    publisher: iceoryx2::port::publisher::Publisher<Ipc, ForceFeedback, ()>,
    subscriber: iceoryx2::port::subscriber::Subscriber<Ipc, HapticState, ()>,
}

/// Why the server's end of the link could not be opened.
#[derive(Debug, thiserror::Error)]
pub enum LinkError {
    /// Another server publishes forces on this machine.
    #[error("another nanopush serve holds the haptic link on this machine (the force service has its one publisher)")]
    ServerLive,
    /// iceoryx2 failed.
    #[error("haptic link (iceoryx2): {0}")]
    Ipc(String),
}

impl ServerLink {
    /// Opens the server's node and ports.
    pub fn open() -> Result<ServerLink, LinkError> {
        let node = ipc_node(SERVER_NODE_NAME).map_err(|e| LinkError::Ipc(e.0))?;
        let force = force_service(&node).map_err(|e| LinkError::Ipc(e.0))?;
        let state = state_service(&node).map_err(|e| LinkError::Ipc(e.0))?;
        let publisher = match force.publisher_builder().create() {
            Ok(p) => p,
            Err(e) if is_publisher_taken(&e) => return Err(LinkError::ServerLive),
            Err(e) => return Err(LinkError::Ipc(format!("{e:?}"))),
        };
        let subscriber = state
            .subscriber_builder()
            .create()
            .map_err(|e| LinkError::Ipc(format!("{e:?}")))?;
        Ok(ServerLink {
            _node: node,
            publisher,
            subscriber,
        })
    }

    /// Publishes a force sample (a failed loan or send is dropped: the next tick sends anew).
    pub fn publish(&self, f: ForceFeedback) {
        if let Ok(sample) = self.publisher.loan_uninit() {
            let _ = sample.write_payload(f).send();
        }
    }

    /// Drains the subscriber; the newest sample and how many arrived.
    pub fn newest(&self) -> (Option<HapticState>, u32) {
        let (mut last, mut n) = (None, 0);
        while let Ok(Some(s)) = self.subscriber.receive() {
            last = Some(*s);
            n += 1;
        }
        (last, n)
    }
}

#[cfg(test)]
mod tests {
    use std::time::Duration;

    use super::*;
    #[test]
    fn samples_that_cannot_be_believed_are_rejected() {
        let good = HapticState {
            position: 0.01,
            max_force: 2.5,
            max_stiffness: 2000.0,
            spec_rate_hz: 1000.0,
            ..Default::default()
        };
        assert!(believable(&good));
        for bad in [
            HapticState {
                position: f64::NAN,
                ..good
            },
            HapticState {
                velocity: f64::INFINITY,
                ..good
            },
            HapticState { position: 1.0, ..good },
            HapticState { max_force: 0.0, ..good },
            HapticState { max_force: 1e6, ..good },
            HapticState {
                max_stiffness: 0.0,
                ..good
            },
            HapticState {
                max_stiffness: 1e9,
                ..good
            },
            HapticState {
                spec_rate_hz: f64::NAN,
                ..good
            },
            HapticState {
                pc_cap: f64::INFINITY,
                ..good
            },
            HapticState {
                force: f64::NAN,
                ..good
            },
        ] {
            assert!(!believable(&bad), "{bad:?}");
        }
    }

    #[test]
    fn the_down_threshold_keeps_detection_within_the_time_out() {
        assert_eq!(down_after_ns(Duration::from_millis(5), 1e-3), 4_000_000);
        assert_eq!(down_after_ns(Duration::from_millis(100), 1e-3), 99_000_000);
        // Never below a tick (a link is not down between two samples).
        assert_eq!(down_after_ns(Duration::from_micros(100), 1e-3), 1_000_000);
    }
}
