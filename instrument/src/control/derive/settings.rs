//! The settings that follow from the contact angle's predicted push: one function per setting,
//! run in the order of [`SETTINGS`], each reading what the ones before it settled. The rule of
//! each is the module doc's of [`super`]; each records its [`Choice`] with the reason.

use super::{
    BACK_OFF, Candidate, Derivation, Fails, MAX_START, MAX_TIMEOUT, PAPER_SPEED, PEAK_SPARE, SET_FRACTION, TICK,
};
use super::{BETAS_DEG, Choice, DerivedStrategy, Refusal, short};
use crate::control::estimator::{ContactSide, PushPrediction};
use crate::control::moves::locate::{LOCAL_PIXELS, local_scan_size};
use crate::control::strategy::pull_off::pull_off_rise;
use crate::scene::Scene;
use crate::scene::file::StrategyFile;

use super::adhesion_field::{Pair, field as adhesion_field};

/// What the settings before give the ones after (SI), and what they start from.
struct Settled {
    cand: Candidate,
    r_a: f64,
    r_t: f64,
    /// The contact angle (rad).
    beta: f64,
    /// The z approach's speed (m/s).
    approach_speed: f64,
    /// The push's speed (µm/s, as chosen).
    speed_um: f64,
    /// The local scan's size and pixel pitch (m).
    scan: f64,
    pitch: f64,
    step: f64,
    approach: f64,
    search: f64,
    start: f64,
    max_push: f64,
    /// The longest push was cut to what a dry run kept the particle for.
    shortened: bool,
}

/// Ticks of the z approach the lever may take up before auto-parking reads the touch: the
/// touch falls between two readings, and the next may come a tick later.
const TOUCH_TICKS: f64 = 1.5;

/// One setting: records its choice (or refuses the scene) from what is settled so far.
type Setting = fn(&mut Derivation, &mut Settled) -> Result<(), Refusal>;

/// Every setting, in the order each needs the ones before it (and the order `nanopush plan`
/// prints them).
const SETTINGS: [Setting; 18] = [
    contact_angle,
    set_point,
    safety_limit,
    lost_threshold,
    speed,
    local_scan,
    step,
    approach_distance,
    search_range,
    start_height,
    approach_speed,
    travel_speed,
    dwell,
    follow_slope,
    max_push,
    clearance,
    z_gain,
    phase_timeout,
];

impl Derivation<'_> {
    /// Every setting that follows from the contact angle's predicted push ([`SETTINGS`]), the
    /// warnings the tolerance calls for, and the strategy they make.
    pub(super) fn settings(
        &mut self,
        cand: Candidate,
        r_a: f64,
        r_t: f64,
        approach_speed: f64,
    ) -> Result<DerivedStrategy, Refusal> {
        let mut s = Settled {
            cand,
            r_a,
            r_t,
            beta: cand.beta_deg.to_radians(),
            approach_speed,
            speed_um: 0.0,
            scan: 0.0,
            pitch: 0.0,
            step: 0.0,
            approach: 0.0,
            search: 0.0,
            start: 0.0,
            max_push: 0.0,
            shortened: false,
        };
        for setting in SETTINGS {
            setting(self, &mut s)?;
        }
        self.tolerance_warnings(&cand.prediction, s.pitch);
        self.file = resolved(self.scene, &self.choices);
        Ok(DerivedStrategy {
            particle: self.part.id,
            tolerance: self.tolerance,
            choices: self.choices.clone(),
            warnings: self.warnings.clone(),
            strategy: self.file.clone(),
            contact_angle_deg: cand.beta_deg,
            speed_um_per_s: s.speed_um,
            local_scan: (s.scan, LOCAL_PIXELS),
            prediction: cand.prediction,
            tried: self.tried.clone(),
            shortened: s.shortened,
            dry_run_passed: false,
        })
    }

    /// A setting the model does not change, said with its reason.
    fn fixed(&mut self, key: &'static str, value: f64, why: &str) {
        self.choose(key, value, value, why.into(), None);
    }

    /// What the tolerance asks that the instrument may not give: said, not refused (the scan
    /// after the push judges).
    fn tolerance_warnings(&mut self, p: &PushPrediction, pitch: f64) {
        if p.periodic_amplitude > self.tolerance {
            self.warnings.push(format!(
                "the model's push is stick-slip with a {:.1} nm amplitude, more than the {} nm tolerance: pushes may end outside it and be corrected",
                p.periodic_amplitude * 1e9,
                crate::words::nm_text(self.tolerance)
            ));
        }
        if pitch / 8.0 > self.tolerance {
            self.warnings.push(format!(
                "the local scan's {:.0} nm pitch is coarse for a {} nm tolerance",
                pitch * 1e9,
                crate::words::nm_text(self.tolerance)
            ));
        }
        let least = crate::control::moves::locate::DONE_WITHIN;
        if self.tolerance < least {
            self.warnings.push(format!(
                "the {} nm tolerance is below the {:.0} nm a push can correct: a move that ends between the two is missed without a correction",
                crate::words::nm_text(self.tolerance),
                least * 1e9
            ));
        }
    }
}

