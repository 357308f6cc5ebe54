//! Client → server: the commands a client sends, each a JSON object with a `type` (and an
//! optional `id` its reply echoes), and the streams it subscribes to. The rules every command
//! follows (unknown fields, keys given twice, units) are in `proto/README.md`; each command is
//! here:
//!
//! | type | fields | needs | reply |
//! |---|---|---|---|
//! | `subscribe` | `streams`: subset of `["tip", "scan"]` | — | `ok` |
//! | `take_lease` | — | operator | `ok`, or `lease_held` / `forbidden` |
//! | `release_lease` | — | the lease | `ok` |
//! | `push` | `particle` (id); either `distance_um` (0, stage range] with `direction_deg` [-360, 360], or `to_x_um`, `to_y_um` in [0, stage range] (the scene's `stage.range_um`, 100 µm in the shipped scenes); optional `tolerance_nm` [1, 100000], default 25 (`push::TOLERANCE_RANGE_NM`, `push::TOLERANCE_NM`; `welcome` says both): the move is `ok` only when the scan after it finds the particle that close to the target | the lease | `ok` when started; a `push_started` for each push of the move (corrections included); `run_done` at the end |
//! | `scan` | optional `centre_x_um`, `centre_y_um`, `size_um` [0.01, stage range], `pixels` [8, 512]; the square must lie within the stage | the lease | `ok`; then `scan_start`, lines, `scan_done` |
//! | `assemble` | either `sites`: 1 to 400 of `{x_um, y_um, tolerance_nm?}` (x, y in [0, stage range]), or `generator`: a pattern generator's text, at most 200 characters (`line:n=5,spacing_um=4`, `grid:rows=3,cols=3,spacing_um=4`, `ring:n=8,radius_um=6`, `text:NP,pitch_um=3`, as `nanopush assemble --pattern` takes them) centred at `at_x_um`, `at_y_um` in [0, stage range] (default the stage's centre; with `generator` only); optional `tolerance_nm` [1, 100000], default 25: a site's tolerance where it gives none; optional `plan_only` (default false): plan and say so, move nothing | the lease; nothing running | `ok` when started; `assembly_planned`, then per move `assembly_move_started`, `push_started` (each push), `run_done`, `assembly_move_ended`, `assembly_site_filled` (when it fills one), `assembly_replanned`; `assembly_done` at the end (`outcome` `planned` for `plan_only`) |
//! | `stop` | — | the lease | `ok`; the tip retracts; a running assembly ends `stopped` |
//! | `haptic` | `action`: `engage` (approach, park, give z to the handle), `release` (park, let the handle go), `recenter` (re-centre the handle, the tip stays), `scale` with `nm_per_mm` [0.01, 1000] and/or `pull_off_at_hand_n` [0.01, 10] | the lease; `engage`/`recenter` a live haptic link | `ok` (for `scale` with `scales`: the scales that will be in force, lowered to the device's renderable region when past it, and why — `HapticScales`), or `unavailable` (no link: `--haptic none`, or no handle samples) |
//! | `ping` | — | — | `ok` |
//! | `ack` | `seq`: the newest `telemetry` frame the client has read (its `seq`; acknowledgements are cumulative) | — | none: the one message not answered `ok` (an `error` when `seq` is not a frame sent to this client). The first `ack` bounds what is in flight to the client from then on: no more frames than it reads in half a second (2 at least), the newest sent once it has read the older. Acknowledge each frame read (up to twice the telemetry rate a second, a budget apart from `--max-rate`), or the newest every ~100 ms and at least before waiting for more (the page does so): no frame comes while the window is full |
//!
//! The server's table of commands (`server/src/session/commands`) gives each its handler and
//! who may send it; its tests check this table's `needs` against it.

use serde::{Deserialize, Serialize};

