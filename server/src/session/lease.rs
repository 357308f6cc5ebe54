//! The control lease: one operator at a time commands the instrument. Taken with `take_lease`,
//! given back with `release_lease` (their handlers: `commands/lease.rs`), or lost with the
//! connection, which also stops what the holder commanded. Haptic z-control ends whenever the
//! lease is freed. Every change is broadcast as a `lease` event.

use std::sync::atomic::Ordering::Relaxed;

use nanopush_proto::ws::ServerMessage;

use crate::app_state::AppState;
use crate::control_loop::{LoopCommand, StopReason};
use crate::haptic::HapticCommand;

/// The lease is free: haptic z-control, which only the holder commands, ends with it (the tip
/// parks, the handle is let go), so z-control is never `engaged` with no holder. Sent whatever
/// the phase (an `engage` still queued is undone too); releasing when off changes nothing.
/// `true` when z-control was on.
pub(super) fn release_haptic(st: &AppState) -> bool {
    let h = &st.shared.metrics.haptic;
    if !h.enabled.load(Relaxed) {
        return false;
    }
    let on = h.phase_name() != "off";
    // A full queue is counted by `command`.
    let _ = st.shared.command(LoopCommand::Haptic(HapticCommand::Release));
    on
}

/// Client `id` disconnected: the lease goes with it, and so does what it commanded. Nobody
/// watches a push, scan or assembly whose operator is gone, so it is stopped (the tip
/// retracts); the push ends in a `run_done` with outcome `stopped`, recorded like any other, an
/// assembly in an `assembly_done` `stopped`, recorded.
pub(super) fn on_disconnect(st: &AppState, id: u32) {
    let mut lease = st.clients.lease.lock().expect("lease lock");
    if *lease != Some(id) {
        return;
    }
    *lease = None;
    drop(lease);
    // Its address keeps its room among the connections a while, for the reconnect.
    st.conn_limits.lease_held(None);
    let pushing = st.shared.busy.load(Relaxed);
    let scanning = st.activity.scanning.load(Relaxed);
    let assembling = st.activity.assembling.load(Relaxed);
    if pushing || scanning || assembling {
        st.activity.scan_cancel.store(true, Relaxed);
        st.activity.generation.fetch_add(1, Relaxed);
        if pushing {
            // A full queue is counted by `command`; the push then ends on its own.
            let _ = st.shared.command(LoopCommand::Stop(StopReason::HolderDisconnected));
        }
    }
    let haptic = if release_haptic(st) {
        "; its haptic z-control was released"
    } else {
        ""
    };
    let what = match (assembling, pushing, scanning) {
        (true, _, _) => "; its assembly was stopped",
        (_, true, _) => "; its push was stopped",
        (_, _, true) => "; its scan was stopped",
        _ => "",
    };
    let what = format!("{what}{haptic}");
    tracing::info!("client {id} held the lease and disconnected{what}");
    st.broadcast_event(&ServerMessage::Lease {
        holder: None,
        holder_name: None,
        reason: Some(format!("client {id}, which held the lease, disconnected{what}")),
    });
}

#[cfg(test)]
mod tests {
    use nanopush_proto::ws::Role;

    use super::*;
    use crate::app_state::test_state;
    use crate::session::tests::{client, command};

    fn next_event(rx: &mut tokio::sync::broadcast::Receiver<axum::extract::ws::Utf8Bytes>) -> serde_json::Value {
        serde_json::from_str(rx.try_recv().expect("an event").as_str()).unwrap()
    }

    #[test]
    fn a_holder_that_disconnects_frees_the_lease_and_stops_its_push() {
        let st = test_state();
        command(&st, &mut client(1, Role::Operator), r#"{"type":"take_lease"}"#).unwrap();
        st.shared.busy.store(true, Relaxed);
        let mut events = st.channels.events.subscribe();
        let generation = st.activity.generation.load(Relaxed);
        on_disconnect(&st, 2);
        assert_eq!(
            st.lease_holder(),
            Some(1),
            "another client's disconnect changes nothing"
        );
        assert!(events.try_recv().is_err());
        on_disconnect(&st, 1);
        assert_eq!(st.lease_holder(), None);
        assert_eq!(
            st.activity.generation.load(Relaxed),
            generation + 1,
            "a push being prepared is dropped"
        );
        assert!(st.activity.scan_cancel.load(Relaxed));
        assert!(matches!(
            st.shared.commands.pop(),
            Some(LoopCommand::Stop(StopReason::HolderDisconnected))
        ));
        let e = next_event(&mut events);
        assert!(e["holder"].is_null());
        assert_eq!(
            e["reason"],
            "client 1, which held the lease, disconnected; its push was stopped"
        );
    }
}
