//! The strategy fed readings by hand through auto-parking: a reading saturated on the pull
//! side is ridden out while the tip rises off the substrate and within the rise its pull-off
//! needs (`strategy::pull_off`); the push side, and a pull that lasts too long, still fail.

use super::tests::{bare_strategy, reading};
use super::*;

/// Where the strategy is after feeding it readings at `volts(rise)` (the stage where it asked,
/// `rise` above the detected substrate) until `stop` says so or 100 000 ticks; the phases it
/// went through.
struct Fed {
    st: Strategy,
    t: f64,
    at: [f64; 3],
    phases: Vec<&'static str>,
}

impl Fed {
    /// The gold-latex strategy brought to the z approach at the baseline, its lever as soft
    /// as to need twice the parking height's rise to let go (the bound's derivation is
    /// `physics::force_curve::tests::the_tip_hangs_free_within_its_release_distance`).
    fn parking() -> Fed {
        let (mut st, start) = bare_strategy();
        st.params.pull_off_rise = 2.0 * st.task.parking_rise();
        let mut fed = Fed {
            st,
            t: 0.0,
            at: start,
            phases: Vec::new(),
        };
        let baseline = fed.st.params.baseline;
        fed.run(|_| baseline, |st| st.phase == Phase::Park);
        fed
    }

    /// The reading on the readout's rail on the pull side (the lever bent toward the substrate).
    fn pull_rail(&self) -> f64 {
        -self.st.params.polarity * self.st.params.full_scale
    }

    /// The rail on the push side.
    fn push_rail(&self) -> f64 {
        self.st.params.polarity * self.st.params.full_scale
    }

    fn run(&mut self, volts: impl Fn(f64) -> f64, stop: impl Fn(&Strategy) -> bool) {
        for _ in 0..100_000 {
            if stop(&self.st) || self.st.done() {
                return;
            }
            self.t += 1e-3;
            let rise = self.st.summary.substrate_z.map_or(0.0, |zs| self.at[2] - zs);
            self.at = self.st.tick(&reading(self.t, volts(rise), self.at));
            let name = self.st.phase.name();
            if self.phases.last() != Some(&name) {
                self.phases.push(name);
            }
        }
        panic!("the strategy never got there: {:?}", self.phases);
    }
}

/// A soft lever's snap-in and pull-off: the reading sits on the pull-side rail from the touch
/// until the tip has risen 60 % of the rise its pull-off may take (past the parking height),
/// and the strategy rides it out: it detects the substrate, rises past the parking height
/// until the tip lets go, comes back down and starts the contact search, with no failure.
#[test]
fn a_pull_side_saturation_is_ridden_out_until_the_tip_lets_go() {
    let mut fed = Fed::parking();
    let allowed = fed.st.params.pull_off_rise;
    let parking = fed.st.task.parking_rise();
    assert!(allowed > parking, "allowed {allowed:e} m, parking rise {parking:e} m");
    let (rail, baseline) = (fed.pull_rail(), fed.st.params.baseline);
    let free_above = parking.max(0.6 * allowed);
    // Free from the first rise past `free_above` on.
    let free = std::cell::Cell::new(false);
    fed.run(
        |rise| {
            free.set(free.get() || rise > free_above);
            if free.get() { baseline } else { rail }
        },
        |st| matches!(st.phase, Phase::ContactSearch { .. }),
    );
    assert_eq!(fed.st.summary.failure, None, "{:?}", fed.phases);
    assert_eq!(
        fed.phases,
        [
            "travel",
            "park",
            "to_parking_height",
            "let_go",
            "to_parking_height",
            "contact_search"
        ]
    );
    let zs = fed.st.summary.substrate_z.expect("detected");
    assert!((fed.at[2] - zs - parking).abs() < 1e-12, "back at the parking height");
}

