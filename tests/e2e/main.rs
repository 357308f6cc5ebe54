//! End-to-end tests: the real binaries, started as a user would start them. One module per
//! command or concern; what they share (scratch directories, a server on a free port, its HTTP
//! API and WebSocket) is in [`util`].

mod assemble;
mod haptic;
mod haptic_grid;
mod haptic_link;
mod layers;
mod model;
mod nanonis;
mod prometheus;
mod push;
mod scan;
mod serve;
mod serve_access;
mod serve_assemble;
mod serve_audit;
mod serve_behaviour;
mod serve_campus;
mod serve_connections;
mod serve_hostile;
mod serve_judge;
mod serve_nanonis;
mod serve_proxy;
mod serve_scenes;
mod serve_sign_in;
mod serve_slow_reader;
mod serve_state;
mod serve_tls;
mod serve_token_file;
mod simulate;
mod sweep;
mod util;
