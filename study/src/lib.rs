//! nanopush-study: the studies that check and explore the nanopush model, kept apart from the
//! server library so that the instrument does not compile them.
//!
//! - [`report`]: the derived quantities of a scene and its force curve (`nanopush model`);
//! - [`accuracy`]: the work-precision report, error against run time (`nanopush accuracy`),
//!   with [`accuracy::reduction`], the quasi-static reduction against the full model;
//! - [`extremes`]: the stability grid on stiff and extreme cases (`nanopush accuracy --extremes`);
//! - [`whole_pushes`]: whole pushes over every valid scene parameter (`nanopush accuracy
//!   --extremes`), each judged by [`judge`];
//! - [`random_scenes`]: random valid scenes nobody tuned, planned, pushed and judged
//!   (`nanopush campaign --random N`);
//! - [`random_assemblies`]: random layouts and patterns assembled and checked against the truth
//!   (`nanopush assemble --random N`);
//! - [`sweep`]: the parameter sweeps of Figs 10-13 (`nanopush sweep`);
//! - [`peers`] (feature `peers`, on by default): peer solvers from crates.io (diffsol,
//!   russell_ode) on the report's classical problems, for comparison at equal error.
//!
//! ```
//! let scene = nanopush_instrument::scene::Scene::default_scene();
//! let report = nanopush_study::report::model_report(&scene);
//! assert!(report.mu_feasible);
//! ```
#![deny(missing_docs)]

pub mod accuracy;
pub mod extremes;
pub mod judge;
#[cfg(feature = "peers")]
pub mod peers;
pub mod random_assemblies;
pub mod random_scenes;
pub mod report;
pub mod sweep;
pub mod whole_pushes;