/// A pull that outlasts the rise the pull-off needs fails with `still_held`, naming the rise and
/// the bound, and the tip goes straight up.
#[test]
fn a_pull_side_saturation_that_lasts_too_long_fails_still_held() {
    let mut fed = Fed::parking();
    let rail = fed.pull_rail();
    fed.run(|_| rail, |st| st.summary.failure.is_some());
    let allowed = fed.st.params.pull_off_rise;
    match fed.st.summary.failure {
        Some(
            f @ Failure::StillHeld {
                rise_nm,
                bound_nm,
                phase,
            },
        ) => {
            assert_eq!(f.code(), "still_held");
            assert_eq!(phase, "let_go");
            assert!((bound_nm - allowed * 1e9).abs() < 1e-9);
            assert!(rise_nm > bound_nm && rise_nm < bound_nm + 2.0, "{f}");
            assert!(f.to_string().contains("still held"), "{f}");
        }
        other => panic!("{other:?} ({:?})", fed.phases),
    }
    assert_eq!(fed.st.phase, Phase::Retract);
}

/// The push side is an emergency in every phase, rising or not: in the rise to the parking
/// height and in the rise that lets go.
#[test]
fn a_push_side_saturation_trips_the_deflection_limit_while_rising() {
    for in_let_go in [false, true] {
        let mut fed = Fed::parking();
        let (pull, push) = (fed.pull_rail(), fed.push_rail());
        // Snap in (the pull rail), and rise on it.
        fed.run(
            |_| pull,
            |st| {
                if in_let_go {
                    matches!(st.phase, Phase::LetGo { .. })
                } else {
                    matches!(st.phase, Phase::ToParkingHeight { .. })
                }
            },
        );
        fed.run(|_| push, |st| st.summary.failure.is_some());
        match fed.st.summary.failure {
            Some(Failure::DeflectionLimit { volts, phase, .. }) => {
                assert_eq!(volts, push);
                assert_eq!(phase, if in_let_go { "let_go" } else { "to_parking_height" });
            }
            other => panic!("{other:?} ({:?})", fed.phases),
        }
        assert_eq!(fed.st.phase, Phase::Retract);
    }
}

/// Elsewhere the pull side is still an emergency: in the contact search (the tip moves along the
/// substrate, not away from it).
#[test]
fn a_pull_side_saturation_while_searching_trips_the_deflection_limit() {
    let mut fed = Fed::parking();
    let (pull, baseline) = (fed.pull_rail(), fed.st.params.baseline);
    fed.run(
        |rise| if rise <= 0.0 { pull } else { baseline },
        |st| matches!(st.phase, Phase::ContactSearch { .. }),
    );
    fed.run(|_| pull, |st| st.summary.failure.is_some());
    assert!(
        matches!(
            fed.st.summary.failure,
            Some(Failure::DeflectionLimit {
                phase: "contact_search",
                ..
            })
        ),
        "{:?}",
        fed.st.summary.failure
    );
}

/// A tip that let go above the parking height and is held again when it gets back down has
/// snapped back onto the substrate: `snapped_back`.
#[test]
fn a_tip_held_again_at_the_parking_height_fails_snapped_back() {
    let mut fed = Fed::parking();
    let (pull, baseline) = (fed.pull_rail(), fed.st.params.baseline);
    let parking = fed.st.task.parking_rise();
    fed.run(|_| pull, |st| matches!(st.phase, Phase::LetGo { .. }));
    fed.run(|_| baseline, |st| matches!(st.phase, Phase::ToParkingHeight { .. }));
    // Held (past the substrate threshold on the pull side, not saturated) on the way down.
    let held = baseline - fed.st.params.polarity * 2.0 * fed.st.params.substrate_threshold;
    fed.run(|_| held, |st| st.summary.failure.is_some());
    match fed.st.summary.failure {
        Some(f @ Failure::SnappedBack { height_nm }) => {
            assert_eq!(f.code(), "snapped_back");
            assert!((height_nm - parking * 1e9).abs() < 1e-6, "{f}");
        }
        other => panic!("{other:?} ({:?})", fed.phases),
    }
}
