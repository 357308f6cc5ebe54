//! The haptic link as the network side sees it: the `haptic` command's checks, the `haptic`
//! object of `/api/status`, and the `haptic` object of telemetry — all read from the atomics the
//! control loop writes ([`HapticMetrics`]).

use std::sync::atomic::Ordering::Relaxed;

use nanopush_proto::ws::{ErrorCode, HapticAction};

use super::HapticMetrics;
use crate::command_checks::{Refusal, number};
use nanopush_proto::haptic::DeviceFaults;
use nanopush_proto::haptic::region::{Limit, limit_force_gain};
use nanopush_proto::ws::HapticScales;

/// What the lease holder asks of haptic z-control.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum HapticCommand {
    /// Approach, park, and give z to the hand.
    Engage,
    /// Park the tip and let the handle go.
    Release,
    /// Re-centre the handle: the tip stays, the hand gets its travel back.
    Recenter,
    /// New scales (each only when given).
    Scale {
        /// Tip metres per handle metre.
        position_gain: Option<f64>,
        /// Hand newtons per tip newton.
        force_gain: Option<f64>,
    },
}

/// The haptic handle for telemetry; `None` without a haptic link.
pub fn haptic_telemetry(h: &HapticMetrics) -> Option<nanopush_proto::ws::HapticTelemetry> {
    if !h.enabled.load(Relaxed) {
        return None;
    }
    Some(nanopush_proto::ws::HapticTelemetry {
        link: h.link_name().into(),
        phase: h.phase_name().into(),
        handle_m: h.live().then(|| h.handle_m()),
        force_n: h.live().then(|| h.force_n()),
        tip_force_n: h.tip_force_n(),
        pc_active: h.pc_active(),
        scales: h.scales.snapshot(),
    })
}

/// The haptic link for `/api/status`: link `up`/`down`/`off`, the device, the z-control phase,
/// the handle and the force at the hand, the bridge's restarts and dropped samples, and the
/// passivity controller's activity.
pub fn haptic_status(h: &HapticMetrics) -> serde_json::Value {
    let link = h.link_name();
    let sampled = h.samples.load(Relaxed) > 0;
    let noted = h.device_noted.load(Relaxed);
    let num = |v: f64| (sampled && v.is_finite()).then_some(v);
    serde_json::json!({
        "link": link,
        "device": sampled.then(|| nanopush_proto::haptic::device_name(h.device.load(Relaxed) as u32)),
        "pid": sampled.then(|| h.pid.load(Relaxed)),
        "engaged": h.phase_name() != "off",
        "phase": h.phase_name(),
        "handle_m": num(h.live_handle_m()),
        "force_n": num(h.live_force_n()),
        "restarts": h.restarts.load(Relaxed),
        "dropped_samples": h.dropped_samples.load(Relaxed),
        "rejected_samples": h.rejected_samples.load(Relaxed),
        "link_downs": h.link_downs.load(Relaxed),
        "tip_z_m": h.tip_z_m().is_finite().then(|| h.tip_z_m()),
        "fault": (h.fault_name() != "none").then(|| h.fault_name()),
        "pc_active": h.pc_active(),
        "pc_damping": num(h.pc_damping()),
        "port_energy_j": num(h.port_energy()),
        "raw_port_energy_j": num(h.raw_port_energy()),
        "stored_energy_bound_j": h.stored_energy_bound(),
        "energy_bounds": h.energy_bounds.load(Relaxed),
        "scales": h.scales.snapshot(),
        "latency_p99_bound_s": (h.latency.count() > 0).then(|| h.latency.quantile_bound(0.99)),
        "rate_hz": noted.then(|| f64::from_bits(h.rate_hz.load(Relaxed))),
        "device_faults": noted.then(|| device_faults(h)),
    })
}

/// The bridge's device fault counters, by name (as the bridge's `--json` has them), and the
/// side at fault of each.
fn device_faults(h: &HapticMetrics) -> serde_json::Value {
    let mut counts = serde_json::Map::new();
    let mut sides = serde_json::Map::new();
    for ((name, side), n) in DeviceFaults::KINDS.iter().zip(&h.device_faults) {
        counts.insert((*name).into(), n.load(Relaxed).into());
        sides.insert((*name).into(), (*side).into());
    }
    counts.insert("side".into(), sides.into());
    counts.into()
}

