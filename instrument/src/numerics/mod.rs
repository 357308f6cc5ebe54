//! Numerics the physics is computed with: forward-mode dual numbers for exact Jacobians
//! ([`dual`]) and the stiff integrators with event location ([`integrate`]). Nothing here knows
//! about AFMs or particles.

pub mod dual;
pub mod integrate;
