//! Routes: straight legs, detours, the stage's edges.

use super::*;

const UM: f64 = 1e-6;

fn router() -> Router {
    Router {
        radius: 0.5 * UM,
        edge_radius: 0.5 * UM,
        max_push: 12.0 * UM,
        clearance: 0.5 * UM,
        run_up: 5.0 * UM,
        tip_radius: 0.03 * UM,
        range: 100.0 * UM,
    }
}

fn clear_of(legs: &[Leg], o: &Obstacle, p: &Router) -> bool {
    legs.iter().all(|l| p.blocker(l.from, l.to, &[*o]).is_none())
}

#[test]
fn a_short_clear_move_is_one_leg() {
    let legs = router()
        .route((40.0 * UM, 30.0 * UM), (45.0 * UM, 30.0 * UM), &[])
        .unwrap();
    assert_eq!(legs.len(), 1);
    assert!((legs[0].length() - 5.0 * UM).abs() < 1e-12);
}

#[test]
fn a_long_move_is_split_into_equal_legs_within_the_longest_push() {
    let p = router();
    let legs = p.route((10.0 * UM, 10.0 * UM), (40.0 * UM, 50.0 * UM), &[]).unwrap();
    // 50 µm in legs of at most 12 µm: 5 legs of 10 µm, end to end.
    assert_eq!(legs.len(), 5);
    for w in legs.windows(2) {
        assert_eq!(w[0].to, w[1].from);
    }
    assert!(legs.iter().all(|l| (l.length() - 10.0 * UM).abs() < 1e-9));
    assert_eq!(legs.last().unwrap().to, (40.0 * UM, 50.0 * UM));
}

#[test]
fn a_blocked_line_goes_around_the_blocker() {
    let p = router();
    let o = Obstacle {
        x: 50.0 * UM,
        y: 30.2 * UM,
        radius: 0.5 * UM,
    };
    let (from, to) = ((40.0 * UM, 30.0 * UM), (60.0 * UM, 30.0 * UM));
    assert!(p.blocker(from, to, &[o]).is_some());
    let legs = p.route(from, to, &[o]).unwrap();
    assert!(legs.len() >= 2);
    assert!(clear_of(&legs, &o, &p));
    assert_eq!(legs.first().unwrap().from, from);
    assert_eq!(legs.last().unwrap().to, to);
}

/// A push to 99.9 µm of a 1 µm particle would take its centre to 100.88 µm (the push goes
/// 0.977 µm further for the retraction's drag). The target must keep the particle
/// on the stage whole; the push's overshoot is cut where it would leave it; a push the tip
/// cannot get behind is refused.
#[test]
fn the_whole_way_stays_on_the_stage_target_overshoot_and_the_tips_reach() {
    let p = Router {
        radius: 1.0 * UM,
        edge_radius: 1.0 * UM,
        ..router()
    };
    let e = p
        .route((59.9 * UM, 50.0 * UM), (99.9 * UM, 50.0 * UM), &[])
        .unwrap_err();
    assert_eq!(
        e.to_string(),
        "target (99.90, 50.00) µm is outside the stage for a particle 1.000 µm in radius; allowed: [1.000, 99.000] µm in x and y"
    );
    assert!(p.route((59.0 * UM, 50.0 * UM), (99.0 * UM, 50.0 * UM), &[]).is_ok());
    // The push's overshoot stops where the particle would leave the stage: 0.5 µm left of
    // the 0.977 µm, along x; along y nothing; diagonally, the nearer edge.
    let r = 1.0 * UM;
    assert!((travel_on_stage((98.5 * UM, 50.0 * UM), (1.0, 0.0), r, 100.0 * UM) - 0.5 * UM).abs() < 1e-12);
    assert!((travel_on_stage((98.5 * UM, 50.0 * UM), (-1.0, 0.0), r, 100.0 * UM) - 97.5 * UM).abs() < 1e-12);
    let diag = (0.6, 0.8);
    assert!((travel_on_stage((90.0 * UM, 95.0 * UM), diag, r, 100.0 * UM) - 5.0 * UM).abs() < 1e-12);
    assert_eq!(travel_on_stage((99.5 * UM, 50.0 * UM), (1.0, 0.0), r, 100.0 * UM), 0.0);
    // Pushed toward −x from 99.5 µm: the tip would have to be at 100.53 µm.
    let leg = |from: f64, to: f64| Leg {
        from: (from * UM, 50.0 * UM),
        to: (to * UM, 50.0 * UM),
    };
    let e = check_reach(&[leg(40.0, 41.0), leg(99.5, 90.0)], 1.03 * UM, 100.0 * UM).unwrap_err();
    assert!(
        e.to_string().starts_with(
            "push 2 would need the tip at (100.530, 50.000) µm, off the stage: allowed [0.000, 100.000] µm"
        ),
        "{e}"
    );
    assert_eq!(check_reach(&[leg(98.97, 90.0)], 1.03 * UM, 100.0 * UM), Ok(()));
}

