//! The 1-DOF haptic side of nanopush: the operator moves the tip's height with a haptic handle
//! and feels the tip-sample force (Sec 4 of the paper: "bilateral force feedback").
//!
//! This crate holds the bilateral scaling between the nano world and the hand
//! ([`scaling::Scaling`]). The shared-memory link to the server is a later addition; the
//! `nanopush-haptic` binary already uses the scaling to render what an operator would feel over
//! a force curve computed by `nanopush model --force-curve --json`.
#![deny(missing_docs)]

pub mod scaling;