/// **β**: the candidate's, with why it was taken.
fn contact_angle(d: &mut Derivation, s: &mut Settled) -> Result<(), Refusal> {
    let beta_hand = d.hand("push.contact_angle_deg");
    let why = format!(
        "{}: the parking height {:.1} nm keeps the apex above the substrate, the push bends the lever {} to a stick-phase peak of {:.3} nm before t*, and every check below passes",
        if beta_hand {
            "given by the scene".to_string()
        } else {
            format!("the first of {BETAS_DEG:?}° that works")
        },
        s.cand.parking * 1e9,
        match s.cand.prediction.side {
            ContactSide::Push => "up (the push side)",
            ContactSide::Pull => "down (the pull side)",
        },
        s.cand.prediction.peak_deflection * 1e9
    );
    d.choices.push(Choice {
        key: "push.contact_angle_deg",
        value: s.cand.beta_deg,
        hand_set: beta_hand,
        why,
    });
    Ok(())
}

/// **Set point** `ζ_set = 0.6 ζ_peak`: reached before the particle moves.
fn set_point(d: &mut Derivation, s: &mut Settled) -> Result<(), Refusal> {
    let (f, ro, pred) = (&d.scene.file, d.readout, s.cand.prediction);
    let peak_v = pred.peak_deflection * ro.gain;
    let side = pred.side.sign();
    let hand_signal = (f.strategy.set_point_v - ro.baseline) * ro.sign * side;
    let check = if hand_signal >= 0.95 * peak_v {
        Some(format!(
            "{:.3} V from the baseline, at or beyond the predicted peak {:.3} V: the search pushes the particle without reaching it",
            hand_signal, peak_v
        ))
    } else if hand_signal < 5.0 * (ro.sigma + ro.pert) {
        Some(format!(
            "{hand_signal:.3} V from the baseline: within 5 × the noise, a false contact"
        ))
    } else {
        None
    };
    d.choose(
        "strategy.set_point_v",
        f.strategy.set_point_v,
        ro.volts(side * SET_FRACTION * pred.peak_deflection),
        format!(
            "{:.0} % of the stick-phase peak deflection {:.3} nm ({:.3} V from the baseline{}): reached before the particle moves, {:.0} × the noise",
            SET_FRACTION * 100.0,
            pred.peak_deflection * 1e9,
            peak_v,
            match pred.side {
                ContactSide::Push => "",
                ContactSide::Pull => {
                    ", on the pull side: at this angle the push bends the lever the way the substrate's adhesion does"
                }
            },
            SET_FRACTION * peak_v / (ro.sigma + ro.pert).max(1e-6)
        ),
        check,
    );
    Ok(())
}

