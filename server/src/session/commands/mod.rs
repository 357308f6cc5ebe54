//! Every WebSocket command in one table, [`route`], as axum's `Router` lists every route: each
//! command's name on the wire, who may send it ([`Who`]), the check of its fields that comes
//! before anything else, what the audit log keeps of it ([`Audit`]), and its handler. The
//! receive loop (`receive.rs`) looks a command up here, runs it with [`Command::run`] (the check,
//! then who, then the handler) and hands the audit log [`Command::audit_text`].
//!
//! # How to add a command
//!
//! 1. **The protocol type**: its variant of `ClientMessage`, with its row in the table of
//!    commands, in `proto/src/ws/client.rs`.
//! 2. **This table**: its entry in [`route`], and a message of it in this file's tests (both
//!    matches are exhaustive: the compiler asks for them), which check its name against its
//!    `type` and who may send it against the protocol's table.
//! 3. **Its handler**: a file of this directory with a [`Handler`], which checks what depends on
//!    the instrument's state (a value out of range is refused naming the field and the allowed
//!    range: `command_checks::number`) and carries the command out.
//! 4. **The page**: its builder in `web/src/wire.js` (`commands`).
//!
//! (A command the control loop carries out in a way it does not know yet also needs its
//! `LoopCommand`, in `control_loop`.)

mod ack;
mod assemble;
mod haptic;
mod instrument;
mod lease;
mod push;
mod scan;
mod stop;
mod subscribe;

use std::sync::Arc;

use nanopush_proto::ws::{ClientMessage, ErrorCode, HapticScales, Role};

use super::Client;
use crate::app_state::AppState;
use crate::command_checks::Refusal;

pub(super) use subscribe::counter;

/// The entry of `msg`'s command.
pub(super) fn route(msg: &ClientMessage) -> Command {
    use Audit::{Fields, Nothing};
    use ClientMessage as M;
    use Who::{Anyone, Commander, Holder, Operator};
    match msg {
        M::Ping { .. } => Command::new("ping", Anyone, Nothing, ping),
        M::Subscribe { .. } => Command::new("subscribe", Anyone, Nothing, subscribe::run),
        M::TakeLease { .. } => Command::new("take_lease", Operator("take the lease"), Fields, lease::take),
        M::ReleaseLease { .. } => Command::new("release_lease", Holder, Fields, lease::release),
        M::Push { .. } => Command::new("push", Commander, Fields, push::run),
        M::Scan { .. } => Command::new("scan", Commander, Fields, scan::run),
        M::Assemble { .. } => {
            Command::new("assemble", Commander, Fields, assemble::run).checked(assemble::fields_agree)
        }
        M::Stop { .. } => Command::new("stop", Commander, Fields, stop::run),
        M::Haptic { .. } => Command::new("haptic", Commander, Fields, haptic::run).checked(haptic::fields_apply),
        M::Ack { .. } => Command::new("ack", Anyone, Nothing, ack::run),
    }
}

/// A command's handler: carries out `msg` (its own command's message, as [`route`] sends it)
/// for client `c`, once the command's check and [`Who`] have passed.
pub(super) type Handler = fn(&Arc<AppState>, &mut Client, ClientMessage) -> Result<Accepted, Refusal>;

/// A check of a command's fields alone, whoever sends it.
pub(super) type Check = fn(&ClientMessage) -> Result<(), Refusal>;

/// One command's entry in the table.
#[derive(Debug, Clone, Copy)]
pub(super) struct Command {
    /// Its `type` on the wire, and its `command` in the audit log.
    pub name: &'static str,
    /// Who may send it.
    pub who: Who,
    /// What the audit log keeps of it.
    pub audit: Audit,
    /// Its fields' check, before anything else (so a command whose fields contradict each other
    /// is `invalid` whoever sends it).
    pub check: Option<Check>,
    /// What carries it out.
    pub handler: Handler,
}

