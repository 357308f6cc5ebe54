//! The shortest route around the other particles when neither the straight line nor one
//! side-step is clear: a visibility graph searched with A*, its route then pulled straight.
//!
//! Each obstacle is inflated to the distance the pushed particle's centre must keep from it,
//! `R = Rₐ + R_o + clearance` (the corridor [`Router`] checks). The graph's nodes are the start,
//! the target, and [`RING`] points around every inflated obstacle on the polygon that
//! circumscribes it (radius `R (1 + MARGIN) / cos(π/RING)`, so a straight line between two
//! neighbouring nodes stays outside the circle); a node inside another inflated obstacle, or
//! where the particle would not lie on the stage whole, is left out. An edge `a → b` is a
//! straight push that [`Router`] finds clear, its run-up behind `a` included, with the tip's
//! contact point behind `a` on the stage. Each node is joined to its [`NEIGHBOURS`] nearest
//! nodes and to the target: in a crowded field, where most long edges are blocked, checking
//! only near ones keeps the search to milliseconds. An edge costs its length plus
//! [`Router::run_up`] at every turn (each waypoint re-parks and searches the contact again), and
//! A* with the straight distance to the target as its heuristic finds the cheapest route of
//! the graph. The route is then pulled straight: from each waypoint, to the farthest later one
//! in a clear line, so that it turns only where it must.

use std::cmp::Ordering;
use std::collections::BinaryHeap;

use super::{Obstacle, Router, on_stage};

/// Nodes around each obstacle.
const RING: usize = 12;

/// Nodes each node is joined to, the nearest (besides the target).
const NEIGHBOURS: usize = 24;

/// How far outside the inflated radius the ring's flat sides lie, as a fraction of it.
const MARGIN: f64 = 0.02;

/// An open node of the search: its cost so far plus the heuristic, and where it came from.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Open {
    f: f64,
    g: f64,
    node: usize,
}

impl Eq for Open {}

impl Ord for Open {
    fn cmp(&self, other: &Self) -> Ordering {
        // A max-heap: the lowest f first.
        other.f.total_cmp(&self.f).then_with(|| other.node.cmp(&self.node))
    }
}

impl PartialOrd for Open {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}

impl Router {
    /// Whether the particle can be pushed straight from `a` to `b`: the corridor (with the
    /// run-up behind `a`) clear of every obstacle, and the tip's contact point behind `a`
    /// (`Rₐ + Rₜ` back along the push) on the stage.
    pub(super) fn straight_clear(&self, a: (f64, f64), b: (f64, f64), obstacles: &[Obstacle]) -> bool {
        let (dx, dy) = (b.0 - a.0, b.1 - a.1);
        let len = dx.hypot(dy);
        if len > 0.0 {
            let behind = self.radius + self.tip_radius;
            let back = (a.0 - dx / len * behind, a.1 - dy / len * behind);
            if !(0.0..=self.range).contains(&back.0) || !(0.0..=self.range).contains(&back.1) {
                return false;
            }
        }
        self.blocker(a, b, obstacles).is_none()
    }

    /// The waypoints of the cheapest route from `from` to `to` around `obstacles`, both ends
    /// included; `None` when the graph holds none.
    pub(super) fn search(&self, from: (f64, f64), to: (f64, f64), obstacles: &[Obstacle]) -> Option<Vec<(f64, f64)>> {
        // The obstacles near the straight line give the nodes first (an ellipse around it);
        // all of them only when those hold no route.
        let d = (to.0 - from.0).hypot(to.1 - from.1);
        let slack = d.max(20.0 * self.radius.max(1e-6));
        let near: Vec<Obstacle> = obstacles
            .iter()
            .copied()
            .filter(|o| (o.x - from.0).hypot(o.y - from.1) + (o.x - to.0).hypot(o.y - to.1) <= d + slack)
            .collect();
        let way = if near.len() < obstacles.len() {
            self.search_among(from, to, &near, obstacles)
                .or_else(|| self.search_among(from, to, obstacles, obstacles))
        } else {
            self.search_among(from, to, obstacles, obstacles)
        }?;
        Some(self.pulled_straight(way, obstacles))
    }

