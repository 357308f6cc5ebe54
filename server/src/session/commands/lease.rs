//! `take_lease` and `release_lease`: the control lease taken by an operator and given back by its
//! holder, each change told to everyone (`lease`).

use std::sync::Arc;

use nanopush_proto::ws::{ClientMessage, ErrorCode, ServerMessage};

use super::{Accepted, Client};
use crate::app_state::AppState;
use crate::command_checks::Refusal;
use crate::session::lease::release_haptic;

/// `take_lease`, from an operator: a free lease is taken (taking it again is fine); a held one
/// is refused with its holder.
pub(super) fn take(st: &Arc<AppState>, c: &mut Client, _: ClientMessage) -> Result<Accepted, Refusal> {
    let mut lease = st.clients.lease.lock().expect("lease lock");
    match *lease {
        Some(h) if h == c.id => Ok(Accepted::PLAIN),
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
            // The holder's address gets room of its own among the connections (`conn_limit.rs`).
            st.conn_limits.lease_held(Some(c.addr));
            st.broadcast_event(&ServerMessage::Lease {
                holder: Some(c.id),
                holder_name: Some(c.person.name.clone()),
                reason: None,
            });
            Ok(Accepted::PLAIN)
        }
    }
}

/// The refusal of `release_lease` from a client that does not hold the lease.
pub(super) fn not_held() -> Refusal {
    Refusal::new(ErrorCode::NoLease, "this client does not hold the lease")
}

/// `release_lease`, from its holder (checked again under the lease's lock).
pub(super) fn release(st: &Arc<AppState>, c: &mut Client, _: ClientMessage) -> Result<Accepted, Refusal> {
    let mut lease = st.clients.lease.lock().expect("lease lock");
    if *lease != Some(c.id) {
        return Err(not_held());
    }
    *lease = None;
    drop(lease);
    st.conn_limits.lease_held(None);
    release_haptic(st);
    st.broadcast_event(&ServerMessage::Lease {
        holder: None,
        holder_name: None,
        reason: None,
    });
    Ok(Accepted::PLAIN)
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
    fn an_operator_takes_a_free_lease_and_everyone_is_told() {
        let st = test_state();
        let mut events = st.channels.events.subscribe();
        let mut op = client(1, Role::Operator);
        command(&st, &mut op, r#"{"type":"take_lease"}"#).unwrap();
        assert_eq!(st.lease_holder(), Some(1));
        let e = next_event(&mut events);
        assert_eq!(e["type"], "lease");
        assert_eq!(e["holder"], 1);
        // Taking it again changes nothing and tells no one.
        command(&st, &mut op, r#"{"type":"take_lease"}"#).unwrap();
        assert!(events.try_recv().is_err());
    }

    #[test]
    fn a_held_lease_is_refused_with_its_holder_and_viewers_never_get_it() {
        let st = test_state();
        let take = r#"{"type":"take_lease"}"#;
        command(&st, &mut client(1, Role::Operator), take).unwrap();
        let r = command(&st, &mut client(2, Role::Operator), take).unwrap_err();
        assert_eq!(r.code, ErrorCode::LeaseHeld);
        assert_eq!(r.message, "client 1 holds the lease");
        let v = command(&st, &mut client(3, Role::Viewer), take).unwrap_err();
        assert_eq!(v.code, ErrorCode::Forbidden);
        assert_eq!(st.lease_holder(), Some(1));
    }

    #[test]
    fn only_the_holder_gives_the_lease_back_and_everyone_is_told() {
        let st = test_state();
        let (mut holder, mut other) = (client(1, Role::Operator), client(2, Role::Operator));
        command(&st, &mut holder, r#"{"type":"take_lease"}"#).unwrap();
        let release = r#"{"type":"release_lease"}"#;
        assert_eq!(command(&st, &mut other, release).unwrap_err().code, ErrorCode::NoLease);
        assert_eq!(st.lease_holder(), Some(1));
        let mut events = st.channels.events.subscribe();
        command(&st, &mut holder, release).unwrap();
        assert_eq!(st.lease_holder(), None);
        assert!(next_event(&mut events)["holder"].is_null());
        assert_eq!(command(&st, &mut holder, release).unwrap_err(), not_held());
    }
}