impl Command {
    /// An entry without a check of its fields.
    const fn new(name: &'static str, who: Who, audit: Audit, handler: Handler) -> Command {
        Command {
            name,
            who,
            audit,
            check: None,
            handler,
        }
    }

    /// The entry with `check` of its fields.
    const fn checked(self, check: Check) -> Command {
        Command {
            check: Some(check),
            ..self
        }
    }

    /// Checks `msg` (its fields, then who sends it) and carries it out for `c`.
    pub fn run(&self, st: &Arc<AppState>, c: &mut Client, msg: ClientMessage) -> Result<Accepted, Refusal> {
        if let Some(check) = self.check {
            check(&msg)?;
        }
        self.who.check(st, c)?;
        (self.handler)(st, c, msg)
    }

    /// What the audit log keeps of `msg`: the command's name and its fields (the null ones left
    /// out), or nothing for a command that changes nothing.
    pub fn audit_text(
        &self,
        msg: &ClientMessage,
    ) -> Option<(&'static str, serde_json::Map<String, serde_json::Value>)> {
        match self.audit {
            Audit::Nothing => None,
            Audit::Fields => {
                let mut args = match serde_json::to_value(msg) {
                    Ok(serde_json::Value::Object(m)) => m,
                    _ => serde_json::Map::new(),
                };
                args.remove("type");
                args.retain(|_, v| !v.is_null());
                Some((self.name, args))
            }
        }
    }
}

/// Who may send a command.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Who {
    /// Anyone connected.
    Anyone,
    /// An operator; a viewer is refused `forbidden`, told that viewers cannot do this.
    Operator(&'static str),
    /// The client holding the lease (`no_lease` for any other), even while the server shuts
    /// down.
    Holder,
    /// The operator holding the lease, while the server is not shutting down: the commands that
    /// change the instrument.
    Commander,
}

impl Who {
    /// Whether client `c` may send the command, or why not.
    pub fn check(self, st: &AppState, c: &Client) -> Result<(), Refusal> {
        match self {
            Who::Anyone => Ok(()),
            Who::Operator(what) if c.role != Role::Operator => Err(Refusal::new(
                ErrorCode::Forbidden,
                format!("viewers cannot {what}; connect with the operator token"),
            )),
            Who::Operator(_) => Ok(()),
            Who::Holder if st.lease_holder() != Some(c.id) => Err(lease::not_held()),
            Who::Holder => Ok(()),
            Who::Commander => {
                Who::Operator("command").check(st, c)?;
                if st.lease_holder() != Some(c.id) {
                    return Err(Refusal::new(
                        ErrorCode::NoLease,
                        "this command needs the control lease: send take_lease first",
                    ));
                }
                if st.activity.stopping.load(std::sync::atomic::Ordering::Relaxed) || *st.channels.shutdown.borrow() {
                    return Err(Refusal::new(ErrorCode::ShuttingDown, "the server is shutting down"));
                }
                Ok(())
            }
        }
    }
}

/// What the audit log keeps of a command.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Audit {
    /// Nothing: the command changes nothing (`ping`, `subscribe`).
    Nothing,
    /// Its name, its fields and what became of it (`ok`, or `refused` with the code and why).
    Fields,
}

/// What a command's `ok` says besides its id.
#[derive(Debug, Clone, Default, PartialEq)]
pub(crate) struct Accepted {
    /// The haptic scales a `haptic` `scale` puts in force.
    pub scales: Option<HapticScales>,
    /// No `ok` is sent (an `ack`).
    pub silent: bool,
}

impl Accepted {
    /// An `ok` with nothing more to say.
    pub const PLAIN: Accepted = Accepted {
        scales: None,
        silent: false,
    };

    /// Accepted, and not answered.
    pub const SILENT: Accepted = Accepted {
        scales: None,
        silent: true,
    };
}