/// The scales a `scale` of `nm_per_mm` and/or `pull_off_at_hand_n` (the other as now) puts in
/// force, for a lever of `k_lever` (N/m) and a pull-off of `adhesion` (N): the force scale
/// lowered to the device's renderable region's edge when past it (the region as the loop last
/// computed it for the device on the link), and why. Before a device is known the asked scales
/// are shown; the loop limits them once one is. A scale omitted is the one the previous accepted
/// `scale` asked for (the loop may not have taken it yet: a burst), else the one in force; call
/// it once per accepted `scale`, as it records what this one asks for.
pub fn scales_in_force(
    h: &HapticMetrics,
    k_lever: f64,
    adhesion: f64,
    nm_per_mm: Option<f64>,
    pull_off_at_hand_n: Option<f64>,
) -> HapticScales {
    let now = h.scales.snapshot();
    let (nm_per_mm, asked) = {
        let mut last = h.asked_scales.lock().unwrap_or_else(|e| e.into_inner());
        let (nm_before, asked_before) = last.unwrap_or((now.nm_per_mm, now.asked_pull_off_at_hand_n));
        let asked = (
            nm_per_mm.unwrap_or(nm_before),
            pull_off_at_hand_n.unwrap_or(asked_before),
        );
        *last = Some(asked);
        asked
    };
    let adhesion = adhesion.max(1e-12);
    let g_p = nm_per_mm * 1e-9 / 1e-3;
    let (g_f, limit) = match now.max_stiffness_n_per_m {
        Some(k_max) => limit_force_gain(asked / adhesion, g_p, k_lever, k_max),
        None => (asked / adhesion, Limit::None),
    };
    HapticScales {
        nm_per_mm,
        pull_off_at_hand_n: g_f * adhesion,
        asked_pull_off_at_hand_n: asked,
        felt_stiffness_n_per_m: g_f * k_lever * g_p,
        limit: limit.name().into(),
        reason: (limit != Limit::None).then(|| limit.reason().into()),
        ..now
    }
}

/// A `haptic` command, checked against the link's state (`h`), whether a push runs (`busy`)
/// and the tip-sample pull-off force (`adhesion`, N); the control loop carries it out.
pub fn haptic_command(
    h: &HapticMetrics,
    busy: bool,
    adhesion: f64,
    action: HapticAction,
    nm_per_mm: Option<f64>,
    pull_off_at_hand_n: Option<f64>,
) -> Result<HapticCommand, Refusal> {
    let cmd = match action {
        HapticAction::Engage | HapticAction::Recenter => {
            if !h.enabled.load(Relaxed) {
                return Err(Refusal::new(
                    ErrorCode::Unavailable,
                    "this server runs without a haptic link (start it with --haptic sim or --haptic external)",
                ));
            }
            if h.link_name() != "up" {
                return Err(Refusal::new(
                    ErrorCode::Unavailable,
                    "the haptic link is down: no handle samples from nanopush-haptic",
                ));
            }
            if action == HapticAction::Engage {
                if busy {
                    return Err(Refusal::new(
                        ErrorCode::Busy,
                        "a push is running (it owns z); engage haptic z-control after it",
                    ));
                }
                HapticCommand::Engage
            } else {
                HapticCommand::Recenter
            }
        }
        HapticAction::Release => HapticCommand::Release,
        HapticAction::Scale => {
            if nm_per_mm.is_none() && pull_off_at_hand_n.is_none() {
                return Err(Refusal::new(
                    ErrorCode::Invalid,
                    "scale needs nm_per_mm and/or pull_off_at_hand_n",
                ));
            }
            let position_gain = nm_per_mm
                .map(|v| number("nm_per_mm", v, 0.01, 1000.0, false, "nm/mm"))
                .transpose()?
                .map(|v| v * 1e-9 / 1e-3);
            let adhesion = adhesion.max(1e-12);
            let force_gain = pull_off_at_hand_n
                .map(|v| number("pull_off_at_hand_n", v, 0.01, 10.0, false, "N"))
                .transpose()?
                .map(|v| v / adhesion);
            HapticCommand::Scale {
                position_gain,
                force_gain,
            }
        }
    };
    Ok(cmd)
}

#[cfg(test)]
mod tests {
    use super::*;
    use nanopush_instrument::control::bilateral::Coupling;
    use nanopush_instrument::scene::Scene;
    use nanopush_proto::haptic::HapticState;

