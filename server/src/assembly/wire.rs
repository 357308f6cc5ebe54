//! An assembly as the protocol says it: the instrument's plan, moves and site reports in the
//! wire's types (`nanopush_proto::ws`, `nanopush_proto::assembly`), SI throughout.

use nanopush_instrument::assembly::summary::purpose_words as purpose;
use nanopush_instrument::assembly::{Pattern, Plan, Seen, SiteState};
use nanopush_proto::ws::{AssemblyPlan, AssemblySite, MapParticle, PlanMove, PlanSite};

fn xy(p: (f64, f64)) -> [f64; 2] {
    [p.0, p.1]
}

/// The pattern's sites, each with its tolerance (the pattern's, else `tolerance`).
pub(crate) fn sites(pattern: &Pattern, tolerance: f64) -> Vec<AssemblySite> {
    pattern
        .sites
        .iter()
        .map(|s| AssemblySite {
            target: [s.x, s.y],
            tolerance: s.tolerance.unwrap_or(tolerance),
        })
        .collect()
}

/// One move of a plan, with the path of its particle's centre.
pub(crate) fn planned_move(m: &nanopush_instrument::assembly::PlannedMove) -> PlanMove {
    let (purpose, site) = purpose(m.purpose);
    let mut path = vec![xy(m.from)];
    path.extend(m.legs.iter().map(|l| xy(l.to)));
    PlanMove {
        purpose: purpose.into(),
        site,
        particle: m.particle,
        from: xy(m.from),
        to: xy(m.to),
        path,
    }
}

/// A plan made from `map`.
pub(crate) fn plan(plan: &Plan, map: &[Seen]) -> AssemblyPlan {
    AssemblyPlan {
        map: map
            .iter()
            .map(|p| MapParticle {
                x: p.x,
                y: p.y,
                radius: p.radius,
            })
            .collect(),
        sites: plan
            .sites
            .iter()
            .map(|s| match s {
                SiteState::Filled { particle } => PlanSite {
                    state: "filled".into(),
                    particle: Some(*particle),
                    status: None,
                    reason: None,
                },
                SiteState::Planned { particle } => PlanSite {
                    state: "planned".into(),
                    particle: Some(*particle),
                    status: None,
                    reason: None,
                },
                SiteState::Open(u) => PlanSite {
                    state: "open".into(),
                    particle: None,
                    status: Some(u.status().into()),
                    reason: Some(u.reason()),
                },
            })
            .collect(),
        moves: plan.moves.iter().map(planned_move).collect(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nanopush_instrument::assembly::{PlannedMove, Purpose, Unfilled};
    use nanopush_instrument::control::Leg;

    #[test]
    fn a_plan_names_its_particles_by_map_index_and_says_why_a_site_is_open() {
        let map = vec![
            Seen {
                x: 1e-6,
                y: 2e-6,
                radius: 5e-7,
            },
            Seen {
                x: 9e-6,
                y: 2e-6,
                radius: 5e-7,
            },
        ];
        let p = Plan {
            sites: vec![
                SiteState::Planned { particle: 1 },
                SiteState::Open(Unfilled::NoParticle),
                SiteState::Filled { particle: 0 },
            ],
            moves: vec![PlannedMove {
                particle: 1,
                from: (9e-6, 2e-6),
                to: (5e-6, 6e-6),
                purpose: Purpose::Fill { site: 0 },
                legs: vec![
                    Leg {
                        from: (9e-6, 2e-6),
                        to: (5e-6, 2e-6),
                    },
                    Leg {
                        from: (5e-6, 2e-6),
                        to: (5e-6, 6e-6),
                    },
                ],
            }],
        };
        let w = plan(&p, &map);
        assert_eq!(w.map.len(), 2);
        assert_eq!((w.sites[0].state.as_str(), w.sites[0].particle), ("planned", Some(1)));
        assert_eq!(w.sites[1].status.as_deref(), Some("unreachable"));
        assert_eq!(
            w.sites[1].reason.as_deref(),
            Some("no particle of the pattern's size is left for it")
        );
        assert_eq!(w.sites[2].state, "filled");
        let m = &w.moves[0];
        assert_eq!((m.purpose.as_str(), m.site, m.particle), ("fill", Some(0), 1));
        assert_eq!(m.path, vec![[9e-6, 2e-6], [5e-6, 2e-6], [5e-6, 6e-6]]);
    }
}
