//! nanopush: force-controlled pushing of nanoparticles with an AFM, after Sitti & Hashimoto,
//! *Force Controlled Pushing of Nanoparticles: Modeling and Experiments*.
//!
//! - [`physics`]: the paper's Section 2, pure functions in SI units (corrected per the errata);
//! - [`scene`]: the TOML scene format (units in field names), its validation, and the SI model
//!   assembled from it;
//! - [`report`]: the derived quantities printed by `nanopush model`;
//! - [`files`]: result files written atomically (temporary name, then rename);
//! - [`accuracy`]: the work-precision report (`nanopush accuracy`);
//! - [`extremes`]: the stability grid (`nanopush accuracy --extremes`);
//! - [`peers`]: peer solvers from crates.io (diffsol, russell_ode) on the report's classical
//!   problems, for comparison at equal error;
//! - [`push_run`]: a push at constant speed, sampled into a trace (`nanopush simulate`);
//! - [`sweep`]: the parameter sweeps of Figs 10-13 (`nanopush sweep`);
//! - [`scan`]: tapping-mode scans (tip dilation, raster, GSF/PNG) and particle localization
//!   (`nanopush scan`);
//! - [`instrument`]: the simulated AFM (stage, tip, substrate, particles) behind the controller;
//! - [`control`]: the strategy of Sec 2.1, the Eq 19 estimator and multi-push planning
//!   (`nanopush push`).
//!
//! ```
//! let scene = nanopush::scene::Scene::default_scene();
//! let model = scene.push_params();
//! assert!((model.cantilever.k_y() - 1427.0).abs() < 1.0);
//! ```
#![deny(missing_docs)]

pub mod accuracy;
pub mod campaign;
pub mod control;
pub mod extremes;
pub mod files;
pub mod instrument;
pub mod peers;
pub mod physics;
pub mod push_run;
pub mod report;
pub mod scan;
pub mod scene;
pub mod serve;
pub mod sweep;

/// The message of a caught panic's payload (`&str` or `String`), for reports that turn a
/// panic in one case, run or push into a row with its reason.
pub fn panic_message(payload: &(dyn std::any::Any + Send)) -> String {
    payload
        .downcast_ref::<&str>()
        .map(|s| s.to_string())
        .or_else(|| payload.downcast_ref::<String>().cloned())
        .unwrap_or_else(|| "(no message)".into())
}
