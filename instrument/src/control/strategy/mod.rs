//! The manipulation strategy of Sec 2.1: its state machine ([`Strategy`], Fig 2), its settings
//! and outcomes, the rule for a reading on the readout's rail ([`pull_off`]), and its runner
//! against the simulated AFM ([`runner`]).

mod machine;
mod outcome;
mod params;
pub mod pull_off;
pub mod runner;

pub use machine::{BACK_OFF, HOLD, Phase, Strategy};
pub use outcome::{Failure, SearchStep, Summary};
pub use params::{Control, PushTask, StrategyParams};
pub use pull_off::pull_off_rise;
pub use runner::{Prepared, PushRequest, RunError, RunRow, StrategyRun, push_once};

#[cfg(test)]
mod contact_tests;
#[cfg(test)]
mod documented_tests;
#[cfg(test)]
mod pull_off_tests;
#[cfg(test)]
mod tests;