/// **Safety limit**: `max(2.5 ζ_peak g, ζ_peak g + 10σ)` from the baseline, within 90 % of
/// the readout's room on the side the contact is read on, at least twice the peak.
fn safety_limit(d: &mut Derivation, s: &mut Settled) -> Result<(), Refusal> {
    let (f, ro) = (&d.scene.file, d.readout);
    let side = s.cand.prediction.side;
    let room = ro.room_on(side);
    let peak_v = s.cand.prediction.peak_deflection * ro.gain;
    // Auto-parking reads the touch of the substrate on the push side: the substrate threshold,
    // and up to a tick and a half of the approach pressed into the lever before a reading shows
    // it.
    let touch_v = match side {
        ContactSide::Push => d.substrate_threshold_v() + TOUCH_TICKS * s.approach_speed * TICK * ro.gain,
        ContactSide::Pull => 0.0,
    };
    let safety = (2.5 * peak_v)
        .max(peak_v + 10.0 * ro.sigma)
        .max(touch_v)
        .min(0.9 * room)
        .max(PEAK_SPARE * peak_v);
    let hand = (f.strategy.safety_limit_v - ro.baseline) * ro.sign * side.sign();
    let check = (hand < 1.1 * peak_v).then(|| {
        format!(
            "{hand:.3} V from the baseline, within 10 % of the predicted peak {peak_v:.3} V: an ordinary push trips it"
        )
    });
    d.choose(
        "strategy.safety_limit_v",
        f.strategy.safety_limit_v,
        ro.baseline + ro.sign * side.sign() * safety,
        format!(
            "2.5 × the peak reading {peak_v:.3} V (or the peak plus 10σ; the instrument's peak exceeds the model's where the snap-in lifts the detected substrate), above the {touch_v:.3} V auto-parking may read at the touch (the substrate threshold and {TOUCH_TICKS} ticks of the approach), within 90 % of the readout's {:.2} V on the {} side",
            room,
            side.name()
        ),
        check,
    );
    Ok(())
}

/// **Particle lost** at half the settled reading after `t*`; no test (0) when the particle
/// rolls ahead of the tip with a reading no test can tell from the baseline
/// ([`Derivation::rolls_unread`]).
fn lost_threshold(d: &mut Derivation, s: &mut Settled) -> Result<(), Refusal> {
    let f = &d.scene.file;
    let settled_v = s.cand.prediction.settled_deflection * d.readout.gain;
    if d.rolls_unread(&s.cand.prediction) {
        let check = (f.strategy.lost_threshold_mv > 0.0).then(|| {
            format!(
                "the particle rolls ahead of the tip at a settled reading of {:.1} mV: a push reads as lost",
                settled_v * 1e3
            )
        });
        // Past the baseline, the reading crosses it on the way from the peak: a test on either
        // side would fire before the push settles.
        let reading = if settled_v < 0.0 {
            format!(
                "the reading {:.1} mV, past the baseline on the other side, which it crosses from the peak on the way",
                settled_v * 1e3
            )
        } else {
            format!(
                "the reading {:.1} mV, as near the baseline as a lost particle's",
                settled_v * 1e3
            )
        };
        d.choose(
            "strategy.lost_threshold_mv",
            f.strategy.lost_threshold_mv,
            0.0,
            format!(
                "no lost-particle test: after t* the model's particle rolls on in front of the tip at its speed (its lag behind the travel settles at {:.1} nm), {reading}; the scan after the push judges it",
                s.cand.prediction.settle_offset * 1e9,
            ),
            check,
        );
        return Ok(());
    }
    let lost = settled_v / 2.0;
    let check = if f.strategy.lost_threshold_mv == 0.0 {
        Some(format!(
            "0 turns the lost-particle test off, though the model's settled reading {:.1} mV would tell a lost particle",
            settled_v * 1e3
        ))
    } else {
        (f.strategy.lost_threshold_mv * 1e-3 >= 0.9 * settled_v).then(|| {
            format!(
                "at or above the settled reading {:.1} mV: an ordinary push looks lost",
                settled_v * 1e3
            )
        })
    };
    d.choose(
        "strategy.lost_threshold_mv",
        f.strategy.lost_threshold_mv,
        (lost * 1e3 * 10.0).round() / 10.0,
        format!(
            "half the settled reading {:.1} mV the model predicts after t*",
            settled_v * 1e3
        ),
        check,
    );
    Ok(())
}

