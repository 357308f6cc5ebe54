//! Every message type that crosses a nanopush process or network boundary.
//!
//! So far: the JSON documents the `nanopush` command line prints with `--json`
//! ([`model::ModelReport`], [`model::ForceCurveReport`]). All quantities are SI (m, N, s, kg,
//! rad, J, Pa); the key names carry no unit suffix because every value is SI. Each document
//! carries `schema` (its name) and `version` ([`VERSION`]) so a reader can reject what it does
//! not understand.
//!
//! ```
//! use nanopush_proto::model::ForceCurvePoint;
//! let p = ForceCurvePoint { distance: 1e-9, gap: 1e-9, deflection: 0.0, force: 0.0, meniscus: false, contact: false };
//! let json = serde_json::to_string(&p).unwrap();
//! assert!(json.contains("\"distance\":1e-9"));
//! ```
#![deny(missing_docs)]

pub mod accuracy;
pub mod haptic;
pub mod model;
pub mod push;
pub mod scan;
pub mod simulate;
pub mod sweep;
pub mod ws;

/// Version of every document in this crate; bumped on any incompatible change.
pub const VERSION: u32 = 1;
