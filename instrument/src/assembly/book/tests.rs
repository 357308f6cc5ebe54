//! The book: what a move's report does to the map and the plan.

use super::*;
use crate::assembly::pattern::Site;
use crate::scan::Tip;

const UM: f64 = 1e-6;

fn book(sites: &[(f64, f64)]) -> Book {
    let pattern = Pattern {
        name: "test".into(),
        sites: sites
            .iter()
            .map(|&(x, y)| Site {
                x: x * UM,
                y: y * UM,
                tolerance: None,
            })
            .collect(),
        radius: Some(0.5 * UM),
    };
    let settings = PlanSettings {
        tolerance: 25e-9,
        clearance: 0.5 * UM,
        max_push: 20.0 * UM,
        approach: 2.0 * UM,
        tip_radius: 30e-9,
        range: 100.0 * UM,
    };
    let tip = Tip {
        radius: 30e-9,
        half_angle: 0.3,
    };
    Book::new(&pattern, AssemblyOptions::default(), settings, tip, 0.0)
}

fn seen(x: f64, y: f64) -> Seen {
    Seen {
        x: x * UM,
        y: y * UM,
        radius: 0.5 * UM,
    }
}

/// A particle twice the pattern's size: one the pattern does not need.
fn big(x: f64, y: f64) -> Seen {
    Seen {
        radius: 1.0 * UM,
        ..seen(x, y)
    }
}

fn report(mv: &PlannedMove, outcome: &str, absent: bool) -> MoveDone {
    MoveDone {
        record: MoveRecord {
            purpose: mv.purpose,
            particle: Some(7),
            from: mv.from,
            to: mv.to,
            outcome: outcome.into(),
            error: None,
            pushes: 0,
            push_time: 0.0,
        },
        failed: true,
        absent,
        ended: None,
        path: Vec::new(),
        images: Vec::new(),
    }
}

#[test]
fn a_particle_the_scan_does_not_find_is_not_sent_again() {
    // One site with a particle the pattern does not need on it (to clear), and one to fill it.
    let mut b = book(&[(50.0, 50.0)]);
    b.start(vec![seen(40.0, 50.0), big(51.2, 50.0)]).unwrap();
    let first = b.next_move().cloned().unwrap();
    assert_eq!((first.particle, first.purpose), (1, Purpose::Clear), "{:?}", b.plan());
    b.moved(&first, report(&first, "not_found: nothing there", true));
    assert_eq!(b.map().len(), 2, "kept on the map: {:?}", b.map());
    assert!(b.plan().moves.iter().all(|m| m.particle != 1), "{:?}", b.plan());
}

#[test]
fn a_particle_lost_after_its_pushes_stays_on_the_map_until_excluded() {
    let mut b = book(&[(50.0, 50.0)]);
    b.start(vec![seen(40.0, 50.0), seen(30.0, 50.0)]).unwrap();
    let first = b.next_move().cloned().unwrap();
    let k = first.particle;
    b.moved(&first, report(&first, "lost", false));
    assert_eq!(b.map().len(), 2);
    let again = b.next_move().cloned().unwrap();
    assert_eq!(again.particle, k, "sent again after one failure");
    b.moved(&again, report(&again, "lost", false));
    assert_eq!(b.map().len(), 2);
    let other = b.next_move().unwrap();
    assert_ne!(other.particle, k, "excluded after two failures: {:?}", b.plan());
}

#[test]
fn a_particle_the_scan_does_not_find_is_still_kept_clear_of() {
    // A particle across the fill's straight line, reported not found where the map has it: the
    // fill still goes around it (a scan in a crowded window can miss a particle that is there).
    let mut b = book(&[(50.0, 50.0)]);
    b.start(vec![seen(40.0, 50.0), big(45.0, 50.0)]).unwrap();
    let unfound = PlannedMove {
        particle: 1,
        from: (45.0 * UM, 50.0 * UM),
        to: (45.0 * UM, 60.0 * UM),
        purpose: Purpose::Clear,
        legs: Vec::new(),
    };
    b.moved(&unfound, report(&unfound, "not_found", true));
    let fill = b.next_move().unwrap();
    assert_eq!((fill.particle, fill.purpose), (0, Purpose::Fill { site: 0 }));
    assert!(fill.legs.len() > 1, "a detour around it: {fill:?}");
    assert!(b.plan().moves.iter().all(|m| m.particle != 1), "{:?}", b.plan());
}

#[test]
fn a_site_far_off_the_stage_is_refused_without_planning() {
    let mut b = book(&[(1e308, 50.0), (1e308, 54.0)]);
    let why = b.start(vec![seen(40.0, 50.0)]).unwrap_err();
    assert!(why.contains("off the stage"), "{why}");
    assert!(b.plan().moves.is_empty(), "{:?}", b.plan());
}

#[test]
fn a_refused_pattern_marks_every_site_refused_with_the_reason() {
    // Two sites on top of each other: refused before anything moves, and no site is said to
    // be missed or blocked by a particle the plan only imagined there.
    let mut b = book(&[(50.0, 50.0), (50.0, 50.0)]);
    let why = b.start(vec![seen(40.0, 50.0), seen(30.0, 50.0)]).unwrap_err();
    assert!(why.contains("sites 0 and 1 are 0.000 µm apart"), "{why}");
    assert!(b.plan().moves.is_empty(), "{:?}", b.plan());
    let report = b.judge(&[seen(40.0, 50.0), seen(30.0, 50.0)], &|_| None);
    for r in &report {
        assert_eq!(r.status, "refused", "{r:?}");
        assert_eq!(r.reason.as_deref(), Some(why.as_str()));
    }
}

#[test]
fn a_miss_without_a_push_gives_the_site_up_at_once() {
    // The particle ended 2.7 nm from its site, with a 1 nm tolerance: the move made no push
    // (no push corrects that little), so sending it again would make no push either.
    let mut b = book(&[(50.0, 50.0)]);
    b.pattern.sites[0].tolerance = Some(1e-9);
    b.start(vec![seen(40.0, 50.0)]).unwrap();
    let first = b.next_move().cloned().unwrap();
    let mut done = report(&first, "missed", false);
    done.failed = false;
    done.record.error = Some(2.7e-9);
    b.moved(&first, done);
    assert!(b.next_move().is_none(), "{:?}", b.plan());
    match &b.plan().sites[0] {
        SiteState::Open(Unfilled::Missed(why)) => {
            assert!(why.contains("2.7 nm from it, nearer than a push can correct"), "{why}");
            assert!(why.contains("outside its 1.0 nm tolerance"), "{why}");
        }
        other => panic!("{other:?}"),
    }
}

#[test]
fn a_site_never_tried_says_so_at_the_end() {
    let mut b = book(&[(50.0, 50.0), (54.0, 50.0)]);
    b.start(vec![seen(40.0, 50.0), seen(60.0, 50.0)]).unwrap();
    // Stopped before any move: the last frame shows the particles where they were.
    let last = b.map().to_vec();
    let sites = b.judge(&last, &|_| None);
    for s in &sites {
        assert_eq!(s.status, "missed");
        assert_eq!(
            s.reason.as_deref(),
            Some("never tried: the assembly ended before its move")
        );
    }
}
