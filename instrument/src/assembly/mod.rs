//! Assembly: many particles pushed into a 2-D pattern, the paper's purpose ("2-D positioning
//! and assembly of nanoparticles") done as the field does it since — assign particles to sites
//! at least total cost and order the moves so that none collide (Barredo et al., *Science* 354,
//! 2016), route each around the others and re-plan after every scan (Celotta et al., *Rev. Sci.
//! Instrum.* 85, 2014; Kalff et al., *Nature Nanotechnology* 11, 2016). The pushing is the
//! paper's: each move is a `nanopush push`, judged by the scan after it.
//!
//! - [`pattern`]: the target sites, from a file or a generator (line, grid, ring, letters);
//! - [`assign`]: which particle fills which site (Kuhn-Munkres);
//! - [`plan`]: the order of the moves and their routes, played out on the positions;
//! - [`book`]: what an assembly knows and has done, whoever makes its moves; it plans again
//!   after every move from the move's local scans;
//! - [`run`]: an assembly against the simulated AFM (`nanopush assemble`).

pub mod assign;
pub mod book;
mod letters;
pub mod pattern;
pub mod plan;
pub mod routing;
pub mod run;
pub mod summary;

pub use book::{AssemblyOptions, Book, MoveDone, MoveRecord, SiteReport, TrueParticle};
pub use pattern::{Pattern, PatternError, Site};
pub use plan::{Constraints, Plan, PlanSettings, PlannedMove, Purpose, Seen, SiteState, Unfilled, plan};
pub use run::{AssemblyRun, Event, Outcome, assemble};
