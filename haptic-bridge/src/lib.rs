//! The 1-DOF haptic side of nanopush: the operator moves the tip's height with a haptic handle
//! and feels the tip-sample force (Sec 4 of the paper: "bilateral force feedback").
//!
//! - [`device`]: the device trait every backend implements (open, read, write force, limits);
//! - [`sim`] and [`operator`]: the simulated handle and the hand that holds it;
//! - [`serial`]: the backend for a Hapkit-class device on a serial port, and its binary protocol;
//! - [`passivity`]: the time-domain passivity observer and controller at the port;
//! - [`bridge`]: one device cycle (read, local model, passivity, clamp, write, publish), and
//!   [`link`], its iceoryx2 ports;
//! - [`latency`]: an allocation-free latency histogram;
//! - [`grid`]: the measures of a closed haptic cycle (raw port energy, chatter, tip-force swing)
//!   and the grid of settings they are checked over;
//! - [`scaling`]: the bilateral scaling between the nano world and the hand.
#![deny(missing_docs)]

pub mod bridge;
pub mod device;
pub mod grid;
pub mod latency;
pub mod link;
pub mod operator;
pub mod passivity;
pub mod scaling;
pub mod serial;
pub mod sim;
