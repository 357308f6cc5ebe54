//! The control lease: one operator at a time commands the instrument. Taken with `take_lease`,
//! given back with `release_lease`, or lost with the connection (which also stops what the
//! holder commanded). Haptic z-control ends whenever the lease is freed. Every change is
//! broadcast as a `lease` event.

use std::sync::atomic::Ordering::Relaxed;

use nanopush_proto::ws::{ErrorCode, Role, ServerMessage};

use super::Client;
use crate::app_state::AppState;
use crate::command_checks::Refusal;
use crate::control_loop::{LoopCommand, StopReason};
use crate::haptic::HapticCommand;

/// A command that changes the instrument needs an operator holding the lease, and a server
/// that is not shutting down.
pub(super) fn require_lease(st: &AppState, c: &Client) -> Result<(), Refusal> {
    if c.role != Role::Operator {
        return Err(Refusal::new(
            ErrorCode::Forbidden,
            "viewers cannot command; connect with the operator token",
        ));
    }
    if st.lease_holder() != Some(c.id) {
        return Err(Refusal::new(
            ErrorCode::NoLease,
            "this command needs the control lease: send take_lease first",
        ));
    }
    if st.activity.stopping.load(Relaxed) || *st.channels.shutdown.borrow() {
        return Err(Refusal::new(ErrorCode::ShuttingDown, "the server is shutting down"));
    }
    Ok(())
}

/// `take_lease`: an operator takes a free lease (taking it again is fine); a held one is
/// refused with its holder.
pub(super) fn take(st: &AppState, c: &Client) -> Result<(), Refusal> {
    if c.role != Role::Operator {
        return Err(Refusal::new(
            ErrorCode::Forbidden,
            "viewers cannot take the lease; connect with the operator token",
        ));
    }
    let mut lease = st.clients.lease.lock().expect("lease lock");
    match *lease {
        Some(h) if h == c.id => Ok(()),
        Some(h) => Err(Refusal::new(
            ErrorCode::LeaseHeld,
            match st.auth.name_of(h) {
                Some(name) => format!("{name} (client {h}) holds the lease"),
                None => format!("client {h} holds the lease"),
            },
        )),
        None => {
            *lease = Some(c.id);
            drop(lease);
            st.broadcast_event(&ServerMessage::Lease {
                holder: Some(c.id),
                holder_name: Some(c.person.name.clone()),
                reason: None,
            });
            Ok(())
        }
    }
}

/// `release_lease`: only its holder gives it back.
pub(super) fn release(st: &AppState, c: &Client) -> Result<(), Refusal> {
    let mut lease = st.clients.lease.lock().expect("lease lock");
    if *lease != Some(c.id) {
        return Err(Refusal::new(ErrorCode::NoLease, "this client does not hold the lease"));
    }
    *lease = None;
    drop(lease);
    release_haptic(st);
    st.broadcast_event(&ServerMessage::Lease {
        holder: None,
        holder_name: None,
        reason: None,
    });
    Ok(())
}

/// The lease is free: haptic z-control, which only the holder commands, ends with it (the tip
/// parks, the handle is let go), so z-control is never `engaged` with no holder. Sent whatever
/// the phase (an `engage` still queued is undone too); releasing when off changes nothing.
/// `true` when z-control was on.
fn release_haptic(st: &AppState) -> bool {
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
/// watches a push or scan whose operator is gone, so it is stopped (the tip retracts); the push
/// ends in a `run_done` with outcome `stopped`, recorded like any other.
pub(super) fn on_disconnect(st: &AppState, id: u32) {
    let mut lease = st.clients.lease.lock().expect("lease lock");
    if *lease != Some(id) {
        return;
    }
    *lease = None;
    drop(lease);
    let pushing = st.shared.busy.load(Relaxed);
    let scanning = st.activity.scanning.load(Relaxed);
    if pushing || scanning {
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
    let what = match (pushing, scanning) {
        (true, _) => "; its push was stopped",
        (_, true) => "; its scan was stopped",
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
    use super::*;
    use crate::session::tests::{client, test_state};

    fn next_event(rx: &mut tokio::sync::broadcast::Receiver<axum::extract::ws::Utf8Bytes>) -> serde_json::Value {
        serde_json::from_str(rx.try_recv().expect("an event").as_str()).unwrap()
    }

    #[test]
    fn an_operator_takes_a_free_lease_and_everyone_is_told() {
        let st = test_state();
        let mut events = st.channels.events.subscribe();
        take(&st, &client(1, Role::Operator)).unwrap();
        assert_eq!(st.lease_holder(), Some(1));
        let e = next_event(&mut events);
        assert_eq!(e["type"], "lease");
        assert_eq!(e["holder"], 1);
        // Taking it again changes nothing and tells no one.
        take(&st, &client(1, Role::Operator)).unwrap();
        assert!(events.try_recv().is_err());
    }

    #[test]
    fn a_held_lease_is_refused_with_its_holder_and_viewers_never_get_it() {
        let st = test_state();
        take(&st, &client(1, Role::Operator)).unwrap();
        let r = take(&st, &client(2, Role::Operator)).unwrap_err();
        assert_eq!(r.code, ErrorCode::LeaseHeld);
        assert_eq!(r.message, "client 1 holds the lease");
        let v = take(&st, &client(3, Role::Viewer)).unwrap_err();
        assert_eq!(v.code, ErrorCode::Forbidden);
        assert_eq!(st.lease_holder(), Some(1));
    }

    #[test]
    fn only_the_holder_releases_and_commands() {
        let st = test_state();
        let (holder, other) = (client(1, Role::Operator), client(2, Role::Operator));
        take(&st, &holder).unwrap();
        assert_eq!(release(&st, &other).unwrap_err().code, ErrorCode::NoLease);
        assert_eq!(require_lease(&st, &other).unwrap_err().code, ErrorCode::NoLease);
        assert_eq!(
            require_lease(&st, &client(3, Role::Viewer)).unwrap_err().code,
            ErrorCode::Forbidden
        );
        require_lease(&st, &holder).unwrap();
        st.activity.stopping.store(true, Relaxed);
        assert_eq!(require_lease(&st, &holder).unwrap_err().code, ErrorCode::ShuttingDown);
        let mut events = st.channels.events.subscribe();
        release(&st, &holder).unwrap();
        assert_eq!(st.lease_holder(), None);
        assert!(next_event(&mut events)["holder"].is_null());
    }

    #[test]
    fn a_holder_that_disconnects_frees_the_lease_and_stops_its_push() {
        let st = test_state();
        take(&st, &client(1, Role::Operator)).unwrap();
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
