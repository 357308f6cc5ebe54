//! The 1-DOF haptic side of nanopush: the operator moves the tip's height with a haptic handle
//! and feels the tip-sample force (Sec 4 of the paper: "bilateral force feedback").
//!
//! - [`device`]: the device trait every backend implements (open, read, write force, limits);
//! - [`scaling`]: the bilateral scaling between the nano world and the hand;
//! - [`serial`]: the backend for a Hapkit-class device on a serial port, and its binary protocol.
#![deny(missing_docs)]

pub mod device;
pub mod scaling;
pub mod serial;