/// **V**: the least of the paper's 1 µm/s, the travel from the set point to the peak in 1.5
/// ticks (the search stops between the two), and `tolerance · 2π f_y / 4` (the stage's
/// ringing at the stop).
fn speed(d: &mut Derivation, s: &mut Settled) -> Result<(), Refusal> {
    let (f, pred) = (&d.scene.file, s.cand.prediction);
    let window = pred.travel_to_peak - pred.travel_to_deflection.unwrap_or(0.0);
    let v_detect = window.max(1e-12) / (1.5 * TICK);
    let omega = 2.0 * std::f64::consts::PI * f.stage.resonance_hz;
    let v_ring = d.tolerance * omega / 4.0;
    let v = PAPER_SPEED.min(v_detect).min(v_ring);
    let hand_v = f.push.speed_um_per_s * 1e-6;
    let check = (hand_v > 1.05 * v_detect.min(v_ring)).then(|| {
        format!(
            "faster than {:.3} µm/s: {}",
            v_detect.min(v_ring) * 1e6,
            if v_detect < v_ring {
                format!(
                    "the search crosses the {:.2} nm between the set point and the peak in under 1.5 ticks",
                    window * 1e9
                )
            } else {
                format!(
                    "the stage rings about V/(2π f_y) at the stop, over a quarter of the {} nm tolerance",
                    crate::words::nm_text(d.tolerance)
                )
            }
        )
    });
    s.speed_um = d.choose(
        "push.speed_um_per_s",
        hand_v * 1e6,
        round_down(v * 1e6),
        format!(
            "the least of the paper's 1 µm/s, the {:.2} nm from the set point to the peak in 1.5 ticks of 1 ms ({:.3} µm/s), and the tolerance × 2π f_y / 4 ({:.3} µm/s: the stage's ringing at the stop)",
            window * 1e9,
            v_detect * 1e6,
            v_ring * 1e6
        ),
        check,
    );
    Ok(())
}

/// The local scan that finds the particle: its size and pixels (not scene fields).
fn local_scan(d: &mut Derivation, s: &mut Settled) -> Result<(), Refusal> {
    let range = d.scene.file.stage.range_um * 1e-6;
    s.scan = local_scan_size(s.r_a, s.r_t, range);
    s.pitch = s.scan / LOCAL_PIXELS as f64;
    d.choices.push(Choice {
        key: "local_scan.size_um",
        value: s.scan * 1e6,
        hand_set: false,
        why: "12 particle radii of substrate to level on, at least 4 µm, at most 32 (Rₐ + Rₜ) (four pixels across the particle's image) and the stage".into(),
    });
    d.choices.push(Choice {
        key: "local_scan.pixels",
        value: LOCAL_PIXELS as f64,
        hand_set: false,
        why: format!(
            "a {:.1} nm pitch: the sphere fit locates the particle to a small fraction of it",
            s.pitch * 1e9
        ),
    });
    Ok(())
}

/// **Δ** `= (Rₐ + Rₜ)/4` within [5, 100] nm.
fn step(d: &mut Derivation, s: &mut Settled) -> Result<(), Refusal> {
    let step = ((s.r_a + s.r_t) / 4.0).clamp(5e-9, 100e-9);
    s.step = d.choose(
        "strategy.step_um",
        d.scene.file.strategy.step_um,
        round_nm(step) * 1e6,
        "a quarter of Rₐ + Rₜ within [5, 100] nm (the paper's 0.1 µm for its 1 µm particles)".into(),
        None,
    ) * 1e-6;
    Ok(())
}

/// **Approach distance**: the clearance the tip needs to touch down beside the particle,
/// `2√(Rₐ Rₜ) − (Rₐ + Rₜ) cos β`, plus four local-scan pixels and two steps.
fn approach_distance(d: &mut Derivation, s: &mut Settled) -> Result<(), Refusal> {
    let f = &d.scene.file;
    let clearance = (2.0 * (s.r_a * s.r_t).sqrt() - (s.r_a + s.r_t) * s.beta.cos()).max(0.0);
    let approach = clearance + 4.0 * s.pitch + 2.0 * s.step;
    s.approach = d.choose(
        "strategy.approach_distance_um",
        f.strategy.approach_distance_um,
        round_nm(approach) * 1e6,
        format!(
            "{:.0} nm for the tip to touch down beside the particle, 2√(RₐRₜ) − (Rₐ + Rₜ) cos β, plus four local-scan pixels ({:.0} nm) and two steps",
            clearance * 1e9,
            4.0 * s.pitch * 1e9
        ),
        (f.strategy.approach_distance_um * 1e-6 < clearance).then(|| {
            format!(
                "the tip touches down on the particle, not beside it: it needs {:.3} µm",
                clearance * 1e6
            )
        }),
    ) * 1e-6;
    Ok(())
}

