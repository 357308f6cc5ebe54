//! The WebSocket protocol of `nanopush serve` (`/ws`): JSON text frames for commands, replies,
//! events and telemetry; binary frames for scan lines ([`ScanLineHeader`]). Documented for
//! clients in `proto/README.md`.
//!
//! Every client message is an object with a `type`; a command may carry an `id` (u32) that its
//! reply (`ok` or `error`) echoes. Values are in the units their names carry (`_um`, `_deg`) on
//! the way in, and SI in telemetry, as every nanopush document.

use serde::{Deserialize, Serialize};

/// Protocol version, sent in `welcome`; bumped on any incompatible change.
pub const WS_VERSION: u32 = 1;

/// The streams a client can subscribe to. Nothing is produced for a stream no client wants.
/// Read from its name only (a derived reader also took `{"tip": null}`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Stream {
    /// `telemetry` at about 60 Hz: tip position, reading, phase.
    Tip,
    /// `scan_start`, binary scan lines as they complete, `scan_done`.
    Scan,
}

impl<'de> Deserialize<'de> for Stream {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct Name;
        impl serde::de::Visitor<'_> for Name {
            type Value = Stream;
            fn expecting(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                f.write_str("a stream's name, \"tip\" or \"scan\"")
            }
            fn visit_str<E: serde::de::Error>(self, v: &str) -> Result<Stream, E> {
                match v {
                    "tip" => Ok(Stream::Tip),
                    "scan" => Ok(Stream::Scan),
                    other => Err(E::custom(format_args!(
                        "unknown stream \"{other}\"; the streams are \"tip\" and \"scan\""
                    ))),
                }
            }
        }
        d.deserialize_str(Name)
    }
}

/// A client → server message.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "snake_case", deny_unknown_fields)]
pub enum ClientMessage {
    /// Choose the streams to receive (replaces the previous choice).
    Subscribe {
        /// Command id, echoed in the reply.
        #[serde(default)]
        id: Option<u32>,
        /// Streams wanted.
        streams: Vec<Stream>,
    },
    /// Ask for the control lease (operators only; one holder at a time).
    TakeLease {
        /// Command id.
        #[serde(default)]
        id: Option<u32>,
    },
    /// Give the lease back.
    ReleaseLease {
        /// Command id.
        #[serde(default)]
        id: Option<u32>,
    },
    /// Push a particle: a distance along a direction, or to a target (then planned as several
    /// pushes if needed). Needs the lease.
    Push {
        /// Command id.
        #[serde(default)]
        id: Option<u32>,
        /// Particle id, as the scene names it.
        particle: u32,
        /// Distance (µm), with `direction_deg`.
        #[serde(default)]
        distance_um: Option<f64>,
        /// Direction in the plane (degrees from +x).
        #[serde(default)]
        direction_deg: Option<f64>,
        /// Target x (µm), with `to_y_um`, instead of a distance.
        #[serde(default)]
        to_x_um: Option<f64>,
        /// Target y (µm).
        #[serde(default)]
        to_y_um: Option<f64>,
        /// The push is `ok` when the scan after it finds the particle within this of the target
        /// (nm); [`crate::push::TOLERANCE_NM`] when left out, within
        /// [`crate::push::TOLERANCE_RANGE_NM`].
        #[serde(default)]
        tolerance_nm: Option<f64>,
    },
    /// A tapping-mode scan of a square region (the scene's `[scan]` where left out). Needs the
    /// lease.
    Scan {
        /// Command id.
        #[serde(default)]
        id: Option<u32>,
        /// Centre x (µm).
        #[serde(default)]
        centre_x_um: Option<f64>,
        /// Centre y (µm).
        #[serde(default)]
        centre_y_um: Option<f64>,
        /// Side (µm).
        #[serde(default)]
        size_um: Option<f64>,
        /// Pixels per line and lines.
        #[serde(default)]
        pixels: Option<u32>,
    },
    /// Abort what runs now: the tip retracts. Needs the lease.
    Stop {
        /// Command id.
        #[serde(default)]
        id: Option<u32>,
    },
    /// Liveness check; answered with `ok`.
    Ping {
        /// Command id.
        #[serde(default)]
        id: Option<u32>,
    },
    /// Haptic z-control from the 1-DOF handle. Needs the lease, and for `engage` a live haptic
    /// link.
    Haptic {
        /// Command id.
        #[serde(default)]
        id: Option<u32>,
        /// What to do.
        action: HapticAction,
        /// New position scale (tip nm per handle mm), with `scale`.
        #[serde(default)]
        nm_per_mm: Option<f64>,
        /// New force scale: the force felt at the scene's pull-off (N), with `scale`.
        #[serde(default)]
        pull_off_at_hand_n: Option<f64>,
    },
}

