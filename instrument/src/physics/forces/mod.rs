//! The interaction forces of Sec 2.2: van der Waals (Eq 1, 2), capillary (Eq 3), electrostatic (Eq 4).

pub mod capillary;
pub mod electrostatic;
pub mod vdw;
