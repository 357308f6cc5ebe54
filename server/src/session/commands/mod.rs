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
//! 2. **This table**: its entry in [`route`] (the match is exhaustive: the compiler asks for it).
//! 3. **Its handler**: a file of this directory with a [`Handler`], which checks what depends on
//!    the instrument's state (a value out of range is refused naming the field and the allowed
//!    range: `command_checks::number`) and carries the command out.
//! 4. **The page**: its builder in `web/src/wire.js` (`commands`).
//!
//! (A command the control loop carries out in a way it does not know yet also needs its
//! `LoopCommand`, in `control_loop`.)

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
        M::Stop { .. } => Command::new("stop", Commander, Fields, stop::run),
        M::Haptic { .. } => Command::new("haptic", Commander, Fields, haptic::run).checked(haptic::fields_apply),
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
}

impl Accepted {
    /// An `ok` with nothing more to say.
    pub const PLAIN: Accepted = Accepted { scales: None };
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
mod tests;