/// The streams a client can subscribe to. Nothing is produced for a stream no client wants.
/// Read from its name only (a derived reader would also take `{"tip": null}`).
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
    /// Push particles into a pattern: the sites given, or a generator's (one of the two). A full
    /// frame finds the particles, the plan assigns them to sites and routes them, each move is a
    /// push judged by the scan after it, and the rest is planned again after each. Needs the
    /// lease, and nothing else running.
    Assemble {
        /// Command id.
        #[serde(default)]
        id: Option<u32>,
        /// The sites, each with its own tolerance or none; instead of `generator`.
        #[serde(default)]
        sites: Option<Vec<SiteUm>>,
        /// A pattern generator's text (`ring:n=8,radius_um=6`); instead of `sites`.
        #[serde(default)]
        generator: Option<String>,
        /// The generator's centre x (µm), with `at_y_um`; the stage's centre when left out.
        #[serde(default)]
        at_x_um: Option<f64>,
        /// The generator's centre y (µm).
        #[serde(default)]
        at_y_um: Option<f64>,
        /// A site's tolerance where the site gives none (nm); [`crate::push::TOLERANCE_NM`] when
        /// left out, within [`crate::push::TOLERANCE_RANGE_NM`].
        #[serde(default)]
        tolerance_nm: Option<f64>,
        /// Plan only: the first full frame and the plan, said in `assembly_planned`; nothing
        /// moves.
        #[serde(default)]
        plan_only: bool,
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
    /// The newest telemetry frame the client has read: the server keeps in flight to it no more
    /// frames than it reads in half a second. Not answered (an `error` when `seq` was not sent to
    /// this client).
    Ack {
        /// The frame's `seq`.
        seq: u64,
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

/// One site of an `assemble` command, in the protocol's units.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SiteUm {
    /// Centre x (µm), in [0, stage range].
    pub x_um: f64,
    /// Centre y (µm), in [0, stage range].
    pub y_um: f64,
    /// How close a particle's centre must come to fill it (nm), in
    /// [`crate::push::TOLERANCE_RANGE_NM`]; the command's `tolerance_nm` when left out.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tolerance_nm: Option<f64>,
}

/// The most sites an `assemble` command may give (as a pattern file may).
pub const ASSEMBLE_MAX_SITES: usize = 400;

/// The longest `generator` text an `assemble` command may give (characters).
pub const ASSEMBLE_MAX_GENERATOR: usize = 200;

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
            | ClientMessage::Assemble { id, .. }
            | ClientMessage::Stop { id }
            | ClientMessage::Ping { id }
            | ClientMessage::Haptic { id, .. } => *id,
            ClientMessage::Ack { .. } => None,
        }
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
        assert_eq!(
            serde_json::from_str::<ClientMessage>(r#"{"type":"ack","seq":1234}"#).unwrap(),
            ClientMessage::Ack { seq: 1234 }
        );
        assert!(serde_json::from_str::<ClientMessage>(r#"{"type":"ack","seq":-1}"#).is_err());
        assert!(serde_json::from_str::<ClientMessage>(r#"{"type":"ack","seq":1,"id":2}"#).is_err());
        assert!(serde_json::from_str::<ClientMessage>(r#"{"type":"push","particle":1,"bogus":1}"#).is_err());
        assert!(serde_json::from_str::<ClientMessage>(r#"{"type":"fly"}"#).is_err());
    }

    /// A stream is its name; `{"tip": null}` (which a derived reader would take) and unknown
    /// names are refused, naming the streams there are.
    #[test]
    fn a_stream_is_a_name_only() {
        for bad in [r#"[{"tip":null}]"#, r#"["wind"]"#, "[1]"] {
            let e = serde_json::from_str::<Vec<Stream>>(bad).unwrap_err().to_string();
            assert!(e.contains("\"tip\"") && e.contains("\"scan\""), "{bad}: {e}");
        }
        assert_eq!(serde_json::to_string(&Stream::Scan).unwrap(), "\"scan\"");
    }

    #[test]
    fn the_assemble_command_parses_sites_or_a_generator() {
        let m: ClientMessage = serde_json::from_str(
            r#"{"type":"assemble","id":3,"sites":[{"x_um":40,"y_um":41.5},{"x_um":44,"y_um":41.5,"tolerance_nm":50}]}"#,
        )
        .unwrap();
        assert_eq!(m.id(), Some(3));
        let ClientMessage::Assemble {
            sites: Some(sites),
            generator: None,
            plan_only: false,
            ..
        } = m
        else {
            panic!("{m:?}")
        };
        assert_eq!(sites[1].tolerance_nm, Some(50.0));
        let m: ClientMessage = serde_json::from_str(
            r#"{"type":"assemble","generator":"ring:n=8,radius_um=6","at_x_um":50,"at_y_um":50,"plan_only":true}"#,
        )
        .unwrap();
        assert!(
            matches!(m, ClientMessage::Assemble { plan_only: true, generator: Some(ref g), .. } if g == "ring:n=8,radius_um=6")
        );
        // A site takes its three fields only; the command its own.
        assert!(
            serde_json::from_str::<ClientMessage>(r#"{"type":"assemble","sites":[{"x_um":1,"y_um":1,"z_um":0}]}"#)
                .is_err()
        );
        assert!(serde_json::from_str::<ClientMessage>(r#"{"type":"assemble","pattern":"ring"}"#).is_err());
        assert!(serde_json::from_str::<ClientMessage>(r#"{"type":"assemble","plan_only":"yes"}"#).is_err());
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
}
