//! The table of commands: each entry's name is its `type` on the wire, who may send what, what
//! the audit log keeps, the check of `haptic`'s fields, and what a `haptic` `scale` puts in force.

use std::sync::atomic::Ordering::Relaxed;

use nanopush_proto::ws::{ClientMessage, ErrorCode, HapticAction, Role, Stream};

use super::*;
use crate::app_state::{HapticScales, test_state};
use crate::command_checks::parse_command;
use crate::session::tests::{client, command};

/// One message of each command, each named by its position in the match of [`route`].
fn one_of_each() -> Vec<ClientMessage> {
    let messages = vec![
        ClientMessage::Ping { id: None },
        ClientMessage::Subscribe {
            id: None,
            streams: vec![Stream::Tip],
        },
        ClientMessage::TakeLease { id: None },
        ClientMessage::ReleaseLease { id: None },
        ClientMessage::Push {
            id: None,
            particle: 1,
            distance_um: Some(1.0),
            direction_deg: None,
            to_x_um: None,
            to_y_um: None,
            tolerance_nm: None,
        },
        ClientMessage::Scan {
            id: None,
            centre_x_um: None,
            centre_y_um: None,
            size_um: None,
            pixels: None,
        },
        ClientMessage::Stop { id: None },
        ClientMessage::Haptic {
            id: None,
            action: HapticAction::Release,
            nm_per_mm: None,
            pull_off_at_hand_n: None,
        },
    ];
    // Every command once: a command added to the protocol makes this match (and `route`'s)
    // incomplete until it is given a message here.
    let mut seen = [false; 8];
    for m in &messages {
        let k = match m {
            ClientMessage::Ping { .. } => 0,
            ClientMessage::Subscribe { .. } => 1,
            ClientMessage::TakeLease { .. } => 2,
            ClientMessage::ReleaseLease { .. } => 3,
            ClientMessage::Push { .. } => 4,
            ClientMessage::Scan { .. } => 5,
            ClientMessage::Stop { .. } => 6,
            ClientMessage::Haptic { .. } => 7,
        };
        seen[k] = true;
    }
    assert!(seen.iter().all(|s| *s), "a message of each command");
    messages
}

#[test]
fn each_command_is_named_as_its_type_on_the_wire() {
    for m in one_of_each() {
        let wire = serde_json::to_value(&m).unwrap();
        assert_eq!(route(&m).name, wire["type"], "{m:?}");
    }
}

#[test]
fn who_may_send_each_command() {
    let who = |m: &ClientMessage| route(m).who;
    let [ping, subscribe, take, release, push, scan, stop, haptic] = one_of_each().try_into().unwrap();
    assert_eq!((who(&ping), who(&subscribe)), (Who::Anyone, Who::Anyone));
    assert_eq!(who(&take), Who::Operator("take the lease"));
    assert_eq!(who(&release), Who::Holder);
    for m in [push, scan, stop, haptic] {
        assert_eq!(who(&m), Who::Commander, "{m:?}");
    }
}

