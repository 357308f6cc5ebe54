//! Where the contact is read and how high the tip meets the particle: a push that bends the
//! lever away from the set point's side, a contact read on the pull side, and a push that
//! follows the substrate's slope.

use super::documented_tests::assert_digits;
use super::tests::{assert_retracted, bare_strategy, push, reading, scene};
use super::*;
use crate::afm::Afm;
use crate::scene::Scene;

const UM: f64 = 1e-6;

/// docs/manipulation.md on the shipped scenes ("Sensor gains and the shipped scenes"): `minimal`
/// aims at β = 45° because "at 30° its push bends the lever down and the set point is never
/// reached" (the scene file: "ζ_z → −1.15 nm"). With only van der Waals forces and no rotation,
/// meniscus or particle z, the model's `ζ_z` at 30° never rises above zero and settles at −1.15 nm;
/// the instrument's search pushes the particle ahead without the reading ever reaching ζ_set, and
/// fails with `no_contact`.
#[test]
fn a_push_that_bends_the_lever_down_never_reaches_the_set_point() {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/minimal.toml");
    let text = std::fs::read_to_string(&path).unwrap();
    let (from, to) = ("particle_id = 1\n", "particle_id = 1\ncontact_angle_deg = 30.0\n");
    assert!(text.contains(from), "the minimal scene's [push]");
    let s = Scene::parse("minimal at 30°", &text.replacen(from, to, 1)).unwrap();
    let params = s.strategy_params(1e-3);
    let p = s.pushed_particle();
    let prep = Prepared::new(&s, p.id, p.radius_nm * 1e-9, &params).unwrap();
    let model = prep.prediction;
    assert_eq!(
        model.travel_to_deflection, None,
        "the model never reaches ζ_set: {model:?}"
    );
    assert!(model.peak_deflection <= 1e-15, "ζ_z never rises: {model:?}");
    assert_digits("settled ζ_z at 30° (nm)", model.settled_deflection / 1e-9, -1.15, 0.005);
    let run = push(&s, 1.0 * UM, (0.0, 0.0));
    assert!(
        matches!(run.summary.failure, Some(Failure::NoContact { .. })),
        "{:?}",
        run.summary.failure
    );
    let lowest = run.trace.iter().map(|r| r.volts).fold(f64::INFINITY, f64::min);
    assert!(lowest > params.set_point, "the reading reached {lowest} V");
    assert!(
        run.search_distance() > 1.0 * UM,
        "the search pushed it {:e} m",
        run.search_distance()
    );
    assert_retracted(&run);
}

/// A contact read on the pull side (the set point and the safety limit mirrored about the
/// baseline): a push-side reading as far out as the set point does not stop the search, the
/// pull-side one does, and past the pull-side safety limit the push fails with the limit's
/// reading and backs off.
#[test]
fn a_contact_read_on_the_pull_side_stops_and_is_limited_there() {
    let (mut st, start) = bare_strategy();
    let p = st.params;
    st.params.set_point = 2.0 * p.baseline - p.set_point;
    st.params.safety_limit = 2.0 * p.baseline - p.safety_limit;
    st.params.contact_side = crate::control::estimator::ContactSide::Pull;
    st.phase = Phase::ContactSearch {
        step: 1,
        in_step: 0.0,
        dwell: 0,
    };
    let mut t = 0.0;
    let mut at = start;
    let mut feed = |st: &mut Strategy, volts: f64| {
        t += 1e-3;
        at = st.tick(&reading(t, volts, at));
    };
    for _ in 0..5 {
        feed(&mut st, p.set_point);
    }
    assert!(matches!(st.phase, Phase::ContactSearch { .. }), "{:?}", st.phase);
    assert_eq!(st.summary.contact_step, None);
    let (set, limit) = (st.params.set_point, st.params.safety_limit);
    feed(&mut st, set);
    assert!(matches!(st.phase, Phase::Push { .. }), "{:?}", st.phase);
    let beyond = limit + (limit - p.baseline) * 0.01;
    feed(&mut st, beyond);
    match st.summary.failure {
        Some(Failure::DeflectionLimit { volts, limit, phase }) => {
            assert_eq!((volts, limit, phase), (beyond, st.params.safety_limit, "push"));
            assert!((volts - p.baseline) * p.polarity < 0.0, "on the pull side: {volts} V");
        }
        ref other => panic!("{other:?}"),
    }
    // Straight up (never parked here, so already at the start height: done).
    assert!(matches!(st.phase, Phase::Retract | Phase::Done), "{:?}", st.phase);
}

/// gold-latex's substrate rises 6 nm per µm along +x. Held at one height (the paper's push, its
/// Fig 15), the stage keeps the height it parked at through the contact search and the push;
/// following the slope the request carries, it rises with the substrate by the slope times its
/// travel in both (the behaviour this buys is checked on the scenes it changes, in
/// `derive::tests`: lab seeds 103 and 128).
#[test]
fn a_push_that_follows_the_slope_rises_with_the_substrate() {
    let rises = |follow: bool| {
        let s = scene(&[(
            "follow_slope = false",
            if follow {
                "follow_slope = true"
            } else {
                "follow_slope = false"
            },
        )]);
        let p = s.pushed_particle();
        let (x, y) = (p.x_um * UM, p.y_um * UM);
        let mut afm = Afm::from_scene(&s, x - 6.0 * UM, y, 1e-3);
        let request = PushRequest {
            id: p.id,
            particle: (x, y),
            radius: p.radius_nm * 1e-9,
            direction: (1.0, 0.0),
            distance: UM,
            pause: None,
            slope: (6e-3, 0.0),
        };
        let run = push_once(&s, &mut afm, &request, s.strategy_params(1e-3)).unwrap();
        assert_eq!(run.summary.failure, None);
        // Rise against travel over each phase, from its first row to its last.
        ["contact_search", "push"].map(|phase| {
            let rows: Vec<_> = run.trace.iter().filter(|r| r.phase == phase).collect();
            let (a, b) = (rows[0], rows[rows.len() - 1]);
            (b.stage[2] - a.stage[2], b.stage[0] - a.stage[0])
        })
    };
    for (rise, travel) in rises(false) {
        assert!(travel > 0.5 * UM);
        assert_eq!(rise, 0.0);
    }
    for (rise, travel) in rises(true) {
        assert!(travel > 0.5 * UM);
        assert!((rise - 6e-3 * travel).abs() < 1e-12, "{rise:e} over {travel:e}");
    }
}
