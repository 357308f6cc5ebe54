//! Server → client: the JSON text messages the server sends (replies, events, telemetry).

use serde::{Deserialize, Serialize};

use super::{
    AssemblyNow, AssemblyPlan, AssemblySite, Bounds, ErrorCode, HapticScales, InstrumentInfo, Judged, ParticleNow,
    PlanMove, PushPath, Role, ScanNow, Telemetry,
};
use crate::assembly::{AssemblySummary, MoveSummary};

/// A server → client text message.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "snake_case")]
pub enum ServerMessage {
    /// First message on a connection.
    Welcome {
        /// [`super::WS_VERSION`].
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
        /// The instrument behind the server and what it offers.
        #[serde(default)]
        instrument: InstrumentInfo,
        /// This run of the server: a client that reconnects and finds another knows the
        /// server restarted (a push it saw running ended unrecorded, or in a record).
        instance: String,
        /// When this run of the server started (ms since the Unix epoch).
        started_unix_ms: u64,
        /// A push's `tolerance_nm` as the server checks it: its default and allowed range
        /// ([`Bounds::PUSH_TOLERANCE_NM`]), so that a client's form starts at the default and
        /// refuses what the server would.
        push_tolerance_nm: Bounds,
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
        /// The assembly running, if any (older servers leave it out).
        #[serde(default)]
        assembly: Option<AssemblyNow>,
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
    /// An assembly's first full frame was taken and its first plan made (to everyone).
    AssemblyPlanned {
        /// Its number (per server run).
        assembly: u64,
        /// The client that commanded it.
        by: u32,
        /// Whether it only plans (`assembly_done` follows at once, nothing moves).
        plan_only: bool,
        /// The pattern's name.
        pattern: String,
        /// The pattern's sites.
        sites: Vec<AssemblySite>,
        /// The plan.
        plan: AssemblyPlan,
        /// The scan record of the full frame it was planned on (none for `plan_only`, or when it
        /// could not be written): the server takes it without streaming it.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        frame: Option<String>,
    },
    /// A move of an assembly starts (to everyone); its pushes follow as `push_started`, its end
    /// as `run_done`.
    AssemblyMoveStarted {
        /// The assembly.
        assembly: u64,
        /// The move's number, from 1.
        number: usize,
        /// Moves planned in all, those made included.
        of: usize,
        /// The move as planned.
        planned: PlanMove,
        /// The particle's scene id.
        particle_id: u32,
    },
    /// A move of an assembly ended, judged by the scan after it (to everyone).
    AssemblyMoveEnded {
        /// The assembly.
        assembly: u64,
        /// The move's number.
        number: usize,
        /// What it ended with.
        made: MoveSummary,
    },
    /// A site holds its particle, as the scan after the move shows (to everyone).
    AssemblySiteFilled {
        /// The assembly.
        assembly: u64,
        /// The site (its index in the pattern).
        site: usize,
    },
    /// The rest of an assembly, planned again from the map the move's scans updated (to
    /// everyone).
    AssemblyReplanned {
        /// The assembly.
        assembly: u64,
        /// The plan.
        plan: AssemblyPlan,
    },
    /// An assembly ended (to everyone).
    AssemblyDone {
        /// The assembly.
        assembly: u64,
        /// `filled`, `incomplete`, `refused` (before anything moved), `stopped`, or `planned`
        /// (a `plan_only` one).
        outcome: String,
        /// Why it was refused or stopped.
        reason: Option<String>,
        /// The report, as `nanopush assemble` writes it (null for `planned`).
        summary: Option<AssemblySummary>,
        /// Its record under `/api/records` (null for `planned`, or when none could be written).
        record: Option<String>,
        /// Why no record was written, when one was not.
        #[serde(default)]
        record_error: Option<String>,
    },
    /// The server is shutting down; the connection closes next.
    Shutdown {
        /// Why.
        reason: String,
    },
}

#[cfg(test)]
mod tests {
    use super::*;

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
            strategy: Some(Box::new(crate::ws::ChosenStrategy {
                summary: "β = 30°, read on the pull side, xy control, 1 µm/s, pushes of at most 20 µm: why".into(),
                tried: vec!["β = 45°, push side: unreadable".into()],
            })),
        };
        let s = serde_json::to_value(ServerMessage::PushStarted(path.clone())).unwrap();
        assert_eq!(s["attempt"], 2);
        assert_eq!(s["strategy"]["tried"][0], "β = 45°, push side: unreadable");
        assert!(s["strategy"]["summary"].as_str().unwrap().contains("pull side"));
        let old: PushPath = serde_json::from_str(r#"{"particle":1,"path":[],"by":1,"run":1}"#).unwrap();
        assert_eq!((old.attempt, old.strategy), (1, None));
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
            assembly: None,
        })
        .unwrap();
        assert_eq!(s["type"], "state");
        assert_eq!(s["lease_name"], "alice");
        assert_eq!(s["particles"][0]["radius"], 5e-7);
        assert_eq!(s["push"]["path"][1][0], 3e-6);
        assert!(s["scan"].is_null());
        assert!(s["assembly"].is_null());
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
    fn assembly_events_carry_their_type_and_the_plan() {
        let plan = AssemblyPlan {
            map: vec![crate::ws::MapParticle {
                x: 1e-6,
                y: 2e-6,
                radius: 5e-7,
            }],
            sites: vec![crate::ws::PlanSite {
                state: "planned".into(),
                particle: Some(0),
                status: None,
                reason: None,
            }],
            moves: vec![PlanMove {
                purpose: "fill".into(),
                site: Some(0),
                particle: 0,
                from: [1e-6, 2e-6],
                to: [4e-6, 2e-6],
                path: vec![[1e-6, 2e-6], [4e-6, 2e-6]],
            }],
        };
        let s = serde_json::to_value(ServerMessage::AssemblyPlanned {
            assembly: 1,
            by: 2,
            plan_only: true,
            pattern: "sites".into(),
            sites: vec![AssemblySite {
                target: [4e-6, 2e-6],
                tolerance: 25e-9,
            }],
            plan: plan.clone(),
            frame: None,
        })
        .unwrap();
        assert_eq!(s["type"], "assembly_planned");
        assert!(s.get("frame").is_none(), "{s}");
        assert_eq!(s["plan"]["moves"][0]["path"][1][0], 4e-6);
        assert_eq!(s["plan"]["sites"][0]["state"], "planned");
        assert!(s["plan"]["sites"][0].get("reason").is_none(), "{s}");
        let back: ServerMessage = serde_json::from_value(s).unwrap();
        assert!(matches!(back, ServerMessage::AssemblyPlanned { plan: p, .. } if p == plan));
        let s = serde_json::to_value(ServerMessage::AssemblyDone {
            assembly: 1,
            outcome: "stopped".into(),
            reason: Some("stopped: stop requested by the operator".into()),
            summary: None,
            record: Some("assembly-1.json".into()),
            record_error: None,
        })
        .unwrap();
        assert_eq!(s["type"], "assembly_done");
        assert_eq!(s["outcome"], "stopped");
        // A state from an older server, without the key, reads as no assembly.
        let old =
            r#"{"type":"state","particles":[],"stage":[0,0,0],"phase":"idle","lease":null,"push":null,"scan":null}"#;
        assert!(matches!(
            serde_json::from_str::<ServerMessage>(old).unwrap(),
            ServerMessage::State { assembly: None, .. }
        ));
    }
}