    /// Once the link is down the handle and the hand's force are unknown (the bridge may be
    /// dead, the device may hold what it last had): `null` in `/api/status` and telemetry, NaN in
    /// `/metrics`, not the last sample's values as if they were live.
    #[test]
    fn a_link_that_is_down_reports_the_hand_as_unknown() {
        let h = HapticMetrics::default();
        h.enabled.store(true, Relaxed);
        let state = HapticState {
            position: 0.01,
            force: 0.7,
            ..HapticState::default()
        };
        h.sample(&state, 1);
        h.link.store(super::super::link::LINK_UP, Relaxed);
        let s = haptic_status(&h);
        assert_eq!(s["force_n"], 0.7);
        assert_eq!(s["handle_m"], 0.01);
        h.link.store(super::super::link::LINK_DOWN, Relaxed);
        let s = haptic_status(&h);
        assert!(s["force_n"].is_null() && s["handle_m"].is_null(), "{s}");
        let t = haptic_telemetry(&h).unwrap();
        assert_eq!((t.force_n, t.handle_m), (None, None));
        assert!(h.live_force_n().is_nan() && h.live_handle_m().is_nan());
    }

    /// The `ok` of a `scale`: before a device is known the asked scales; with the simulated
    /// device (2 kN/m) the default 10 nm/mm and 1 N as asked, 10 N lowered to the edge with the
    /// reason, and the status's scales are those the loop put in force.
    #[test]
    fn a_scale_is_answered_with_the_scales_in_force_and_the_reason() {
        let scene = Scene::default_scene();
        let (k_z, adhesion) = (scene.tip_sample().k_c, scene.tip_sample().adhesion());
        let h = HapticMetrics::default();
        let s = scales_in_force(&h, k_z, adhesion, Some(10.0), Some(10.0));
        assert_eq!(
            (s.limit.as_str(), s.pull_off_at_hand_n, s.max_stiffness_n_per_m),
            ("none", 10.0, None)
        );
        let p = scene.bilateral_params(1e-3);
        let mut c = Coupling::new(1e-3);
        let handle = sim_handle();
        c.update(&p, Some(&handle), true);
        h.note_scales(&p, &c);
        let now = h.scales.snapshot();
        assert_eq!((now.limit.as_str(), now.nm_per_mm), ("none", 10.0));
        assert!((now.pull_off_at_hand_n - 1.0).abs() < 1e-12, "{now:?}");
        let ten = scales_in_force(&h, k_z, adhesion, None, Some(10.0));
        assert_eq!(ten.limit, "renderable_region");
        assert!(ten.reason.as_deref().is_some_and(|r| r.contains("Z-width")));
        assert!((ten.felt_stiffness_n_per_m - 2000.0).abs() < 1e-6, "{ten:?}");
        assert!(
            ten.pull_off_at_hand_n < 1.4 && ten.asked_pull_off_at_hand_n == 10.0,
            "{ten:?}"
        );
        let one = scales_in_force(&h, k_z, adhesion, Some(10.0), Some(1.0));
        assert_eq!((one.limit.as_str(), one.reason), ("none", None));
    }

    /// A sample of the simulated device (2 kN/m at 1 kHz) with one tick of round trip.
    fn sim_handle() -> HapticState {
        HapticState {
            max_force: 2.5,
            max_stiffness: 2000.0,
            spec_rate_hz: 1000.0,
            rate_hz: 1000.0,
            latency_ns: 1_000_000,
            ..HapticState::default()
        }
    }

    /// A burst of `scale`s answered before the loop takes the first: each `ok` builds on the
    /// scales the previous one asked for, not on those the loop still has in force (a scale of
    /// 1000 nm/mm and 10 N, then 10 nm/mm, then 1 N is 10 nm/mm and 1 N, as asked, in force).
    #[test]
    fn a_burst_of_scales_builds_on_the_last_one_asked() {
        let scene = Scene::default_scene();
        let (k_z, adhesion) = (scene.tip_sample().k_c, scene.tip_sample().adhesion());
        let h = HapticMetrics::default();
        let p = scene.bilateral_params(1e-3);
        let mut c = Coupling::new(1e-3);
        let handle = sim_handle();
        c.update(&p, Some(&handle), true);
        h.note_scales(&p, &c);
        scales_in_force(&h, k_z, adhesion, Some(1000.0), Some(10.0));
        let nm = scales_in_force(&h, k_z, adhesion, Some(10.0), None);
        assert_eq!((nm.nm_per_mm, nm.asked_pull_off_at_hand_n), (10.0, 10.0), "{nm:?}");
        let one = scales_in_force(&h, k_z, adhesion, None, Some(1.0));
        assert_eq!((one.nm_per_mm, one.asked_pull_off_at_hand_n), (10.0, 1.0), "{one:?}");
        assert_eq!((one.limit.as_str(), one.reason.as_deref()), ("none", None), "{one:?}");
    }
}
