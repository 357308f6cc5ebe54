//! The scene fields a refusal caused by an adhesion names: the fields that set the terms pulling
//! hardest ([`Attraction::ranked`]), not always the humidity. A tip held by its work-function
//! voltage is not freed by a drier room.

use crate::physics::pushing::params::Attraction;

/// Which pair the adhesion holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Pair {
    /// The tip on the substrate (pull-off after auto-parking, snap-in).
    TipSubstrate,
    /// The tip on the particle (letting go after the push).
    TipParticle,
}

/// The field to change so that `source` pulls less between `pair`, with the direction.
fn one(pair: Pair, source: Attraction) -> &'static str {
    use Attraction::*;
    use Pair::*;
    match (pair, source) {
        (_, Capillary) => "environment.relative_humidity (drier: a shorter meniscus)",
        // Eq 4's charged area is 4πR r₁, and the Kelvin radius r₁ grows with the humidity.
        (TipSubstrate, Electrostatic) => {
            "environment.tip_substrate_voltage_v (smaller |U|) or environment.relative_humidity (drier: Eq 4's area 4πR r₁ shrinks)"
        }
        (TipParticle, Electrostatic) => {
            "environment.tip_particle_voltage_v (smaller |U|) or environment.relative_humidity (drier: Eq 4's area 4πR r₁ shrinks)"
        }
        (TipSubstrate, VanDerWaals) => "tip.hamaker_zj or substrate.hamaker_zj (smaller)",
        (TipParticle, VanDerWaals) => "tip.hamaker_zj or particles[].hamaker_zj (smaller)",
        (_, Contact) => "environment.solid_liquid_energy_mj_per_m2 (smaller: a weaker JKR contact)",
    }
}

/// The fields to change so that the adhesion between `pair` pulls less, the strongest term's
/// first (`sources` as [`Attraction::ranked`] gives them). With none pulling (a repulsive
/// scene) the humidity is named, the meniscus being what forms at contact.
pub(super) fn field(pair: Pair, sources: &[Attraction]) -> String {
    if sources.is_empty() {
        return one(pair, Attraction::Capillary).into();
    }
    sources.iter().map(|&s| one(pair, s)).collect::<Vec<_>>().join(", or ")
}

/// What snaps the tip in to the substrate above a parking height, in words, and the fields to
/// change. With a meniscus the scene can form, its length sets the snap-in height unless the
/// other attractions alone snap the tip in above `parking` too (`dry_snap_in`: the snap-in
/// with the meniscus left out); without one, the attraction whose pull outgrows the lever's
/// stiffness does.
pub(super) fn snap_in_cause(
    ts: &crate::physics::force_curve::TipSample,
    dry_snap_in: impl FnOnce() -> f64,
    parking: f64,
) -> (&'static str, String) {
    let meniscus = ts.long_range.capillary.as_ref().is_some_and(|c| c.possible());
    if meniscus && dry_snap_in() < parking {
        return ("the meniscus", one(Pair::TipSubstrate, Attraction::Capillary).into());
    }
    let mut dry = *ts;
    dry.long_range.capillary = None;
    (
        "the attraction",
        format!(
            "cantilever.stiffness_n_per_m (stiffer), or {}",
            field(Pair::TipSubstrate, &dry.adhesion_sources())
        ),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::{DEFAULT_SCENE, Scene};

    fn scene(edits: &[(&str, &str)]) -> Scene {
        let mut text = DEFAULT_SCENE.to_string();
        for (from, to) in edits {
            assert!(text.contains(from), "{from}");
            text = text.replacen(from, to, 1);
        }
        Scene::parse("test", &text).unwrap()
    }

    /// The paper's humid scene holds its tip on the silicon by van der Waals (27.9 nN) and the
    /// meniscus (27.1 nN) about equally: both are named, the stronger first. With the meniscus
    /// left out (the humidity kept: Eq 4's area needs its Kelvin radius) and 5 V between tip and
    /// substrate, the voltage first.
    #[test]
    fn the_fields_named_follow_the_terms_that_pull_hardest() {
        let humid = scene(&[]);
        let src = humid.tip_sample().adhesion_sources();
        assert_eq!(src, [Attraction::VanDerWaals, Attraction::Capillary]);
        assert_eq!(
            field(Pair::TipSubstrate, &src),
            "tip.hamaker_zj or substrate.hamaker_zj (smaller), or environment.relative_humidity (drier: a shorter meniscus)"
        );

        let charged = scene(&[
            ("capillary = true", "capillary = false"),
            ("electrostatic = false", "electrostatic = true"),
            ("tip_substrate_voltage_v = 0.0", "tip_substrate_voltage_v = 5.0"),
            ("tip_particle_voltage_v = 0.25", "tip_particle_voltage_v = 5.0"),
        ]);
        let src = charged.tip_sample().adhesion_sources();
        assert_eq!(src, [Attraction::Electrostatic]);
        assert!(field(Pair::TipSubstrate, &src).starts_with("environment.tip_substrate_voltage_v (smaller |U|)"));
        // The charged area 4πR r₁ of Eq 4 is the Kelvin radius's: the humidity is named too.
        assert!(field(Pair::TipSubstrate, &src).contains("relative_humidity"));
        let src = charged.push_params().adhesion_ta_sources();
        assert_eq!(src, [Attraction::Electrostatic]);
        assert!(field(Pair::TipParticle, &src).starts_with("environment.tip_particle_voltage_v (smaller |U|)"));
        // The snap-in of a scene without a meniscus: the lever and the attraction.
        let (cause, f) = snap_in_cause(&charged.tip_sample(), || unreachable!("no meniscus"), 1e-9);
        assert_eq!(cause, "the attraction");
        assert!(
            f.starts_with("cantilever.stiffness_n_per_m (stiffer), or environment.tip_substrate_voltage_v"),
            "{f}"
        );
        // With one, its length when the rest alone would not snap the tip in above the parking
        // height: the humidity alone, though van der Waals pulls harder at contact.
        let (cause, f) = snap_in_cause(&humid.tip_sample(), || 1e-9, 50e-9);
        assert_eq!(
            (cause, f.as_str()),
            (
                "the meniscus",
                "environment.relative_humidity (drier: a shorter meniscus)"
            )
        );
        // When the rest would, the attraction (5 V at 38 % humidity on a 0.05 N/m lever snaps
        // in at 60 nm with or without the meniscus).
        let (cause, f) = snap_in_cause(&humid.tip_sample(), || 60e-9, 50e-9);
        assert_eq!(cause, "the attraction");
        assert!(
            !f.contains("humidity") && f.starts_with("cantilever.stiffness_n_per_m"),
            "{f}"
        );
    }

    /// The ranking keeps the terms within a quarter of the strongest, strongest first, and
    /// drops what does not pull.
    #[test]
    fn the_ranking_keeps_terms_within_a_quarter_of_the_strongest() {
        use Attraction::*;
        let r = Attraction::ranked([
            (VanDerWaals, 1.0),
            (Capillary, 4.0),
            (Electrostatic, 0.99),
            (Contact, -1.0),
        ]);
        assert_eq!(r, [Capillary, VanDerWaals]);
        assert!(Attraction::ranked([(Contact, 0.0), (Capillary, f64::NAN)]).is_empty());
    }
}