/// **Search range**: twice the approach distance, the model's travel to the set point and four
/// steps.
fn search_range(d: &mut Derivation, s: &mut Settled) -> Result<(), Refusal> {
    let f = &d.scene.file;
    let pred = s.cand.prediction;
    let to_set = pred.travel_to_deflection.unwrap_or(pred.travel_to_peak);
    s.search = 2.0 * s.approach + to_set + 4.0 * s.step;
    d.choose(
        "strategy.search_range_um",
        f.strategy.search_range_um,
        round_nm(s.search) * 1e6,
        format!(
            "twice the approach distance, plus the model's {:.1} nm from the touch to the set point, plus four steps",
            to_set * 1e9
        ),
        (f.strategy.search_range_um * 1e-6 < s.approach + to_set)
            .then(|| "shorter than the approach distance and the travel to the set point".into()),
    );
    Ok(())
}

/// **Start height** (the retraction's): high enough to let go, and to clear every particle
/// wherever the tip travels at it. The tip moves at a fixed height, and a tilted substrate
/// rises (or falls, and auto-parking descends at most twice the start height) by the tilt
/// times the distance, at most the stage's diagonal; plus four RMS of roughness.
fn start_height(d: &mut Derivation, s: &mut Settled) -> Result<(), Refusal> {
    let f = &d.scene.file;
    let pred = s.cand.prediction;
    let tallest = f.particles.iter().map(|p| 2.0 * p.radius_nm * 1e-9).fold(0.0, f64::max);
    let sub = &f.substrate;
    let slope = sub.tilt_x_mrad.hypot(sub.tilt_y_mrad) * 1e-3;
    let rise = slope * f.stage.range_um * 1e-6 * std::f64::consts::SQRT_2 + 4.0 * sub.roughness_rms_nm * 1e-9;
    let clear = tallest + (0.25 * tallest).max(0.5e-6) + rise;
    let release = pred.release_lift.unwrap_or(0.0);
    let lift_need = s.cand.parking + BACK_OFF * s.beta.sin() + 1.25 * release + 0.2e-6;
    let start = clear.max(lift_need);
    if start > MAX_START {
        return Err(d.refuse(Fails {
            code: "too_tall",
            advice: Vec::new(),
            reason: format!(
                "the retraction needs a start height of {:.1} µm (the tallest particle {:.1} µm, the lift to let go {:.2} µm), above the {} µm allowed",
                start * 1e6,
                tallest * 1e6,
                release * 1e6,
                MAX_START * 1e6
            ),
            field: format!(
                "particles[].radius_nm (smaller) or {}",
                adhesion_field(Pair::TipParticle, &d.scene.push_params_for(d.part).adhesion_ta_sources())
            ),
        }));
    }
    let check = (f.strategy.start_height_um * 1e-6 < lift_need).then(|| {
        format!(
            "below the {:.3} µm the tip needs to let go of the particle: it drags the particle back as it lifts",
            lift_need * 1e6
        )
    });
    s.start = d.choose(
        "strategy.start_height_um",
        f.strategy.start_height_um,
        (start * 1e7).ceil() / 10.0,
        format!(
            "above the tallest particle ({:.2} µm) by a quarter of it, at least 0.5 µm, plus the substrate's rise over the stage's diagonal and its roughness ({:.3} µm), and above the parking height plus 1.25 × the {:.3} µm the model lifts before the tip lets go",
            tallest * 1e6,
            rise * 1e6,
            release * 1e6
        ),
        check,
    ) * 1e-6;
    Ok(())
}

