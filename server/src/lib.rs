//! `nanopush serve`: the teleoperation server — the 1 kHz control loop on its own thread, the
//! WebSocket protocol of `proto/README.md`, roles and the control lease, metrics, recording. The
//! instrument it drives (physics, control, scans, the simulated AFM) is `nanopush-instrument`.

pub mod app;
pub mod app_state;
pub mod audit;
pub mod auth;
pub mod client_addr;
pub mod clock;
pub mod command_checks;
pub mod control_loop;
pub mod data_dir;
pub mod frames;
pub mod guard;
pub mod haptic;
pub mod histogram;
mod lifecycle;
pub mod metrics;
pub mod push;
pub mod record_routes;
pub mod records;
pub mod scan_job;
pub mod session;
pub mod telemetry;
pub mod tls;

pub use lifecycle::{IDLE_HTTP, ServeError, Started, run};