/// What a `haptic` command does.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum HapticAction {
    /// Approach the surface, park above it, and give the tip's height to the hand (forces ramp
    /// in over a second once they are small).
    Engage,
    /// Park the tip and let the handle go.
    Release,
    /// Re-centre: the tip stays, the handle's travel is centred on where the hand is.
    Recenter,
    /// Change the scales (`nm_per_mm`, `pull_off_at_hand_n`).
    Scale,
}

impl ClientMessage {
    /// The command id, if any.
    pub fn id(&self) -> Option<u32> {
        match self {
            ClientMessage::Subscribe { id, .. }
            | ClientMessage::TakeLease { id }
            | ClientMessage::ReleaseLease { id }
            | ClientMessage::Push { id, .. }
            | ClientMessage::Scan { id, .. }
            | ClientMessage::Stop { id }
            | ClientMessage::Ping { id }
            | ClientMessage::Haptic { id, .. } => *id,
        }
    }
}

/// A client's role, from its token.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Role {
    /// Watches; cannot command.
    Viewer,
    /// May take the lease and command.
    Operator,
}

/// Why a message was refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ErrorCode {
    /// Not JSON, or not a known message shape.
    Malformed,
    /// Larger than the server's message limit.
    TooLarge,
    /// More messages per second than allowed; this one was dropped.
    RateLimited,
    /// A viewer sent a command.
    Forbidden,
    /// The command needs the lease, which this client does not hold.
    NoLease,
    /// Another operator holds the lease.
    LeaseHeld,
    /// A number is not finite.
    NotFinite,
    /// A number is outside its allowed range.
    OutOfRange,
    /// No particle with that id.
    UnknownParticle,
    /// Something runs already (a push or a scan); stop it first.
    Busy,
    /// The request is inconsistent (both a distance and a target, say).
    Invalid,
    /// The server is shutting down.
    ShuttingDown,
    /// What the command needs is not there (the haptic link is off or down).
    Unavailable,
}

/// Tip telemetry (SI).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Telemetry {
    /// Server time since start (s).
    pub t: f64,
    /// The frame's number, from 1, one more for each frame the server produces: a client sees
    /// each number at most once and in increasing order, and a number skipped is a frame it
    /// lost (announced by `lagged`).
    #[serde(default)]
    pub seq: u64,
    /// Stage position: tip x, y and the undeflected apex height (m).
    pub stage: [f64; 3],
    /// Deflection reading (V).
    pub volts: f64,
    /// Strategy phase (`idle` when nothing runs, `scanning` during a scan).
    pub phase: String,
    /// The pushed particle's estimated centre (m), while a push runs.
    pub estimate: Option<[f64; 2]>,
    /// The tip force from the measured deflection, `k_z ζ_z` (N), positive repulsive.
    #[serde(default)]
    pub tip_force_n: f64,
    /// The haptic link, when the server runs one (`--haptic sim|external`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub haptic: Option<HapticTelemetry>,
}

/// A particle where the server believes it is now (SI).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ParticleNow {
    /// Particle id.
    pub id: u32,
    /// Centre x, y (m).
    pub x: f64,
    /// Centre y (m).
    pub y: f64,
    /// Radius (m).
    pub radius: f64,
}

/// A push as commanded: the particle and the planned path of its centre (SI).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PushPath {
    /// Particle.
    pub particle: u32,
    /// The path's points (m): where the particle was located, then the end of each leg.
    pub path: Vec<[f64; 2]>,
    /// The client that commanded it.
    pub by: u32,
    /// Its run number (per server run), as its record's summary says: with the server's
    /// `instance`, a client that lost sight of the push finds its record and no other.
    pub run: u64,
    /// Which push of the move this is: 1, then 2.. for each correction from where the scan
    /// after the previous push found the particle (older servers leave it out: 1).
    #[serde(default = "first_attempt")]
    pub attempt: u32,
    /// What the strategy plan for this particle warns of (a hand-set value that cannot work, a
    /// dry run that fails, a tolerance no push can reach), on the first push of a move.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub warnings: Vec<String>,
}

fn first_attempt() -> u32 {
    1
}