fn approach_speed(d: &mut Derivation, _: &mut Settled) -> Result<(), Refusal> {
    d.fixed(
        "strategy.approach_speed_um_per_s",
        d.scene.file.strategy.approach_speed_um_per_s,
        "the z approach and the lift: 1 nm a tick, gentle on the substrate",
    );
    Ok(())
}

fn travel_speed(d: &mut Derivation, _: &mut Settled) -> Result<(), Refusal> {
    d.fixed(
        "strategy.travel_speed_um_per_s",
        d.scene.file.strategy.travel_speed_um_per_s,
        "moves at the start height, clear of every particle",
    );
    Ok(())
}

fn dwell(d: &mut Derivation, _: &mut Settled) -> Result<(), Refusal> {
    d.fixed(
        "strategy.dwell_ms",
        d.scene.file.strategy.dwell_ms,
        "readings averaged after each search step (the contact is checked every tick regardless)",
    );
    Ok(())
}

/// **Follow the slope**: the tip follows the substrate's slope, as the local scan before each
/// push measures it, through the contact search and the push: held at one height instead, the
/// tip's height above a sloping substrate changes along the push by the slope times the travel,
/// and with it the contact angle and the reading (a pull-side reading drifts off the contact,
/// a rolling particle is left behind). An angle whose dry run fails following the measured slope
/// is tried again held at one height ([`Derivation::held`]): a scan whose height drifts
/// (`scan.drift_z_nm_per_s`) levels its image by a plane tilted along its slow axis, a slope the
/// substrate does not have.
fn follow_slope(d: &mut Derivation, _: &mut Settled) -> Result<(), Refusal> {
    let f = &d.scene.file;
    let why = if d.held {
        "the tip is held at one height: following the slope the local scan measured, this angle's dry run failed (what was tried says how; a scan whose height drifts reads a slope along its slow axis that the substrate does not have)".to_string()
    } else {
        "the tip follows the substrate's slope as the local scan before each push measures it, keeping its height above the substrate and the contact angle along the push".to_string()
    };
    d.choose(
        "strategy.follow_slope",
        if f.strategy.follow_slope { 1.0 } else { 0.0 },
        if d.held { 0.0 } else { 1.0 },
        why,
        None,
    );
    Ok(())
}

/// **Longest push**: the substrate's slope changes the contact angle along a push held at one
/// height by at most 5° a leg, `Δz = 0.087 (Rₐ + Rₜ) cos β`; a longer move re-parks for each
/// leg. A push that follows the slope keeps the same bound: the measured slope and the
/// roughness still leave the height off by some of it.
fn max_push(d: &mut Derivation, s: &mut Settled) -> Result<(), Refusal> {
    let f = &d.scene.file;
    let slope = (f.substrate.tilt_x_mrad.hypot(f.substrate.tilt_y_mrad)) * 1e-3;
    let dz = 5f64.to_radians() * (s.r_a + s.r_t) * s.beta.cos();
    let range = f.stage.range_um * 1e-6;
    let max_push = if slope > 0.0 {
        (dz / slope).clamp(0.2e-6, 20e-6)
    } else {
        20e-6
    }
    .min(range);
    // Below the least push the bound cannot hold: said, with what the least push changes.
    let floor = if slope > 0.0 && dz / slope < 0.2e-6 {
        format!(
            "; held at one height, even the least push, 0.2 µm, changes it by {:.1} nm",
            slope * 0.2e-6 * 1e9
        )
    } else {
        String::new()
    };
    let mut why = format!(
        "a longer move is planned as several pushes, each re-parked: the substrate's slope {:.1} mrad may change the contact angle by at most 5° a push ({:.1} nm of height{floor}), at most 20 µm and the stage's range",
        slope * 1e3,
        dz * 1e9
    );
    let max_push = match d.push_cap {
        Some((cap, lost)) if cap < max_push => {
            s.shortened = true;
            why = format!(
                "pushes of {} µm: the dry run of a longer push lost the particle after {} µm as the reading drifted off the contact, and a fresh set point each push keeps it",
                short(cap * 1e6),
                short(lost * 1e6)
            );
            cap
        }
        _ => max_push,
    };
    s.max_push = d.choose(
        "strategy.max_push_um",
        f.strategy.max_push_um,
        (max_push * 1e8).floor() / 100.0,
        why,
        None,
    ) * 1e-6;
    Ok(())
}

