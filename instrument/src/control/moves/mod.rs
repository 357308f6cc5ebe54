//! A move as the operator asks for it: find the particle in a local scan and route its legs
//! around the others ([`locate`]), push them with the strategy, and judge where the particle
//! ended by the scan after ([`run`]).

pub mod locate;
pub mod run;

pub use locate::{DONE_WITHIN, MoveError, MoveRoute, MoveTarget, locate_near, route_move};
pub use run::{DEFAULT_ATTEMPTS, MoveOptions, MoveRun, MoveRunError, PushedLeg, Verdict, move_particle};