/// A move judged by the scan after its last push (SI).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Judged {
    /// Where the scan after the last push found the particle (m).
    pub measured: [f64; 2],
    /// Where it was sent (m).
    pub target: [f64; 2],
    /// The measured distance from the target (m).
    pub error_m: f64,
    /// The move's tolerance (m): `ok` within it, `missed` beyond it.
    pub tolerance_m: f64,
    /// Pushes made: the first and the corrections.
    pub attempts: u32,
}

/// The latest scan, for a client that joins after it (SI).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ScanNow {
    /// Scan id.
    pub scan: u32,
    /// Pixels per line.
    pub xres: u32,
    /// Lines.
    pub yres: u32,
    /// Left edge (m).
    pub x_offset: f64,
    /// Bottom edge (m).
    pub y_offset: f64,
    /// Width (m).
    pub x_real: f64,
    /// Height (m).
    pub y_real: f64,
    /// Whether it has finished (false: its remaining lines follow on the `scan` stream).
    pub done: bool,
    /// Its record (a GSF file under `/api/records`), when finished and written.
    pub record: Option<String>,
    /// A push has run since: the sample no longer looks like this.
    pub stale: bool,
}

/// The haptic handle in telemetry (SI).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct HapticTelemetry {
    /// `up`, `down`.
    pub link: String,
    /// Haptic z-control phase: `off`, `approach`, `park`, `settle`, `ramp`, `engaged`,
    /// `clutched`, `pushing`, `link_lost`, `retract`.
    pub phase: String,
    /// Handle position (m); null before the first sample.
    pub handle_m: Option<f64>,
    /// Force rendered at the hand (N); null before the first sample.
    pub force_n: Option<f64>,
    /// Tip force from the measured deflection (N), positive repulsive.
    pub tip_force_n: f64,
    /// Whether the passivity controller acted within the last 100 ms.
    pub pc_active: bool,
    /// The scales in force.
    pub scales: HapticScales,
}

/// The scales of haptic z-control in force, and why they differ from those asked: in the `ok`
/// of a `haptic` `scale`, in telemetry's `haptic` and in `/api/status`'s `haptic`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct HapticScales {
    /// Tip nanometres per handle millimetre.
    pub nm_per_mm: f64,
    /// The tip-sample pull-off as felt at the hand, in force (N).
    pub pull_off_at_hand_n: f64,
    /// The pull-off at the hand asked for (N).
    pub asked_pull_off_at_hand_n: f64,
    /// The contact's stiffness felt at the hand in force, `g_f k_z g_p` (N/m).
    pub felt_stiffness_n_per_m: f64,
    /// The device's renderable region's edge at its rate and the measured delay (N/m); null
    /// before a device is known.
    pub max_stiffness_n_per_m: Option<f64>,
    /// The round-trip delay the region is computed for (s).
    pub delay_s: f64,
    /// `none`, `renderable_region`, `energy_bounding`.
    pub limit: String,
    /// Why, in a sentence; null when `limit` is `none`.
    pub reason: Option<String>,
}

