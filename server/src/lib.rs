//! `nanopush serve`: the teleoperation server — the 1 kHz control loop on its own thread, the
//! WebSocket protocol of `proto/README.md`, roles and the control lease, metrics, recording. The
//! instrument it drives (physics, control, scans, the simulated AFM) is `nanopush-instrument`.
//!
//! # Layers
//!
//! Each module uses only modules of lower layers (its tests aside), so no two modules use each
//! other, however indirectly. The state holds data and handles only; the jobs that work on it
//! (a push, a scan, the telemetry) sit above it, and the network above them. `tests/e2e/layers.rs`
//! reads this table and checks every `crate::` path against it.
//!
//! | layer | modules | what they are |
//! |---|---|---|
//! | 0 | `clock`, `histogram`, `client_addr`, `guard`, `data_dir`, `frames`, `command_checks` | foundations: they use no other module of the server |
//! | 1 | `tls`, `auth`, `haptic`, `conn_limit` | HTTPS, who connects, the haptic link, the connection caps |
//! | 2 | `audit`, `metrics` | the audit log (names `auth`'s people), the loop's metrics (and the link's) |
//! | 3 | `control_loop` | the 1 kHz loop and what crosses to it |
//! | 4 | `records`, `instrument_loop` | the recorder of the loop's pushes, and the data directory's records; the loop over a real controller |
//! | 5 | `app_state` | the state every task shares: settings, clients, lease, broadcasts, what the instrument is doing |
//! | 6 | `push`, `scan_job` | the instrument's jobs beside the loop: a push (launch, judge, prepare), a scan |
//! | 7 | `assembly` | an assembly: a pattern's moves, each a push through the loop, planned again after each |
//! | 8 | `telemetry`, `session`, `record_routes` | the loop's events and telemetry to the clients; one WebSocket connection and its table of commands; the records over HTTP |
//! | 9 | `app` | the HTTP side: the routes, the guard, sign-in, the WebSocket upgrade |
//! | 10 | `lifecycle` | the server's life: starts the threads and tasks, serves, shuts down in order |

pub mod app;
pub mod app_state;
pub mod assembly;
pub mod audit;
pub mod auth;
pub mod client_addr;
pub mod clock;
pub mod command_checks;
pub mod conn_limit;
pub mod control_loop;
pub mod data_dir;
pub mod frames;
pub mod guard;
pub mod haptic;
pub mod histogram;
pub mod instrument_loop;
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
