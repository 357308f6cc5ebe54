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
//! - [`control`]: the strategy of Sec 2.1, the Eq 19 estimator, multi-push planning
//!   (`nanopush push`) and the bilateral haptic law;
//! - [`files`]: result files written atomically (temporary name, then rename).
//!
//! The studies of the model (work-precision, extremes, campaign, sweeps, the model report, the
//! peer solvers) are the `nanopush-study` crate; the command line is `nanopush-cli`.
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

/// A number as an error message shows it: as written when short, else in scientific notation (a
/// 1e308 is not 309 digits, a 1e-320 not 330).
pub fn shown(v: f64) -> String {
    let plain = v.to_string();
    if plain.len() <= 16 { plain } else { format!("{v:e}") }
}

/// A length (m) in nm as the user gave it, for messages: to the picometre, trailing zeros
/// dropped (a 1.75 nm tolerance reads `1.75`, not `2`; 25e-9 reads `25`).
pub fn nm_text(v: f64) -> String {
    shown((v * 1e12).round() / 1e3)
}

/// The message of a caught panic's payload (`&str` or `String`), for reports that turn a
/// panic in one case, run or push into a row with its reason.
pub fn panic_message(payload: &(dyn std::any::Any + Send)) -> String {
    payload
        .downcast_ref::<&str>()
        .map(|s| s.to_string())
        .or_else(|| payload.downcast_ref::<String>().cloned())
        .unwrap_or_else(|| "(no message)".into())
}