    /// The route through as few of `way`'s waypoints as clear straight lines allow.
    fn pulled_straight(&self, way: Vec<(f64, f64)>, obstacles: &[Obstacle]) -> Vec<(f64, f64)> {
        let mut out = vec![way[0]];
        let mut i = 0;
        while i + 1 < way.len() {
            let j = (i + 1..way.len())
                .rev()
                .find(|&j| j == i + 1 || self.straight_clear(way[i], way[j], obstacles))
                .expect("the next waypoint is always reachable");
            out.push(way[j]);
            i = j;
        }
        out
    }

    /// [`Router::search`] with the nodes of `around` (checked against every one of `obstacles`).
    fn search_among(
        &self,
        from: (f64, f64),
        to: (f64, f64),
        around: &[Obstacle],
        obstacles: &[Obstacle],
    ) -> Option<Vec<(f64, f64)>> {
        let nodes = self.nodes(from, to, around, obstacles);
        let dist = |a: (f64, f64), b: (f64, f64)| (a.0 - b.0).hypot(a.1 - b.1);
        let n = nodes.len();
        let mut best = vec![f64::INFINITY; n];
        let mut parent = vec![usize::MAX; n];
        let mut closed = vec![false; n];
        let mut open = BinaryHeap::new();
        best[0] = 0.0;
        open.push(Open {
            f: dist(from, to),
            g: 0.0,
            node: 0,
        });
        let mut order: Vec<usize> = Vec::with_capacity(n);
        while let Some(Open { g, node, .. }) = open.pop() {
            if closed[node] || g > best[node] {
                continue;
            }
            closed[node] = true;
            if node == 1 {
                let mut path = vec![nodes[1]];
                let mut k = 1;
                while parent[k] != usize::MAX {
                    k = parent[k];
                    path.push(nodes[k]);
                }
                path.reverse();
                return Some(path);
            }
            let turn = if node == 0 { 0.0 } else { self.run_up };
            // The target, and the nearest nodes.
            order.clear();
            order.extend((2..n).filter(|&k| !closed[k]));
            let take = NEIGHBOURS.min(order.len());
            if take > 0 && take < order.len() {
                order.select_nth_unstable_by(take - 1, |&a, &b| {
                    dist(nodes[node], nodes[a]).total_cmp(&dist(nodes[node], nodes[b]))
                });
            }
            order.truncate(take);
            order.push(1);
            for &next in &order {
                let cost = g + turn + dist(nodes[node], nodes[next]);
                if cost >= best[next] || cost + dist(nodes[next], to) >= best[1] {
                    continue;
                }
                if !self.straight_clear(nodes[node], nodes[next], obstacles) {
                    continue;
                }
                best[next] = cost;
                parent[next] = node;
                open.push(Open {
                    f: cost + dist(nodes[next], to),
                    g: cost,
                    node: next,
                });
            }
        }
        None
    }

    /// The start (node 0), the target (node 1) and the ring points around every obstacle of
    /// `around` that lie outside every inflated obstacle and keep the particle on the stage.
    fn nodes(&self, from: (f64, f64), to: (f64, f64), around: &[Obstacle], obstacles: &[Obstacle]) -> Vec<(f64, f64)> {
        let inflated = |o: &Obstacle| self.radius + o.radius + self.clearance;
        let mut nodes = vec![from, to];
        let step = std::f64::consts::TAU / RING as f64;
        let stretch = (1.0 + MARGIN) / (std::f64::consts::PI / RING as f64).cos();
        for o in around {
            let rho = inflated(o) * stretch;
            for k in 0..RING {
                let a = k as f64 * step;
                let p = (o.x + rho * a.cos(), o.y + rho * a.sin());
                let free = obstacles
                    .iter()
                    .all(|q| (p.0 - q.x).hypot(p.1 - q.y) >= inflated(q) * (1.0 + MARGIN / 2.0));
                if free && on_stage(p, self.edge_radius, self.range) {
                    nodes.push(p);
                }
            }
        }
        nodes
    }
}

#[cfg(test)]
impl Router {
    /// [`Router::straight_clear`], for the plan's replay in the assembly's tests.
    pub(crate) fn straight_clear_for_tests(&self, a: (f64, f64), b: (f64, f64), obstacles: &[Obstacle]) -> bool {
        self.straight_clear(a, b, obstacles)
    }
}
