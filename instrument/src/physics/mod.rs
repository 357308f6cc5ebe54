//! The paper's physics (Sec 2): pure functions and small types in SI units, no I/O, no async.
//!
//! Each module is named after the paper's concept and states its equations in its doc comments,
//! with the corrections of `docs/errata.md` where the print is wrong.

pub mod cantilever;
pub mod contact;
pub mod force_curve;
pub mod forces;
pub mod friction;
pub mod pushing;
pub mod sensor;
pub mod shearing;
pub mod stage;
pub mod topography;

/// Interatomic cut-off distance `a₀` (m): contact separation of two surfaces (Israelachvili,
/// *Intermolecular and Surface Forces*), where the van der Waals laws are evaluated at contact.
pub const A0_DEFAULT: f64 = 0.165e-9;