#[test]
fn targets_outside_the_stage_and_walled_in_paths_are_refused() {
    let p = router();
    let e = p
        .route((40.0 * UM, 30.0 * UM), (140.0 * UM, 30.0 * UM), &[])
        .unwrap_err();
    assert!(e.to_string().contains("allowed: [0.500, 99.500] µm in x and y"), "{e}");
    // A wall of particles across the whole path, 3 µm apart.
    let wall: Vec<Obstacle> = (0..=33)
        .map(|k| Obstacle {
            x: 50.0 * UM,
            y: k as f64 * 3.0 * UM,
            radius: 0.5 * UM,
        })
        .collect();
    let e = p
        .route((40.0 * UM, 30.0 * UM), (60.0 * UM, 30.0 * UM), &wall)
        .unwrap_err();
    assert!(matches!(e, RouteError::Blocked { .. }), "{e}");
}

/// A U-shaped pocket around the start: the straight line and both side-steps run into its
/// walls, and the route leaves through the open side and goes around.
#[test]
fn a_route_leaves_a_pocket_that_blocks_every_side_step() {
    let p = router();
    let mut walls = Vec::new();
    // The pocket opens toward −x: walls at x = 56 µm (the back) and y = 22, 38 µm (the sides),
    // deep enough for the run-up behind a push out of it.
    for k in 0..=16 {
        let y = 22.0 + k as f64;
        walls.push(Obstacle {
            x: 56.0 * UM,
            y: y * UM,
            radius: 0.5 * UM,
        });
    }
    for k in 0..=16 {
        let x = 40.0 + k as f64;
        walls.push(Obstacle {
            x: x * UM,
            y: 22.0 * UM,
            radius: 0.5 * UM,
        });
        walls.push(Obstacle {
            x: x * UM,
            y: 38.0 * UM,
            radius: 0.5 * UM,
        });
    }
    let (from, to) = ((46.0 * UM, 30.0 * UM), (64.0 * UM, 30.0 * UM));
    let legs = p.route(from, to, &walls).unwrap();
    assert_eq!(legs.first().unwrap().from, from);
    assert_eq!(legs.last().unwrap().to, to);
    for w in legs.windows(2) {
        assert_eq!(w[0].to, w[1].from);
    }
    for l in &legs {
        assert!(p.blocker(l.from, l.to, &walls).is_none(), "{l:?} crosses a wall");
        assert!(l.length() <= p.max_push + 1e-12, "{l:?}");
    }
    // It leaves by the open side: some waypoint lies left of the pocket's mouth (x < 40 µm).
    assert!(legs.iter().any(|l| l.to.0 < 40.0 * UM), "{legs:?}");
}

