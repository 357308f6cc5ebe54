//! Which particle goes to which site: a minimum-cost bipartite matching (the Hungarian method,
//! Kuhn-Munkres, from the `pathfinding` crate) of the open sites against the particles that
//! may fill them, at the straight distance from each particle to each site (Barredo et al.,
//! Science 354, 2016, assign atoms to sites the same way).
//!
//! The method wants no more rows than columns: with fewer particles than sites, the sites are
//! matched against the particles plus one stand-in per missing particle, at a cost above every
//! real one, and a site matched to a stand-in has no particle.

use pathfinding::kuhn_munkres::kuhn_munkres_min;
use pathfinding::matrix::Matrix;

/// Costs are the distance in picometres: integers, exact to far below anything a scan resolves,
/// and a 1000 µm stage is 10⁹ of them.
const PER_METRE: f64 = 1e12;

/// The particle index for each site (`None`: no particle left for it), at least total distance.
/// `eligible(site, particle)` says which particle may go to which site.
pub fn assign(
    sites: &[(f64, f64)],
    particles: &[(f64, f64)],
    eligible: impl Fn(usize, usize) -> bool,
) -> Vec<Option<usize>> {
    if sites.is_empty() {
        return Vec::new();
    }
    let n = particles.len();
    let columns = n.max(sites.len());
    // Above any real cost: a site goes to a stand-in (or an ineligible particle) only when the
    // real ones run out.
    let far: i64 = (2e-3 * PER_METRE) as i64 * (sites.len() as i64 + 1);
    let mut m = Matrix::new(sites.len(), columns, far);
    for (i, s) in sites.iter().enumerate() {
        for (j, p) in particles.iter().enumerate() {
            if eligible(i, j) {
                m[(i, j)] = ((s.0 - p.0).hypot(s.1 - p.1) * PER_METRE).round() as i64;
            }
        }
    }
    let (_, cols) = kuhn_munkres_min(&m);
    cols.into_iter()
        .enumerate()
        .map(|(i, j)| (j < n && eligible(i, j)).then_some(j))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The total distance of an assignment.
    fn total(sites: &[(f64, f64)], particles: &[(f64, f64)], a: &[Option<usize>]) -> f64 {
        a.iter()
            .enumerate()
            .filter_map(|(i, j)| j.map(|j| (sites[i].0 - particles[j].0).hypot(sites[i].1 - particles[j].1)))
            .sum()
    }

    /// Every permutation of `k` of `n` particles, for the brute force.
    fn permutations(n: usize, k: usize) -> Vec<Vec<usize>> {
        if k == 0 {
            return vec![Vec::new()];
        }
        let mut out = Vec::new();
        for rest in permutations(n, k - 1) {
            for j in 0..n {
                if !rest.contains(&j) {
                    let mut v = rest.clone();
                    v.push(j);
                    out.push(v);
                }
            }
        }
        out
    }

    #[test]
    fn two_crossed_particles_are_assigned_uncrossed() {
        let sites = [(0.0, 0.0), (10e-6, 0.0)];
        let particles = [(11e-6, 1e-6), (-1e-6, 1e-6)];
        assert_eq!(assign(&sites, &particles, |_, _| true), vec![Some(1), Some(0)]);
    }

    #[test]
    fn with_fewer_particles_than_sites_the_far_site_goes_without() {
        let sites = [(0.0, 0.0), (50e-6, 0.0), (1e-6, 0.0)];
        let particles = [(0.5e-6, 1e-6), (2e-6, 0.0)];
        let a = assign(&sites, &particles, |_, _| true);
        assert_eq!(a[1], None);
        assert_eq!(a.iter().flatten().count(), 2);
    }

    #[test]
    fn an_ineligible_particle_is_never_sent() {
        let sites = [(0.0, 0.0)];
        let particles = [(0.1e-6, 0.0), (30e-6, 0.0)];
        assert_eq!(assign(&sites, &particles, |_, j| j == 1), vec![Some(1)]);
        assert_eq!(assign(&sites, &particles, |_, _| false), vec![None]);
    }

    proptest::proptest! {
        /// On random layouts of up to 6 sites and 7 particles, the matching's total distance
        /// equals the brute force's best.
        #[test]
        fn the_assignment_is_the_least_total_distance(
            sites in proptest::collection::vec((0.0f64..100.0, 0.0f64..100.0), 1..6),
            particles in proptest::collection::vec((0.0f64..100.0, 0.0f64..100.0), 1..7),
        ) {
            let sites: Vec<(f64, f64)> = sites.iter().map(|p| (p.0 * 1e-6, p.1 * 1e-6)).collect();
            let particles: Vec<(f64, f64)> = particles.iter().map(|p| (p.0 * 1e-6, p.1 * 1e-6)).collect();
            let a = assign(&sites, &particles, |_, _| true);
            let k = sites.len().min(particles.len());
            proptest::prop_assert_eq!(a.iter().flatten().count(), k);
            let best = if sites.len() <= particles.len() {
                permutations(particles.len(), sites.len())
                    .iter()
                    .map(|p| total(&sites, &particles, &p.iter().map(|&j| Some(j)).collect::<Vec<_>>()))
                    .fold(f64::INFINITY, f64::min)
            } else {
                permutations(sites.len(), particles.len())
                    .iter()
                    .map(|p| {
                        let mut a = vec![None; sites.len()];
                        for (j, &i) in p.iter().enumerate() {
                            a[i] = Some(j);
                        }
                        total(&sites, &particles, &a)
                    })
                    .fold(f64::INFINITY, f64::min)
            };
            proptest::prop_assert!((total(&sites, &particles, &a) - best).abs() < 1e-9, "{} vs {}", total(&sites, &particles, &a), best);
        }
    }
}
