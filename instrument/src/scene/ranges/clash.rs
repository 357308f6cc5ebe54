//! Particles that clash: two of one id, or two overlapping.

use crate::scene::file::ParticleFile;

/// The first pair of particles that clash, in file order: the smallest `i` with an earlier `j`
/// of the same id or overlapping it (centres closer than the radii's sum), the smallest such
/// `j`, and whether it is the id (checked before the overlap, for each `j`). In O(n log n) for
/// scattered particles (a sweep along x), where comparing every pair made 1.8·10⁹ comparisons for 60 000.
pub(crate) fn first_clash(ps: &[ParticleFile]) -> Option<(usize, usize, bool)> {
    let mut best: Option<(usize, usize, bool)> = None;
    let mut keep = |i: usize, j: usize, same_id: bool| {
        let (a, b) = (i.max(j), i.min(j));
        let cand = (a, b, same_id);
        // For one pair, the id is checked first.
        if best.is_none_or(|x| (a, b, !same_id) < (x.0, x.1, !x.2)) {
            best = Some(cand);
        }
    };
    let mut first_of: std::collections::HashMap<u32, usize> = std::collections::HashMap::new();
    for (i, p) in ps.iter().enumerate() {
        match first_of.get(&p.id) {
            Some(&j) => keep(i, j, true),
            None => {
                first_of.insert(p.id, i);
            }
        }
    }
    let r_max = ps.iter().map(|p| p.radius_nm).fold(0.0, f64::max);
    let mut order: Vec<usize> = (0..ps.len()).collect();
    order.sort_by(|&a, &b| ps[a].x_um.total_cmp(&ps[b].x_um));
    for (k, &a) in order.iter().enumerate() {
        let p = &ps[a];
        for &b in &order[k + 1..] {
            let q = &ps[b];
            if (q.x_um - p.x_um) * 1e3 >= p.radius_nm + r_max {
                break;
            }
            let d_nm = ((p.x_um - q.x_um).powi(2) + (p.y_um - q.y_um).powi(2)).sqrt() * 1e3;
            if d_nm < p.radius_nm + q.radius_nm {
                keep(a, b, false);
            }
        }
    }
    best
}