/// A pocket shallower than the run-up holds its particle: a push out of it needs the tip
/// behind the particle, inside the back wall.
#[test]
fn a_pocket_shallower_than_the_run_up_is_blocked() {
    let p = router();
    let mut walls = Vec::new();
    for k in 0..=12 {
        walls.push(Obstacle {
            x: 46.0 * UM,
            y: (24.0 + k as f64) * UM,
            radius: 0.5 * UM,
        });
    }
    for k in 0..=10 {
        let x = 36.0 + k as f64;
        walls.push(Obstacle {
            x: x * UM,
            y: 24.0 * UM,
            radius: 0.5 * UM,
        });
        walls.push(Obstacle {
            x: x * UM,
            y: 36.0 * UM,
            radius: 0.5 * UM,
        });
    }
    let e = p
        .route((42.0 * UM, 30.0 * UM), (55.0 * UM, 30.0 * UM), &walls)
        .unwrap_err();
    assert!(matches!(e, RouteError::Blocked { .. }), "{e}");
}

/// Every waypoint re-parks: of two routes, the one with fewer turns wins unless the other is
/// shorter by more than a run-up a turn.
#[test]
fn a_route_turns_no_more_than_it_must() {
    let p = router();
    // Two particles side by side across the line, a gap between them too narrow to pass.
    let pair = [
        Obstacle {
            x: 50.0 * UM,
            y: 29.0 * UM,
            radius: 0.5 * UM,
        },
        Obstacle {
            x: 50.0 * UM,
            y: 31.0 * UM,
            radius: 0.5 * UM,
        },
    ];
    let (from, to) = ((40.0 * UM, 30.0 * UM), (60.0 * UM, 30.0 * UM));
    let legs = p.route(from, to, &pair).unwrap();
    let corners = legs.windows(2).filter(|w| {
        let (a, b) = (w[0].direction(), w[1].direction());
        (a.0 * b.1 - a.1 * b.0).abs() > 1e-9
    });
    assert_eq!(corners.count(), 1, "{legs:?}");
}

proptest::proptest! {
    #![proptest_config(proptest::prelude::ProptestConfig::with_cases(64))]
    /// On random fields of up to 60 particles, a route found is clear of every particle leg by
    /// leg (its run-up included), on the stage, made of pushes no longer than the longest, and
    /// ends at the target; none found means the straight line was blocked.
    #[test]
    fn a_route_through_a_random_field_is_clear_leg_by_leg(
        field in proptest::collection::vec((5.0f64..95.0, 5.0f64..95.0, 0.2f64..1.5), 0..60),
        from in (10.0f64..90.0, 10.0f64..90.0),
        to in (10.0f64..90.0, 10.0f64..90.0),
    ) {
        let p = router();
        let (from, to) = ((from.0 * UM, from.1 * UM), (to.0 * UM, to.1 * UM));
        let obstacles: Vec<Obstacle> = field
            .iter()
            .map(|&(x, y, r)| Obstacle { x: x * UM, y: y * UM, radius: r * UM })
            .filter(|o| {
                let keep = |q: (f64, f64)| (o.x - q.0).hypot(o.y - q.1) > p.radius + o.radius + p.clearance;
                keep(from) && keep(to)
            })
            .collect();
        match p.route(from, to, &obstacles) {
            Ok(legs) => {
                proptest::prop_assert_eq!(legs.first().map(|l| l.from), Some(from));
                proptest::prop_assert_eq!(legs.last().map(|l| l.to), Some(to));
                for l in &legs {
                    proptest::prop_assert!(p.blocker(l.from, l.to, &obstacles).is_none(), "{:?}", l);
                    proptest::prop_assert!(l.length() <= p.max_push * (1.0 + 1e-9));
                    proptest::prop_assert!(on_stage(l.to, p.edge_radius, p.range));
                }
            }
            Err(RouteError::Blocked { .. }) => {
                proptest::prop_assert!(p.blocker(from, to, &obstacles).is_some());
            }
            Err(e) => proptest::prop_assert!(false, "{e}"),
        }
    }
}
