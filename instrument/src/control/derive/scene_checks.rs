//! The checks of the scene before any contact angle is tried: the substrate's detection, the
//! tip's pull-off from the substrate after auto-parking, and the stage.

use super::adhesion_field::{Pair, field as adhesion_field};
use super::{
    Advice, AdviceKey, Choice, Derivation, Fails, MAX_START, Refusal, STAGE_SETTLE, STAGE_STIFFNESS_RATIO, TOUCH_PRESS,
    short,
};
use crate::control::strategy::pull_off::{PULL_OFF_MARGIN, PULL_OFF_SLACK, pull_off_rise};

impl Derivation<'_> {
    /// The substrate threshold of auto-parking: 10σ of the noise plus twice the perturbation,
    /// at least 30 mV, within half the readout's room, and seen before the tip presses
    /// [`TOUCH_PRESS`] into the substrate.
    pub(super) fn substrate_threshold(&mut self) -> Result<(), Refusal> {
        let f = &self.scene.file;
        let ro = self.readout;

        let noise = 10.0 * ro.sigma + 2.0 * ro.pert;
        let thr = noise.max(0.03);
        let thr_check = (f.strategy.substrate_threshold_mv * 1e-3 < noise).then(|| {
            format!(
                "within 10σ + 2p = {:.1} mV of the readout's noise: the noise can trip it",
                noise * 1e3
            )
        });
        let thr = self.choose(
            "strategy.substrate_threshold_mv",
            f.strategy.substrate_threshold_mv,
            (thr * 1e3).round(),
            format!(
                "10σ of the readout noise plus twice the perturbation, at least 30 mV: the touch is told from noise (the tip presses {:.2} nm before it is seen)",
                thr / ro.gain * 1e9
            ),
            thr_check,
        ) * 1e-3;
        if thr >= 0.5 * ro.room {
            return Err(self.refuse(Fails {
                code: "unreadable",
                advice: Vec::new(),
                reason: format!(
                    "the substrate threshold {:.0} mV (10σ of the noise) is over half the readout's room {:.2} V on the push side",
                    thr * 1e3,
                    ro.room
                ),
                field: "sensor.noise_rms_mv (lower) or sensor.full_scale_v (higher)".into(),
            }));
        }
        let press = thr / ro.gain;
        if press > TOUCH_PRESS {
            let need = thr / TOUCH_PRESS * 1e-9;
            return Err(self.refuse(Fails {
                code: "unreadable",
                advice: vec![Advice::new(
                    AdviceKey::Gain,
                    need,
                    1.0,
                    crate::scene::GAIN_V_PER_NM.hi(),
                )],
                reason: format!(
                    "the tip would press {:.1} nm into the substrate before the reading shows it ({:.0} mV at {} V/nm)",
                    press * 1e9,
                    thr * 1e3,
                    short(ro.gain * 1e-9)
                ),
                field: format!("sensor.gain_v_per_nm: |gain| ≥ {} V/nm", short(need)),
            }));
        }
        Ok(())
    }

    /// The tip's pull-off from the substrate after auto-parking: the lever bends the other way
    /// by up to the adhesion over `k_c` as the stage rises, and the strategy rides out a reading
    /// saturated on that side up to [`pull_off_rise`] above the detected substrate. That rise
    /// must be at most what the strategy may lift, [`MAX_START`].
    pub(super) fn check_pull_off(&mut self) -> Result<(), Refusal> {
        let ts = self.scene.tip_sample();
        let f = &self.scene.file;
        let ro = self.readout;
        let adhesion = ts.adhesion();
        let k_c = ts.k_c;
        let bend = adhesion.max(0.0) / k_c;
        let rise = pull_off_rise(&ts);
        let other_room = f.sensor.full_scale_v + ro.sign * ro.baseline;
        let pull_v = bend * ro.gain;
        if !(rise.is_finite() && rise <= MAX_START) {
            // 1.5 (F/k + r) + slack ≤ MAX: F/k ≤ (MAX − slack)/1.5 − r.
            let rest = ts.release_distance() - bend;
            let room = (MAX_START - PULL_OFF_SLACK) / PULL_OFF_MARGIN - rest;
            let need_k = adhesion / room.max(1e-12);
            return Err(self.refuse(Fails {
                code: "adhesion",
                advice: vec![Advice::new(
                    AdviceKey::Stiffness,
                    need_k,
                    1.0,
                    crate::scene::STIFFNESS_N_PER_M.hi(),
                )],
                reason: format!(
                    "the tip's adhesion to the substrate, {:.2} nN, holds it until the {} N/m lever has bent {:.2} µm: letting go after auto-parking needs a rise of up to {:.1} µm (1.5 (F_ad/k_c + L_t + δ_b + a₀) + 10 nm), more than the {} µm the strategy may lift",
                    adhesion * 1e9,
                    short(k_c),
                    bend * 1e6,
                    rise * 1e6,
                    MAX_START * 1e6
                ),
                field: format!(
                    "cantilever.stiffness_n_per_m: k_c ≥ {} N/m, or {}",
                    short(need_k),
                    adhesion_field(Pair::TipSubstrate, &ts.adhesion_sources())
                ),
            }));
        }
        let saturates = if pull_v >= other_room {
            format!(
                "the pull-off reads up to {:.1} V, past the {:.2} V of room on that side: the saturated reading is ridden out meanwhile",
                pull_v, other_room
            )
        } else {
            format!(
                "the pull-off reads up to {:.2} V, within the {:.2} V of room on that side",
                pull_v, other_room
            )
        };
        self.choices.push(Choice {
            key: "pull_off.rise_um",
            value: rise * 1e6,
            hand_set: false,
            why: format!(
                "the rise above the detected substrate by which the tip must have let go of it after auto-parking: 1.5 × (the adhesion {:.2} nN over k_c, {:.1} nm, plus the meniscus's rupture gap and a₀) + 10 nm; {saturates}",
                adhesion * 1e9,
                bend * 1e9
            ),
        });
        Ok(())
    }

    /// The stage must settle between the steps: its ringing `Q/(π f_y)` dying within
    /// [`STAGE_SETTLE`]. A stiffness `m (2π f_y)²` under [`STAGE_STIFFNESS_RATIO`] times the
    /// lever's is a warning: the model's Eq 13 carries the push's load through the stage's
    /// stiffness, so the prediction and the dry run see the yield.
    pub(super) fn check_stage(&mut self) -> Result<(), Refusal> {
        let f = &self.scene.file;
        let st = &f.stage;
        if f.physics.stage == crate::scene::file::DofFile::Off {
            return Ok(());
        }
        let m = st.moving_mass_g * 1e-3;
        let omega = 2.0 * std::f64::consts::PI * st.resonance_hz;
        let k_stage = m * omega * omega;
        let c = self.scene.cantilever();
        let k_lever = c.k_y().max(c.k_z());
        if k_stage < STAGE_STIFFNESS_RATIO * k_lever {
            let need = (STAGE_STIFFNESS_RATIO * k_lever / m).sqrt() / (2.0 * std::f64::consts::PI);
            self.warnings.push(format!(
                "the stage's stiffness m (2π f_y)² = {} N/m is less than {} times the lever's stiffer direction (max(k_y, k_z) = {} N/m, the lateral k_y from the lever's shape): it yields under the push, which the model predicts and the dry run checks; stage.resonance_hz ≥ {} Hz would make it negligible",
                short(k_stage),
                STAGE_STIFFNESS_RATIO,
                short(k_lever),
                short(need)
            ));
        }
        let settle = st.quality_factor / (std::f64::consts::PI * st.resonance_hz);
        if settle > STAGE_SETTLE {
            return Err(self.refuse(Fails {
                code: "stage",
                advice: Vec::new(),
                reason: format!(
                    "the stage rings for Q/(π f_y) = {} s after every step and stop, more than {} s",
                    short(settle),
                    STAGE_SETTLE
                ),
                field: format!(
                    "stage.quality_factor: Q ≤ {} at this resonance, or a higher stage.resonance_hz",
                    short(STAGE_SETTLE * std::f64::consts::PI * st.resonance_hz)
                ),
            }));
        }
        Ok(())
    }
}