#[test]
fn a_command_needs_an_operator_holding_the_lease_while_the_server_runs() {
    let st = test_state();
    let (mut holder, mut other, mut viewer) = (
        client(1, Role::Operator),
        client(2, Role::Operator),
        client(3, Role::Viewer),
    );
    command(&st, &mut holder, r#"{"type":"take_lease"}"#).unwrap();
    let stop = r#"{"type":"stop"}"#;
    let e = command(&st, &mut viewer, stop).unwrap_err();
    assert_eq!(
        e,
        Refusal::new(
            ErrorCode::Forbidden,
            "viewers cannot command; connect with the operator token"
        )
    );
    let e = command(&st, &mut viewer, r#"{"type":"take_lease"}"#).unwrap_err();
    assert_eq!(
        e.message,
        "viewers cannot take the lease; connect with the operator token"
    );
    let e = command(&st, &mut other, stop).unwrap_err();
    assert_eq!(
        e,
        Refusal::new(
            ErrorCode::NoLease,
            "this command needs the control lease: send take_lease first"
        )
    );
    assert_eq!(Who::Commander.check(&st, &holder), Ok(()));
    // Anyone may ping and subscribe.
    command(&st, &mut viewer, r#"{"type":"ping"}"#).unwrap();
    command(&st, &mut viewer, r#"{"type":"subscribe","streams":["scan"]}"#).unwrap();
    assert_eq!(st.clients.scan_subscribers.load(Relaxed), 1);
    // Shutting down: nothing more is commanded, but the holder may still give the lease back.
    st.activity.stopping.store(true, Relaxed);
    assert_eq!(
        command(&st, &mut holder, stop).unwrap_err().code,
        ErrorCode::ShuttingDown
    );
    command(&st, &mut holder, r#"{"type":"release_lease"}"#).unwrap();
    assert_eq!(st.lease_holder(), None);
}

#[test]
fn commands_that_change_the_instrument_are_audited_with_their_fields() {
    let push = parse_command(r#"{"type":"push","id":4,"particle":2,"distance_um":0.5,"direction_deg":90}"#).unwrap();
    let (name, args) = route(&push).audit_text(&push).unwrap();
    assert_eq!(name, "push");
    assert_eq!(
        serde_json::Value::Object(args),
        serde_json::json!({"id": 4, "particle": 2, "distance_um": 0.5, "direction_deg": 90.0})
    );
    for m in one_of_each() {
        let audited = route(&m).audit_text(&m).is_some();
        let changes_nothing = matches!(m, ClientMessage::Ping { .. } | ClientMessage::Subscribe { .. });
        assert_eq!(audited, !changes_nothing, "{m:?}");
    }
}

/// `haptic`'s scales go with `scale` only, and the check comes before anything else: a viewer
/// is told of the field too.
#[test]
fn a_field_of_another_action_is_refused_naming_it() {
    let m = parse_command(r#"{"type":"haptic","action":"recenter","nm_per_mm":-5}"#).unwrap();
    let e = haptic::fields_apply(&m).unwrap_err();
    assert_eq!(e.code, ErrorCode::Invalid);
    assert!(
        e.message.contains("nm_per_mm") && e.message.contains("\"recenter\""),
        "{}",
        e.message
    );
    let m = parse_command(r#"{"type":"haptic","action":"engage","pull_off_at_hand_n":1e300}"#).unwrap();
    assert!(
        haptic::fields_apply(&m)
            .unwrap_err()
            .message
            .contains("pull_off_at_hand_n")
    );
    let m = parse_command(r#"{"type":"haptic","action":"scale","nm_per_mm":5}"#).unwrap();
    assert_eq!(haptic::fields_apply(&m), Ok(()));
    let st = test_state();
    let e = command(
        &st,
        &mut client(1, Role::Viewer),
        r#"{"type":"haptic","action":"recenter","nm_per_mm":5}"#,
    )
    .unwrap_err();
    assert_eq!(e.code, ErrorCode::Invalid);
}

/// The haptic scales in force start at the scene's and follow each accepted `haptic scale` (a
/// refused one changes nothing): `/api/status` shows them, and the `ok` says them.
#[test]
fn the_haptic_scales_in_force_follow_accepted_scale_commands() {
    let st = test_state();
    let start = *st.haptic_scales.lock().unwrap();
    assert_eq!(start.nm_per_mm, st.scene.file.haptic.nm_per_mm);
    assert_eq!(start.pull_off_at_hand_n, st.scene.file.haptic.pull_off_at_hand_n);
    let mut c = client(1, Role::Operator);
    command(&st, &mut c, r#"{"type":"take_lease"}"#).unwrap();
    let ok = command(&st, &mut c, r#"{"type":"haptic","action":"scale","nm_per_mm":20}"#).unwrap();
    assert_eq!(ok.scales.map(|s| s.nm_per_mm), Some(20.0));
    assert_eq!(st.haptic_scales.lock().unwrap().nm_per_mm, 20.0);
    assert_eq!(
        st.haptic_scales.lock().unwrap().pull_off_at_hand_n,
        start.pull_off_at_hand_n
    );
    let refused = command(
        &st,
        &mut c,
        r#"{"type":"haptic","action":"scale","pull_off_at_hand_n":50}"#,
    );
    assert_eq!(refused.unwrap_err().code, ErrorCode::OutOfRange);
    command(
        &st,
        &mut c,
        r#"{"type":"haptic","action":"scale","pull_off_at_hand_n":2.5}"#,
    )
    .unwrap();
    assert_eq!(
        *st.haptic_scales.lock().unwrap(),
        HapticScales {
            nm_per_mm: 20.0,
            pull_off_at_hand_n: 2.5
        }
    );
    // Another action's `ok` says no scales.
    let ok = command(&st, &mut c, r#"{"type":"haptic","action":"release"}"#).unwrap();
    assert_eq!(ok, Accepted::PLAIN);
}

/// The protocol's table of commands (`proto/src/ws/client.rs`) lists each command of this table
/// once, and says who may send it as this table does.
#[test]
fn the_protocol_documents_each_command_and_who_may_send_it() {
    let doc = include_str!("../../../../proto/src/ws/client.rs");
    let mut documented = std::collections::BTreeMap::new();
    for row in doc.lines().filter_map(|l| l.strip_prefix("//! | `")) {
        let cells: Vec<&str> = row.split(" | ").collect();
        let name = cells[0].trim_end_matches('`');
        assert!(documented.insert(name, cells[2]).is_none(), "{name} twice");
    }
    let commands = one_of_each();
    assert_eq!(documented.len(), commands.len(), "{documented:?}");
    for m in commands {
        let entry = route(&m);
        let needs = documented
            .get(entry.name)
            .unwrap_or_else(|| panic!("{} documented", entry.name));
        let says = match entry.who {
            Who::Anyone => "—",
            Who::Operator(_) => "operator",
            Who::Holder | Who::Commander => "the lease",
        };
        assert!(needs.starts_with(says), "{}: needs {needs:?}, not {says:?}", entry.name);
    }
}
