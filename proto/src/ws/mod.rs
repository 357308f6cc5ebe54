//! The WebSocket protocol of `nanopush serve` (`/ws`): JSON text frames for commands, replies,
//! events and telemetry; binary frames for scan lines ([`ScanLineHeader`]). Documented for
//! clients in `proto/README.md`.
//!
//! Every client message is an object with a `type`; a command may carry an `id` (u32) that its
//! reply (`ok` or `error`) echoes. Values are in the units their names carry (`_um`, `_deg`) on
//! the way in, and SI in telemetry, as every nanopush document.
//!
//! Its parts: the commands ([`client`]), the server's messages ([`server`]), the data both
//! share ([`types`]) and the binary scan lines ([`scan_line`]); each item is also here, as
//! `nanopush_proto::ws::ClientMessage` and so on.

pub mod client;
pub mod scan_line;
pub mod server;
pub mod types;

pub use client::{ASSEMBLE_MAX_GENERATOR, ASSEMBLE_MAX_SITES, ClientMessage, HapticAction, SiteUm, Stream};
pub use scan_line::{FrameError, SCAN_LINE_HEADER_LEN, SCAN_LINE_MAGIC, ScanLineHeader};
pub use server::ServerMessage;
pub use types::{
    AssemblyNow, AssemblyPlan, AssemblySite, Bounds, ChosenStrategy, ErrorCode, HapticScales, HapticTelemetry,
    InstrumentInfo, Judged, MapParticle, ParticleNow, PlanMove, PlanSite, PushPath, Role, ScanNow, Telemetry,
};

/// Protocol version, sent in `welcome`; bumped on any incompatible change.
pub const WS_VERSION: u32 = 1;
