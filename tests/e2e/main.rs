//! End-to-end tests: the real binaries, started as a user would start them.

mod haptic;
mod haptic_link;
mod model;
mod prometheus;
mod push;
mod scan;
mod serve;
mod serve_behaviour;
mod serve_hostile;
mod serve_scenes;
mod serve_state;
mod simulate;
mod sweep;