fn clearance(d: &mut Derivation, _: &mut Settled) -> Result<(), Refusal> {
    d.fixed(
        "strategy.clearance_um",
        d.scene.file.strategy.clearance_um,
        "kept between the pushed particle and the others when planning",
    );
    Ok(())
}

fn z_gain(d: &mut Derivation, _: &mut Settled) -> Result<(), Refusal> {
    d.fixed(
        "strategy.z_gain_nm_per_v",
        d.scene.file.strategy.z_gain_nm_per_v,
        "the z force loop's gain (z and xyz control only)",
    );
    Ok(())
}

/// **Time-out**: three times the longest phase (the longest push at V, the approach from twice
/// the start height, the pull-off's rise, the search with its dwells), within [120, 600] s.
fn phase_timeout(d: &mut Derivation, s: &mut Settled) -> Result<(), Refusal> {
    let f = &d.scene.file;
    let v = s.speed_um * 1e-6;
    let longest = (s.max_push / v)
        .max(2.0 * s.start / s.approach_speed)
        .max(pull_off_rise(&d.scene.tip_sample()) / s.approach_speed)
        .max(s.search / v + s.search / s.step * f.strategy.dwell_ms * 1e-3);
    let timeout = (3.0 * longest).clamp(120.0, MAX_TIMEOUT).ceil();
    if longest > MAX_TIMEOUT {
        d.warnings.push(format!(
            "the longest phase would take {longest:.0} s at {} µm/s, more than the {MAX_TIMEOUT:.0} s a phase may: such a push fails with a time-out",
            short(v * 1e6)
        ));
    }
    d.choose(
        "strategy.phase_timeout_s",
        f.strategy.phase_timeout_s,
        timeout,
        format!("three times the longest phase ({longest:.0} s), within [120, {MAX_TIMEOUT:.0}] s"),
        (f.strategy.phase_timeout_s < longest).then(|| format!("shorter than the longest phase, {longest:.0} s")),
    );
    Ok(())
}

/// The `[strategy]` in force: the scene's, with every choice's value written in.
fn resolved(scene: &Scene, choices: &[Choice]) -> StrategyFile {
    let mut s = scene.file.strategy.clone();
    for c in choices {
        let v = c.value;
        match c.key {
            "strategy.start_height_um" => s.start_height_um = v,
            "strategy.approach_speed_um_per_s" => s.approach_speed_um_per_s = v,
            "strategy.travel_speed_um_per_s" => s.travel_speed_um_per_s = v,
            "strategy.substrate_threshold_mv" => s.substrate_threshold_mv = v,
            "strategy.step_um" => s.step_um = v,
            "strategy.dwell_ms" => s.dwell_ms = v,
            "strategy.set_point_v" => s.set_point_v = v,
            "strategy.approach_distance_um" => s.approach_distance_um = v,
            "strategy.search_range_um" => s.search_range_um = v,
            "strategy.safety_limit_v" => s.safety_limit_v = v,
            "strategy.lost_threshold_mv" => s.lost_threshold_mv = v,
            "strategy.max_push_um" => s.max_push_um = v,
            "strategy.clearance_um" => s.clearance_um = v,
            "strategy.phase_timeout_s" => s.phase_timeout_s = v,
            "strategy.z_gain_nm_per_v" => s.z_gain_nm_per_v = v,
            "strategy.follow_slope" => s.follow_slope = v != 0.0,
            _ => {}
        }
    }
    s
}

/// A speed rounded down to three significant digits (µm/s), so the plan prints what it uses.
fn round_down(v: f64) -> f64 {
    if !(v.is_finite() && v > 0.0) {
        return v;
    }
    let scale = 10f64.powi(2 - v.log10().floor() as i32);
    (v * scale).floor() / scale
}

/// A length rounded to the nanometre (m).
fn round_nm(v: f64) -> f64 {
    (v * 1e9).round().max(1.0) * 1e-9
}
