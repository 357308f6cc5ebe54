//! The nanopush instrument: force-controlled pushing of nanoparticles with an AFM, after Sitti &
//! Hashimoto, *Force Controlled Pushing of Nanoparticles: Modeling and Experiments*. Everything
//! here is plain computation and files: no async runtime, no sockets, no logging. The server
//! (`nanopush-server`), the command line and the studies are built on it.
//!
//! - [`physics`]: the paper's Section 2, pure functions in SI units (corrected per the errata,
//!   `docs/errata.md`), with [`physics::pushing::trace`], a push at constant speed sampled into a
//!   trace (`nanopush simulate`);
//! - [`numerics`]: dual numbers for exact Jacobians and the stiff integrators with events;
//! - [`scene`]: the TOML scene format (units in field names), its validation, and the SI model
//!   assembled from it;
//! - [`scan`]: tapping-mode scans (tip dilation, raster, GSF/PNG) and particle localization
//!   (`nanopush scan`);
//! - [`afm`]: the simulated AFM (stage, tip, substrate, particles) behind the controller;
//! - [`assembly`]: many particles pushed into a pattern (assignment, order, routes, re-planning);
//! - [`control`]: the strategy of Sec 2.1, the Eq 19 estimator, multi-push planning
//!   (`nanopush push`) and the bilateral haptic law;
//! - [`files`]: result files written atomically (temporary name, then rename).
//!
//! The studies of the model (work-precision, extremes, whole pushes, random scenes and
//! assemblies, sweeps, the model report, the peer solvers) are the `nanopush-study` crate; the
//! command line is `nanopush-cli`; the server, `nanopush-server`.
//!
//! # Layers
//!
//! Each module uses only modules of lower layers (tests aside), checked by the workspace's
//! `tests/e2e/layers.rs` against this table:
//!
//! | layer | modules | what they are |
//! |---|---|---|
//! | 0 | `numerics`, `files`, `words` | integrators and dual numbers; result files; numbers in messages |
//! | 1 | `physics` | the paper's Section 2 |
//! | 2 | `scene` | the scene file, its validation, the model assembled from it |
//! | 3 | `scan` | tapping-mode scans and localization |
//! | 4 | `afm` | the simulated AFM |
//! | 5 | `control` | the strategy, the estimator, routes, moves, the derived strategy, the haptic law |
//! | 6 | `assembly` | patterns assembled from many moves |
//!
//! ```
//! let scene = nanopush_instrument::scene::Scene::default_scene();
//! let model = scene.push_params();
//! assert!((model.cantilever.k_y() - 1427.0).abs() < 1.0);
//! ```
#![deny(missing_docs)]

pub mod afm;
pub mod assembly;
pub mod control;
pub mod files;
pub mod numerics;
pub mod physics;
pub mod scan;
pub mod scene;
mod words;

pub use words::{nm_text, panic_message, shown};