/// `ping`: answered `ok`.
fn ping(_: &Arc<AppState>, _: &mut Client, _: ClientMessage) -> Result<Accepted, Refusal> {
    Ok(Accepted::PLAIN)
}

/// The refusal of a handler given another command's message: [`route`] sent it to the wrong
/// handler, a fault of the server's, never of the client's.
fn misrouted(msg: &ClientMessage) -> Refusal {
    Refusal::new(
        ErrorCode::Invalid,
        format!("internal error: the server's table of commands sent {msg:?} to another command's handler"),
    )
}

#[cfg(test)]
mod tests {
    //! Each entry's name is its `type` on the wire, who may send what, what the audit log keeps,
    //! the check of `haptic`'s fields, and what a `haptic` `scale` puts in force.

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
            ClientMessage::Assemble {
                id: None,
                sites: None,
                generator: Some("ring:n=3,radius_um=2".into()),
                at_x_um: None,
                at_y_um: None,
                tolerance_nm: None,
                plan_only: true,
            },
            ClientMessage::Haptic {
                id: None,
                action: HapticAction::Release,
                nm_per_mm: None,
                pull_off_at_hand_n: None,
            },
            ClientMessage::Ack { seq: 1 },
        ];
        // Every command once: a command added to the protocol makes this match (and `route`'s)
        // incomplete until it is given a message here.
        let mut seen = [false; 10];
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
                ClientMessage::Ack { .. } => 8,
                ClientMessage::Assemble { .. } => 9,
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
        let [ping, subscribe, take, release, push, scan, stop, assemble, haptic, ack] =
            one_of_each().try_into().unwrap();
        assert_eq!(
            (who(&ping), who(&subscribe), who(&ack)),
            (Who::Anyone, Who::Anyone, Who::Anyone)
        );
        assert_eq!(who(&take), Who::Operator("take the lease"));
        assert_eq!(who(&release), Who::Holder);
        for m in [push, scan, stop, assemble, haptic] {
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
        let push =
            parse_command(r#"{"type":"push","id":4,"particle":2,"distance_um":0.5,"direction_deg":90}"#).unwrap();
        let (name, args) = route(&push).audit_text(&push).unwrap();
        assert_eq!(name, "push");
        assert_eq!(
            serde_json::Value::Object(args),
            serde_json::json!({"id": 4, "particle": 2, "distance_um": 0.5, "direction_deg": 90.0})
        );
        for m in one_of_each() {
            let audited = route(&m).audit_text(&m).is_some();
            let changes_nothing = matches!(
                m,
                ClientMessage::Ping { .. } | ClientMessage::Subscribe { .. } | ClientMessage::Ack { .. }
            );
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

    /// An `ack` of a frame sent is taken and not answered; one of a frame never sent (or before
    /// any) is refused naming the frames there are.
    #[test]
    fn an_ack_is_silent_and_must_name_a_frame_sent() {
        let st = test_state();
        let mut c = client(1, Role::Viewer);
        let e = command(&st, &mut c, r#"{"type":"ack","seq":5}"#).unwrap_err();
        assert_eq!(e.code, ErrorCode::OutOfRange);
        assert!(e.message.contains("no telemetry frame has been sent"), "{}", e.message);
        c.acks.newest_sent.store(40, Relaxed);
        assert_eq!(command(&st, &mut c, r#"{"type":"ack","seq":30}"#), Ok(Accepted::SILENT));
        assert_eq!(c.acks.acked.load(Relaxed), 30);
        for bad in [0, 41] {
            let e = command(&st, &mut c, &format!(r#"{{"type":"ack","seq":{bad}}}"#)).unwrap_err();
            assert_eq!(
                e.message,
                format!("ack seq = {bad} is out of range; allowed: [1, 40] (the frames sent to this client)")
            );
        }
        // An older one changes nothing.
        command(&st, &mut c, r#"{"type":"ack","seq":10}"#).unwrap();
        assert_eq!(c.acks.acked.load(Relaxed), 30);
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
}
