//! Every message type that crosses a nanopush process or network boundary.
//!
//! The JSON documents the `nanopush` command line prints with `--json`
//! ([`model::ModelReport`], [`model::ForceCurveReport`]), the WebSocket protocol ([`ws`]) and
//! the haptic link's payloads ([`haptic`]). All quantities are SI (m, N, s, kg, rad, J, Pa); a
//! key names its unit only where the value is not in SI base units, or where the operator's
//! hand and the tip meet in one object (the convention: `proto/README.md`, "Units"). Each document
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
pub mod assembly;
pub mod haptic;
pub mod model;
pub mod nanonis;
pub mod push;
pub mod scan;
pub mod simulate;
pub mod sweep;
pub mod ws;

/// Version of every document in this crate; bumped on any incompatible change.
pub const VERSION: u32 = 1;
