//! Whether the strategy can work on a predicted push: the reading shows the contact, the peak
//! fits the readout, `t*` is seen and the tip lets go; and what a `deflection_limit` refusal
//! names.

use super::adhesion_field::{Pair, field as adhesion_field};
use super::{
    Advice, AdviceKey, Candidate, Derivation, Fails, MAX_START, MAX_STIFFNESS, PEAK_SPARE, SET_FRACTION, TOUCH_PRESS,
    short,
};
use crate::control::estimator::PushPrediction;
use crate::scene::file::ControlFile;

impl Derivation<'_> {
    /// Whether the strategy can work on the predicted push: the reading shows the contact, the
    /// peak fits the readout, `t*` is seen and the tip lets go.
    pub(super) fn check(&self, c: &Candidate) -> Result<(), Fails> {
        let ro = self.readout;
        let p = &c.prediction;
        let room = ro.room_on(p.side);
        let k = self.scene.file.cantilever.stiffness_n_per_m;
        let gain_nm = ro.gain * 1e-9;
        if p.peak_deflection.abs() < 1e-13 && p.settled_deflection.abs() < 1e-13 {
            return Err(Fails {
                code: "no_resistance",
                advice: Vec::new(),
                reason: format!(
                    "at β = {}° the particle offers the tip no resistance: it moves without bending the lever (ζ_z stays below 0.1 pm), so no reading can find or follow it",
                    c.beta_deg
                ),
                field: "friction.particle_substrate_static and friction.tip_particle_static (above 0)".into(),
            });
        }
        if p.peak_deflection <= 0.0 {
            return Err(Fails {
                code: "unreadable",
                advice: Vec::new(),
                reason: format!(
                    "at β = {}° the push bends the lever away from the {} side (peak ζ_z on that side {:.3} nm)",
                    c.beta_deg,
                    p.side.name(),
                    p.peak_deflection * 1e9
                ),
                field: "push.contact_angle_deg (steeper) or cantilever.tilt_deg".into(),
            });
        }
        // The deflection limit first: a lever that reaches it before the model's push ends
        // cannot push, whether or not the particle would shear loose later.
        let separates = p.travel_to_peak <= 0.75 * p.travel;
        let peak_v = p.peak_deflection * ro.gain;
        if PEAK_SPARE * peak_v > 0.9 * room {
            let need_k = k * PEAK_SPARE * peak_v / (0.9 * room);
            let (field, advice) = self.deflection_limit_field(p, separates, need_k, peak_v);
            return Err(Fails {
                code: "deflection_limit",
                advice,
                reason: format!(
                    "at β = {}° the lever's deflection limit is reached before the particle shears: the stick-phase peak {}{:.2} nm reads {:.2} V, and twice that is beyond 90 % of the readout's {:.2} V on the {} side",
                    c.beta_deg,
                    if separates {
                        ""
                    } else {
                        "(still rising at the end of the model's push) "
                    },
                    p.peak_deflection * 1e9,
                    peak_v,
                    room,
                    p.side.name()
                ),
                // Still rising: the figures scale a peak the model has not reached, so they
                // are needed but not known to be enough (1.1 × the figure, applied, can ask for 20
                // times more). A figure outside what a scene allows,
                // or a gain too small for the readout to see the touch or the set point, is
                // said to be no way out rather than offered.
                field,
            });
        }
        if !separates {
            return Err(Fails {
                code: "no_separation",
                advice: Vec::new(),
                reason: format!(
                    "at β = {}° the particle does not shear loose within {:.0} nm of push (ζ_z still rising at {:.2} nm, {:.2} nN on the lever)",
                    c.beta_deg,
                    0.75 * p.travel * 1e9,
                    p.peak_deflection * 1e9,
                    p.peak_deflection * k * 1e9
                ),
                field: "cantilever.stiffness_n_per_m (stiffer) or friction.particle_substrate_static (lower)".into(),
            });
        }
        let floor = ro.sigma + ro.pert;
        if SET_FRACTION * peak_v < 10.0 * floor {
            let gain = gain_field(gain_nm * 10.0 * floor / (SET_FRACTION * peak_v), true);
            return Err(Fails {
                code: "unreadable",
                advice: gain.1,
                reason: format!(
                    "at β = {}° the set point, {:.0} % of the peak {:.4} nm, reads {:.1} mV: under 10 × the noise and perturbation ({:.1} mV)",
                    c.beta_deg,
                    SET_FRACTION * 100.0,
                    p.peak_deflection * 1e9,
                    SET_FRACTION * peak_v * 1e3,
                    floor * 1e3
                ),
                field: gain.0,
            });
        }
        let drop_v = (p.peak_deflection - p.settled_deflection) * ro.gain;
        let need_drop = 12.0 * ro.sigma + 2.0 * ro.pert;
        if drop_v < need_drop {
            let gain = gain_field(gain_nm * need_drop / drop_v.max(1e-12), true);
            return Err(Fails {
                code: "unreadable",
                advice: gain.1,
                reason: format!(
                    "at β = {}° the drop at t* ({:.3} nm, {:.1} mV) is under 12σ + 2p = {:.1} mV: the separation cannot be told from noise",
                    c.beta_deg,
                    (p.peak_deflection - p.settled_deflection) * 1e9,
                    drop_v * 1e3,
                    need_drop * 1e3
                ),
                field: gain.0,
            });
        }
        let settled_v = p.settled_deflection * ro.gain;
        let need_settled = 8.0 * ro.sigma + 2.0 * ro.pert;
        let rolls_unread = self.rolls_unread(p);
        if settled_v < need_settled && !rolls_unread {
            // A reading that settles at or beyond the baseline cannot be raised by any gain.
            let gain = if settled_v > 0.0 {
                gain_field(gain_nm * need_settled / settled_v, false)
            } else {
                (
                    "the particle, its friction or the contact angle: the push settles with the lever at or beyond the baseline, which no gain can read".into(),
                    Vec::new(),
                )
            };
            return Err(Fails {
                code: "unreadable",
                advice: gain.1,
                reason: format!(
                    "at β = {}° the settled reading after t* ({:.1} mV) is under 8σ + 2p = {:.1} mV: the push could not be told from a lost particle",
                    c.beta_deg,
                    settled_v * 1e3,
                    need_settled * 1e3
                ),
                field: gain.0,
            });
        }
        // The z loop holds the reading after t* at its level: a particle rolling on with no
        // load gives it no contact to hold.
        if rolls_unread && self.file.control != ControlFile::Xy {
            return Err(Fails {
                code: "unreadable",
                advice: Vec::new(),
                reason: format!(
                    "at β = {}° the particle rolls on in front of the tip after t* with no load on the lever (a settled reading of {:.1} mV): the {} loop would hold the tip to a reading that is not the contact's",
                    c.beta_deg,
                    settled_v * 1e3,
                    self.file.control.name()
                ),
                field: "strategy.control = \"xy\" (or --control xy)".into(),
            });
        }
        if p.release_lift.is_none() {
            return Err(Fails {
                code: "stuck",
                advice: Vec::new(),
                reason: format!(
                    "at β = {}° the tip still holds the particle after a lift to {} µm: the adhesion outlasts any retraction",
                    c.beta_deg,
                    MAX_START * 1e6
                ),
                field: adhesion_field(
                    Pair::TipParticle,
                    &self.scene.push_params_for(self.part).adhesion_ta_sources(),
                ),
            });
        }
        Ok(())
    }

    /// The substrate threshold chosen (V; the scene's 30 mV floor before it is).
    pub(super) fn substrate_threshold_v(&self) -> f64 {
        self.choices
            .iter()
            .find(|c| c.key == "strategy.substrate_threshold_mv")
            .map_or(0.03, |c| c.value * 1e-3)
    }

    /// Whether the model's push settles with the particle rolling on in front of the tip and a
    /// reading the push-side lost-particle test cannot follow (under `8σ + 2p`: at the baseline,
    /// or past it on the other side): such a push is run without that test
    /// (`strategy.lost_threshold_mv = 0`), its end told by the scan after it. The particle then
    /// moves at the tip's speed, behind its travel by the settled lag.
    pub(super) fn rolls_unread(&self, p: &PushPrediction) -> bool {
        let ro = self.readout;
        p.settled && p.phase == "roll" && p.settled_deflection * ro.gain < 8.0 * ro.sigma + 2.0 * ro.pert
    }

    /// The fields a `deflection_limit` refusal names: a stiffer lever (at most
    /// [`MAX_STIFFNESS`]) or a smaller gain (no smaller than the readout needs to see the touch
    /// of the substrate, [`TOUCH_PRESS`], and the set point, 10 × the noise), each figure "at
    /// the least" when the model's peak was still rising.
    fn deflection_limit_field(
        &self,
        p: &PushPrediction,
        separates: bool,
        need_k: f64,
        peak_v: f64,
    ) -> (String, Vec<Advice>) {
        let ro = self.readout;
        let gain_nm = ro.gain * 1e-9;
        let (ge, le, least, least_gain) = if separates {
            ("≥", "≤", "", "")
        } else {
            (
                ">",
                "<",
                " at the least (the model's push had not sheared the particle loose, so no value is known to be enough)",
                " at the least",
            )
        };
        let k_helps = need_k <= MAX_STIFFNESS;
        let stiffer = format!("cantilever.stiffness_n_per_m: k_c {ge} {} N/m needed", short(need_k));
        let k_no = format!("{stiffer}, beyond the {} N/m a scene allows", short(MAX_STIFFNESS));
        let gain_max = gain_nm * 0.9 * ro.room_on(p.side) / (PEAK_SPARE * peak_v);
        let threshold = self.substrate_threshold_v();
        let touch_floor = threshold / (TOUCH_PRESS * 1e9);
        let set_floor = 10.0 * (ro.sigma + ro.pert) / (SET_FRACTION * p.peak_deflection * 1e9);
        let gain_floor = touch_floor.max(set_floor);
        let gain_helps = gain_max >= gain_floor;
        let smaller = format!("|sensor.gain_v_per_nm| {le} {} V/nm", short(gain_max));
        let gain_no = format!(
            "{smaller}, but below {} V/nm the readout does not see the touch of the substrate or the set point",
            short(gain_floor)
        );
        let k_advice = Advice::new(AdviceKey::Stiffness, need_k, 1.0, MAX_STIFFNESS);
        let gain_advice = Advice::new(AdviceKey::Gain, gain_max, -1.0, gain_floor);
        match (k_helps, gain_helps) {
            (true, true) => (
                format!("{stiffer}{least}, or {smaller}{least_gain}"),
                vec![k_advice, gain_advice],
            ),
            (true, false) => (
                format!("{stiffer}{least} (a smaller gain cannot help: {gain_no})"),
                vec![k_advice],
            ),
            (false, true) => (
                format!("{smaller}{least} (a stiffer lever cannot help: {k_no})"),
                vec![gain_advice],
            ),
            (false, false) => (
                format!(
                    "the particle, its friction or the contact angle: neither a stiffer lever ({k_no}) nor a smaller gain ({gain_no}) can help"
                ),
                Vec::new(),
            ),
        }
    }
}

/// The field an `unreadable` refusal names: the gain the reading needs (V/nm), when a scene
/// allows it ([`crate::scene::GAIN_V_PER_NM`]), and a quieter readout when `noise_helps`.
fn gain_field(need: f64, noise_helps: bool) -> (String, Vec<Advice>) {
    let max = crate::scene::GAIN_V_PER_NM.hi();
    let quieter = if noise_helps {
        ", or a lower sensor.noise_rms_mv"
    } else {
        ""
    };
    if need <= max {
        (
            format!("sensor.gain_v_per_nm: |gain| ≥ {} V/nm{quieter}", short(need)),
            vec![Advice::new(AdviceKey::Gain, need, 1.0, max)],
        )
    } else {
        let text = format!(
            "the particle, its friction or the contact angle: the reading would need |sensor.gain_v_per_nm| ≥ {} V/nm, beyond the {} V/nm a scene allows{quieter}",
            short(need),
            short(max)
        );
        (text, Vec::new())
    }
}
