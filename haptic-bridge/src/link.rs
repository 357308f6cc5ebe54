//! The bridge's end of the iceoryx2 haptic link: publishes [`HapticState`] on
//! `nanopush/haptic/state`, subscribes to [`ForceFeedback`] on `nanopush/haptic/force`.
//!
//! The node is built with the configuration in code (`nanopush_proto::haptic::ipc_config`: no config-file search, no
//! warning), leaves signals to the process, and removes the resources of dead nodes when it is
//! created (a bridge or server killed with SIGKILL). The state service allows one publisher: a
//! second bridge while one is live is refused with [`LinkError::BridgeLive`].

use nanopush_proto::haptic::{
    BRIDGE_NODE_NAME, ForceFeedback, HapticState, IpcNode, force_service, ipc_node, is_publisher_taken, state_service,
};

use crate::bridge::Link;

type Ipc = iceoryx2::service::ipc::Service;

/// Why the link could not be opened.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum LinkError {
    /// Another bridge publishes the handle's state.
    #[error(
        "another nanopush-haptic is live on this machine (the haptic state service has its one \
         publisher); stop it first"
    )]
    BridgeLive,
    /// iceoryx2 failed.
    #[error("haptic link (iceoryx2): {0}")]
    Ipc(String),
}

/// The bridge's ports.
pub struct IpcLink {
    _node: IpcNode,
    publisher: iceoryx2::port::publisher::Publisher<Ipc, HapticState, ()>,
    subscriber: iceoryx2::port::subscriber::Subscriber<Ipc, ForceFeedback, ()>,
    /// Samples the link failed to send.
    pub send_failures: u64,
}

impl IpcLink {
    /// Opens the bridge's node and ports.
    pub fn open() -> Result<IpcLink, LinkError> {
        let ipc = |e: &dyn std::fmt::Debug| LinkError::Ipc(format!("{e:?}"));
        let node = ipc_node(BRIDGE_NODE_NAME).map_err(|e| LinkError::Ipc(e.0))?;
        let state = state_service(&node).map_err(|e| LinkError::Ipc(e.0))?;
        let force = force_service(&node).map_err(|e| LinkError::Ipc(e.0))?;
        let publisher = match state.publisher_builder().create() {
            Ok(p) => p,
            Err(e) if is_publisher_taken(&e) => return Err(LinkError::BridgeLive),
            Err(e) => return Err(ipc(&e)),
        };
        let subscriber = force.subscriber_builder().create().map_err(|e| ipc(&e))?;
        Ok(IpcLink {
            _node: node,
            publisher,
            subscriber,
            send_failures: 0,
        })
    }
}

impl Link for IpcLink {
    fn publish(&mut self, state: &HapticState) {
        let sent = match self.publisher.loan_uninit() {
            Ok(sample) => sample.write_payload(*state).send().is_ok(),
            Err(_) => false,
        };
        if !sent {
            self.send_failures += 1;
        }
    }

    fn newest(&mut self) -> Option<ForceFeedback> {
        let mut last = None;
        while let Ok(Some(s)) = self.subscriber.receive() {
            last = Some(*s);
        }
        last
    }
}
