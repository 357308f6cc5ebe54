//! Stiff integration of `M y' = f(t, y)`: Rosenbrock (Rodas4), ESDIRK (TR-BDF2) and implicit
//! Euler with adaptive steps, dense output and event location.

mod driver;
pub(crate) mod linalg;
pub(crate) mod methods;
mod problem;
pub(crate) mod rosenbrock;
/// The reference problems, for the tests here and the studies' work-precision report (feature
/// `test-problems`): not part of the instrument.
#[cfg(any(test, feature = "test-problems"))]
pub mod test_problems;

pub use driver::{Integrator, MAX_EVENTS};
pub use methods::Method;
pub use problem::{Events, IntegrateError, MAX_DIM, NoEvents, Options, Outcome, Problem, Stats};

#[cfg(test)]
mod tests;