/// A server → client text message.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "snake_case")]
pub enum ServerMessage {
    /// First message on a connection.
    Welcome {
        /// [`WS_VERSION`].
        version: u32,
        /// This connection's id.
        client: u32,
        /// Its role.
        role: Role,
        /// Who holds the lease now.
        lease: Option<u32>,
        /// The name of the person holding the lease (their token's name; `operator` without a
        /// token file).
        #[serde(default)]
        lease_name: Option<String>,
        /// The name of the person this connection's credential names (`anonymous` for a
        /// viewer without one).
        #[serde(default)]
        name: String,
        /// Scene name.
        scene: String,
        /// Control loop rate (Hz).
        tick_hz: f64,
        /// This run of the server: a client that reconnects and finds another knows the
        /// server restarted (a push it saw running ended unrecorded, or in a record).
        instance: String,
        /// When this run of the server started (ms since the Unix epoch).
        started_unix_ms: u64,
    },
    /// Second message on a connection, right after `welcome`: the instrument as it is now, so
    /// a client that joins late (or reloads) shows what the others see.
    State {
        /// The particles where the server believes they are (the scene's positions, then each
        /// push's final estimate).
        particles: Vec<ParticleNow>,
        /// Stage position (m), as in telemetry.
        stage: [f64; 3],
        /// Phase, as in telemetry.
        phase: String,
        /// Lease holder.
        lease: Option<u32>,
        /// The lease holder's name.
        #[serde(default)]
        lease_name: Option<String>,
        /// The push running now, if any.
        push: Option<PushPath>,
        /// The latest scan (running or finished), if any.
        scan: Option<ScanNow>,
    },
    /// A push was planned and starts (to everyone): what will be pushed, along which path.
    PushStarted(PushPath),
    /// A command was accepted.
    Ok {
        /// Its id.
        id: Option<u32>,
        /// For a `haptic` `scale`: the scales that will be in force (the asked ones, or lower
        /// where the device cannot render them passively), and why.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        scales: Option<HapticScales>,
    },
    /// A message was refused.
    Error {
        /// The command's id, when it could be read.
        id: Option<u32>,
        /// Why.
        code: ErrorCode,
        /// In words, naming the field and the allowed range.
        message: String,
    },
    /// Tip telemetry (stream `tip`).
    Telemetry(Telemetry),
    /// This client was too slow and skipped `skipped` messages.
    Lagged {
        /// Messages skipped.
        skipped: u64,
    },
    /// The lease changed hands (to everyone).
    Lease {
        /// Holder now.
        holder: Option<u32>,
        /// The holder's name (absent when the lease is free).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        holder_name: Option<String>,
        /// Why it changed, when not by the holder's own command (its connection closed).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        reason: Option<String>,
    },
    /// A push ended (to everyone).
    RunDone {
        /// Particle.
        particle: u32,
        /// `ok` or the failure code.
        outcome: String,
        /// The failure in words.
        failure: Option<String>,
        /// Estimated final centre (m); null when the push never started (no plan, not found).
        estimate: Option<[f64; 2]>,
        /// Name of its record under `/api/records`; null when none was written.
        record: Option<String>,
        /// Why no record was written (disk full, read-only, gone), when one was not.
        #[serde(default)]
        record_error: Option<String>,
        /// What the scan after the last push measured, when one was made: `ok` and `missed`
        /// are decided by it, never by the estimate.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        judged: Option<Judged>,
    },
    /// A scan starts (stream `scan`); binary line frames follow.
    ScanStart {
        /// Scan id.
        scan: u32,
        /// Pixels per line.
        xres: u32,
        /// Lines.
        yres: u32,
        /// Left edge (m).
        x_offset: f64,
        /// Bottom edge (m).
        y_offset: f64,
        /// Width (m).
        x_real: f64,
        /// Height (m).
        y_real: f64,
    },
    /// A scan ended (stream `scan`).
    ScanDone {
        /// Scan id.
        scan: u32,
        /// Name of its record; null when none was written.
        record: Option<String>,
        /// Why no record was written, when one was not (a cancelled scan has neither).
        #[serde(default)]
        record_error: Option<String>,
    },
    /// The server is shutting down; the connection closes next.
    Shutdown {
        /// Why.
        reason: String,
    },
}

/// The header of a binary scan-line frame, little-endian, 32 bytes, followed by `xres` f32
/// heights (m), left to right:
///
/// | offset | type | field |
/// |---|---|---|
/// | 0 | `[u8; 4]` | magic `NPSL` |
/// | 4 | u16 | version (1) |
/// | 6 | u16 | reserved (0) |
/// | 8 | u32 | scan id |
/// | 12 | u32 | line index (0 = first, bottom) |
/// | 16 | u32 | xres |
/// | 20 | u32 | yres |
/// | 24 | f64 | line y (m) |
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ScanLineHeader {
    /// Scan id.
    pub scan: u32,
    /// Line index.
    pub line: u32,
    /// Pixels per line.
    pub xres: u32,
    /// Lines.
    pub yres: u32,
    /// Line y (m).
    pub y: f64,
}

/// Magic of a scan-line frame.
pub const SCAN_LINE_MAGIC: [u8; 4] = *b"NPSL";
/// Header length (bytes).
pub const SCAN_LINE_HEADER_LEN: usize = 32;

/// Why a binary frame could not be decoded.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum FrameError {
    /// Shorter than its header or its declared data.
    Short(usize),
    /// Not a scan line.
    BadMagic,
    /// A version this decoder does not know.
    Version(u16),
}

impl ScanLineHeader {
    /// Encodes the header and `heights` into one frame.
    pub fn encode(&self, heights: &[f32]) -> Vec<u8> {
        let mut b = Vec::with_capacity(SCAN_LINE_HEADER_LEN + 4 * heights.len());
        b.extend_from_slice(&SCAN_LINE_MAGIC);
        b.extend_from_slice(&1u16.to_le_bytes());
        b.extend_from_slice(&0u16.to_le_bytes());
        for v in [self.scan, self.line, self.xres, self.yres] {
            b.extend_from_slice(&v.to_le_bytes());
        }
        b.extend_from_slice(&self.y.to_le_bytes());
        for h in heights {
            b.extend_from_slice(&h.to_le_bytes());
        }
        b
    }

