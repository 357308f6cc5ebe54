//! The data the messages of both directions share: roles, error codes, telemetry, particles,
//! pushes, judged moves, scans, assemblies and the haptic scales (SI unless a name says
//! otherwise).

use serde::{Deserialize, Serialize};

use crate::assembly::MoveSummary;
use crate::push::{TOLERANCE_NM, TOLERANCE_RANGE_NM};

/// A number a command takes, as the server checks it: its default when left out and its allowed
/// range, `[min, max]`, in the unit its name says.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Bounds {
    /// Taken when the field is left out.
    pub default: f64,
    /// The least allowed.
    pub min: f64,
    /// The most allowed.
    pub max: f64,
}

impl Bounds {
    /// A push's `tolerance_nm`: [`TOLERANCE_NM`] within [`TOLERANCE_RANGE_NM`].
    pub const PUSH_TOLERANCE_NM: Bounds = Bounds {
        default: TOLERANCE_NM,
        min: TOLERANCE_RANGE_NM.0,
        max: TOLERANCE_RANGE_NM.1,
    };
}

/// A client's role, from its token.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
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
    /// The request is inconsistent (both a distance and a target, say; both sites and a
    /// generator; a generator that is not one).
    Invalid,
    /// The server is shutting down.
    ShuttingDown,
    /// What the command needs is not there (the haptic link is off or down).
    Unavailable,
}

/// The instrument the server drives, as its backend reports it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct InstrumentInfo {
    /// Which backend, for people: `simulated AFM`, or `Nanonis HOST:PORT`.
    pub backend: String,
    /// How often it delivers a new reading (Hz): the rate telemetry's values really change at.
    pub feed_rate_hz: f64,
    /// The controller holds the normal force with its own Z feedback.
    pub z_closed_locally: bool,
    /// Nothing that moves the tip or changes Z is sent.
    pub read_only: bool,
    /// What the page can do with it: `push`, `scan`, `assemble`, `haptic`.
    pub offers: Vec<String>,
}

impl Default for InstrumentInfo {
    /// The simulated AFM at the paper's 1 kHz, offering everything.
    fn default() -> InstrumentInfo {
        InstrumentInfo {
            backend: "simulated AFM".into(),
            feed_rate_hz: 1000.0,
            z_closed_locally: false,
            read_only: false,
            offers: ["push", "scan", "assemble", "haptic"].map(String::from).to_vec(),
        }
    }
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
    /// The strategy the plan chose for this particle and why, on the first push of a move (none
    /// on a correction, and from older servers).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub strategy: Option<Box<ChosenStrategy>>,
}

/// The strategy a plan chose, in words.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ChosenStrategy {
    /// One line: the contact angle, the side the contact is read on, the loop closure, the
    /// speed, the longest push, and why.
    pub summary: String,
    /// What the plan tried before it and why each was not taken, a line each (at most 16).
    #[serde(default)]
    pub tried: Vec<String>,
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

/// One site of an assembly's pattern (SI).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct AssemblySite {
    /// Its centre (m).
    pub target: [f64; 2],
    /// How close a particle's centre must come to fill it (m).
    pub tolerance: f64,
}

/// A particle as an assembly's scans show it (SI): the plan names particles by their index in
/// the map.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct MapParticle {
    /// Centre x (m).
    pub x: f64,
    /// Centre y (m).
    pub y: f64,
    /// Radius (m).
    pub radius: f64,
}

/// What a plan says of one site.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PlanSite {
    /// `filled` (a particle is on it already), `planned` (a move of the plan fills it) or
    /// `open` (it stays open: `status` and `reason` say why).
    pub state: String,
    /// The particle on it or sent to it (its index in the plan's `map`).
    pub particle: Option<usize>,
    /// For an open site: `unreachable`, `refused` or `missed`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub status: Option<String>,
    /// For an open site: why, in words.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reason: Option<String>,
}

/// One move of a plan (SI).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PlanMove {
    /// `fill` (a site), `clear` (a particle the pattern does not need, out of the way) or
    /// `park` (a particle to place later, aside for now).
    pub purpose: String,
    /// The site it fills.
    pub site: Option<usize>,
    /// The particle (its index in the plan's `map`).
    pub particle: usize,
    /// Where the particle is (m).
    pub from: [f64; 2],
    /// Where it goes (m).
    pub to: [f64; 2],
    /// The path of its centre: `from`, then the end of each straight push (m).
    pub path: Vec<[f64; 2]>,
}

/// An assembly's plan as it stands (SI).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AssemblyPlan {
    /// Every particle as the scans last showed it.
    pub map: Vec<MapParticle>,
    /// Each site, in the pattern's order.
    pub sites: Vec<PlanSite>,
    /// The moves still to make, in order.
    pub moves: Vec<PlanMove>,
}

/// The assembly running now, for a client that joins during it (SI).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AssemblyNow {
    /// Its number (per server run), as its events and its record say.
    pub assembly: u64,
    /// The client that commanded it.
    pub by: u32,
    /// Whether it only plans.
    pub plan_only: bool,
    /// The pattern's name (the generator's text, or `sites`).
    pub pattern: String,
    /// The pattern's sites.
    pub sites: Vec<AssemblySite>,
    /// `planning` (the first full frame and plan), `moving` (a move runs), `replanning` (after
    /// a move) or `judging` (the last full frame).
    pub phase: String,
    /// The plan as it stands; null before the first.
    pub plan: Option<AssemblyPlan>,
    /// Each move made so far, in order.
    pub moves: Vec<MoveSummary>,
    /// The sites filled so far, as the scans after the moves showed them.
    pub filled: Vec<usize>,
    /// The move running: its number, from 1, and the moves planned in all (those made
    /// included).
    pub moving: Option<[usize; 2]>,
}