    /// Decodes a frame into its header and heights.
    pub fn decode(b: &[u8]) -> Result<(ScanLineHeader, Vec<f32>), FrameError> {
        if b.len() < SCAN_LINE_HEADER_LEN {
            return Err(FrameError::Short(b.len()));
        }
        if b[..4] != SCAN_LINE_MAGIC {
            return Err(FrameError::BadMagic);
        }
        let version = u16::from_le_bytes([b[4], b[5]]);
        if version != 1 {
            return Err(FrameError::Version(version));
        }
        let u = |k: usize| u32::from_le_bytes([b[k], b[k + 1], b[k + 2], b[k + 3]]);
        let h = ScanLineHeader {
            scan: u(8),
            line: u(12),
            xres: u(16),
            yres: u(20),
            y: f64::from_le_bytes(b[24..32].try_into().expect("8 bytes")),
        };
        let need = SCAN_LINE_HEADER_LEN + 4 * h.xres as usize;
        if b.len() != need {
            return Err(FrameError::Short(b.len()));
        }
        let heights = b[SCAN_LINE_HEADER_LEN..]
            .chunks_exact(4)
            .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
            .collect();
        Ok((h, heights))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn client_messages_parse_from_their_documented_json() {
        let m: ClientMessage =
            serde_json::from_str(r#"{"type":"push","id":7,"particle":1,"distance_um":2.5,"direction_deg":90}"#)
                .unwrap();
        assert_eq!(m.id(), Some(7));
        assert!(matches!(m, ClientMessage::Push { particle: 1, distance_um: Some(d), .. } if d == 2.5));
        let m: ClientMessage = serde_json::from_str(r#"{"type":"subscribe","streams":["tip","scan"]}"#).unwrap();
        assert_eq!(
            m,
            ClientMessage::Subscribe {
                id: None,
                streams: vec![Stream::Tip, Stream::Scan]
            }
        );
        assert!(serde_json::from_str::<ClientMessage>(r#"{"type":"push","particle":1,"bogus":1}"#).is_err());
        assert!(serde_json::from_str::<ClientMessage>(r#"{"type":"fly"}"#).is_err());
    }

    /// Issue 27.8: a stream is its name; `{"tip": null}` (which a derived reader took) and
    /// unknown names are refused, naming the streams there are.
    #[test]
    fn a_stream_is_a_name_only() {
        for bad in [r#"[{"tip":null}]"#, r#"["wind"]"#, "[1]"] {
            let e = serde_json::from_str::<Vec<Stream>>(bad).unwrap_err().to_string();
            assert!(e.contains("\"tip\"") && e.contains("\"scan\""), "{bad}: {e}");
        }
        assert_eq!(serde_json::to_string(&Stream::Scan).unwrap(), "\"scan\"");
    }

    #[test]
    fn server_messages_serialize_with_a_type_tag() {
        let s = serde_json::to_string(&ServerMessage::Error {
            id: Some(3),
            code: ErrorCode::OutOfRange,
            message: "x".into(),
        })
        .unwrap();
        assert_eq!(s, r#"{"type":"error","id":3,"code":"out_of_range","message":"x"}"#);
        let t = serde_json::to_string(&ServerMessage::Telemetry(Telemetry {
            t: 1.0,
            seq: 7,
            stage: [0.0; 3],
            volts: -0.2,
            phase: "idle".into(),
            estimate: None,
            tip_force_n: 1e-9,
            haptic: None,
        }))
        .unwrap();
        assert!(t.contains(r#""tip_force_n":1e-9"#), "{t}");
        assert!(t.starts_with(r#"{"type":"telemetry","t":1.0,"seq":7,"#), "{t}");
        // Without a haptic link, no `haptic` key at all.
        assert!(!t.contains("haptic"), "{t}");
    }

    #[test]
    fn the_state_and_push_started_messages_carry_their_type_and_fields() {
        let path = PushPath {
            particle: 2,
            path: vec![[1e-6, 2e-6], [3e-6, 2e-6]],
            by: 5,
            run: 3,
            attempt: 2,
            warnings: vec!["strategy.speed_um_per_s = 10 (hand-set): faster than the set point allows".into()],
        };
        let s = serde_json::to_value(ServerMessage::PushStarted(path.clone())).unwrap();
        assert_eq!(s["attempt"], 2);
        assert_eq!(
            s["warnings"][0],
            "strategy.speed_um_per_s = 10 (hand-set): faster than the set point allows"
        );
        assert_eq!(s["type"], "push_started");
        assert_eq!(s["particle"], 2);
        assert_eq!(s["by"], 5);
        assert_eq!(s["run"], 3);
        let s = serde_json::to_value(ServerMessage::State {
            particles: vec![ParticleNow {
                id: 2,
                x: 1e-6,
                y: 2e-6,
                radius: 5e-7,
            }],
            stage: [0.0; 3],
            phase: "idle".into(),
            lease: Some(5),
            lease_name: Some("alice".into()),
            push: Some(path),
            scan: None,
        })
        .unwrap();
        assert_eq!(s["type"], "state");
        assert_eq!(s["lease_name"], "alice");
        assert_eq!(s["particles"][0]["radius"], 5e-7);
        assert_eq!(s["push"]["path"][1][0], 3e-6);
        assert!(s["scan"].is_null());
        // A lease change by command has no reason key; one by a disconnect says why.
        let l = serde_json::to_string(&ServerMessage::Lease {
            holder: None,
            holder_name: None,
            reason: None,
        })
        .unwrap();
        assert_eq!(l, r#"{"type":"lease","holder":null}"#);
        // A held lease names its holder.
        let l = serde_json::to_string(&ServerMessage::Lease {
            holder: Some(3),
            holder_name: Some("alice".into()),
            reason: None,
        })
        .unwrap();
        assert_eq!(l, r#"{"type":"lease","holder":3,"holder_name":"alice"}"#);
    }

    #[test]
    fn the_haptic_command_parses_and_refuses_unknown_actions() {
        let m: ClientMessage =
            serde_json::from_str(r#"{"type":"haptic","id":7,"action":"scale","nm_per_mm":20}"#).unwrap();
        assert_eq!(
            m,
            ClientMessage::Haptic {
                id: Some(7),
                action: HapticAction::Scale,
                nm_per_mm: Some(20.0),
                pull_off_at_hand_n: None,
            }
        );
        assert_eq!(m.id(), Some(7));
        assert!(serde_json::from_str::<ClientMessage>(r#"{"type":"haptic","action":"wobble"}"#).is_err());
        assert!(serde_json::from_str::<ClientMessage>(r#"{"type":"haptic","action":"engage","force":1}"#).is_err());
    }

    #[test]
    fn scan_line_frames_round_trip_and_reject_bad_input() {
        let h = ScanLineHeader {
            scan: 2,
            line: 5,
            xres: 3,
            yres: 8,
            y: 1.5e-6,
        };
        let f = h.encode(&[1.0, 2.0, 3.0]);
        assert_eq!(f.len(), SCAN_LINE_HEADER_LEN + 12);
        assert_eq!(&f[..4], b"NPSL");
        assert_eq!(ScanLineHeader::decode(&f).unwrap(), (h, vec![1.0, 2.0, 3.0]));
        assert_eq!(ScanLineHeader::decode(&f[..20]), Err(FrameError::Short(20)));
        assert_eq!(ScanLineHeader::decode(&f[..40]), Err(FrameError::Short(40)));
        let mut bad = f.clone();
        bad[0] = b'X';
        assert_eq!(ScanLineHeader::decode(&bad), Err(FrameError::BadMagic));
        let mut v2 = f;
        v2[4] = 2;
        assert_eq!(ScanLineHeader::decode(&v2), Err(FrameError::Version(2)));
    }

    /// Every byte of every header field is read from its own place: fields whose four bytes all
    /// differ survive the round trip (cargo-mutants: reading byte `k - 1` for `k + 1` survived on
    /// values with only a low byte); a line of no pixels is a 32-byte frame, not a short one.
    #[test]
    fn a_scan_line_header_round_trips_with_every_byte_set() {
        let h = ScanLineHeader {
            scan: 0x0403_0201,
            line: 0x0807_0605,
            xres: 2,
            yres: 0x0c0b_0a09,
            y: -1.234_567_890_123e-5,
        };
        let f = h.encode(&[-0.5, 7.25]);
        assert_eq!(ScanLineHeader::decode(&f).unwrap(), (h, vec![-0.5, 7.25]));
        let empty = ScanLineHeader { xres: 0, ..h };
        let f = empty.encode(&[]);
        assert_eq!(f.len(), SCAN_LINE_HEADER_LEN);
        assert_eq!(ScanLineHeader::decode(&f).unwrap(), (empty, vec![]));
    }
}
