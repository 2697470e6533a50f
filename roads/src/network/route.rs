//! Routes through a network: the shortest way by travel time over the cell graph, respecting
//! one-way roads, with a cost a caller may add per passage (the queue at a conflict zone).
//!
//! The nodes are the passages, directed (crossing edge e of cell a into cell b); inside a convex
//! cell the way from one passage's middle to another's is the straight segment between them, so a
//! route is the polyline start → the middles of the passages it crosses → goal.

use super::{CellKind, Network};
use std::cmp::Ordering;
use std::collections::BinaryHeap;
use uav::Vec2;

/// The speed (m/s) a route's travel time assumes on a road without a speed limit.
pub const CRUISE_MPS: f64 = 2.0;

/// Edge of a segment's cell (cyclic order p1, p2, p4, p3) that its road enters by: p2–p4.
const ENTRY_EDGE: usize = 1;
/// Edge of a segment's cell that its road leaves by: p3–p1.
const EXIT_EDGE: usize = 3;

/// A route: the cells in the order flown and the polyline through their passages.
#[derive(Debug, Clone, PartialEq)]
pub struct Route {
    /// The cells, from the start's to the goal's.
    pub cells: Vec<usize>,
    /// Start, the middle of every passage crossed, goal.
    pub waypoints: Vec<Vec2>,
    /// Its cost: travel time (s) plus what the caller added.
    pub cost: f64,
}

#[derive(Debug, PartialEq)]
struct Queued {
    cost: f64,
    node: usize,
}

impl Eq for Queued {}

impl Ord for Queued {
    fn cmp(&self, other: &Self) -> Ordering {
        // A min-heap on cost (costs are finite: distances and the caller's finite additions).
        other.cost.total_cmp(&self.cost).then_with(|| other.node.cmp(&self.node))
    }
}

impl PartialOrd for Queued {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}

/// The directed passages numbered as the nodes of the route search, built once with the network.
#[derive(Debug, Clone, Default)]
pub(super) struct PassageIndex {
    /// Node n: crossing passage `nodes[n] = (cell, k)`, the k-th passage of that cell, out of it.
    nodes: Vec<(usize, usize)>,
    /// The node of a cell's first passage (the others follow it).
    offsets: Vec<usize>,
}

impl PassageIndex {
    /// The index of every cell's `passages`.
    pub(super) fn new(passages: &[Vec<super::Passage>]) -> Self {
        let nodes =
            passages.iter().enumerate().flat_map(|(c, list)| (0..list.len()).map(move |k| (c, k))).collect();
        let offsets = passages
            .iter()
            .scan(0, |total, list| {
                let at = *total;
                *total += list.len();
                Some(at)
            })
            .collect();
        Self { nodes, offsets }
    }
}

impl Network {
    /// The middle of edge `edge` of cell `cell`.
    fn edge_middle(&self, cell: usize, edge: usize) -> Vec2 {
        let v = &self.cells[cell].vertices;
        (v[edge] + v[(edge + 1) % v.len()]) / 2.0
    }

    /// Whether a UAV may cross edge `edge` of cell `from` (passable) in that direction: not
    /// backwards along a one-way road, nor into a one-way road's end or out of its start.
    pub fn may_cross(&self, from: usize, edge: usize) -> bool {
        let passage = self.passages[from].iter().find(|p| p.edge == edge);
        let Some(p) = passage else { return false };
        let leaving_ok = match self.cells[from].kind {
            CellKind::Segment { road, .. } if self.layout.roads[road].one_way => edge != ENTRY_EDGE,
            _ => true,
        };
        let entering_ok = match self.cells[p.other].kind {
            CellKind::Segment { road, .. } if self.layout.roads[road].one_way => p.other_edge != EXIT_EDGE,
            _ => true,
        };
        leaving_ok && entering_ok
    }

    /// The speed limit (m/s) in cell `cell`: its road's, if it has one; in a junction the largest
    /// limit of the roads that meet there when every one has a limit (none otherwise: a UAV crossing
    /// between limited roads does not speed up inside the junction).
    pub fn speed_limit(&self, cell: usize) -> Option<f64> {
        match self.cells.get(cell)?.kind {
            CellKind::Segment { road, .. } => self.layout.roads[road].speed_limit,
            CellKind::Junction { .. } => self.junction_limits.get(cell).copied().flatten(),
        }
    }

    /// Every cell's junction speed limit ([`Network::speed_limit`]; None for segments), from `cells`,
    /// their `passages` and the roads of `layout`.
    pub(super) fn junction_limits(
        layout: &super::NetworkLayout,
        cells: &[super::Cell],
        passages: &[Vec<super::Passage>],
    ) -> Vec<Option<f64>> {
        let road_limit = |c: usize| match cells[c].kind {
            CellKind::Segment { road, .. } => layout.roads[road].speed_limit,
            CellKind::Junction { .. } => None,
        };
        (0..cells.len())
            .map(|c| match cells[c].kind {
                CellKind::Junction { .. } if !passages[c].is_empty() => {
                    let limits: Option<Vec<f64>> = passages[c].iter().map(|p| road_limit(p.other)).collect();
                    limits.map(|l| l.into_iter().fold(0.0, f64::max))
                }
                _ => None,
            })
            .collect()
    }

    /// Seconds to fly `metres` in cell `cell` (its road's speed limit, else [`CRUISE_MPS`]).
    fn time_in(&self, cell: usize, metres: f64) -> f64 {
        metres / self.speed_limit(cell).unwrap_or(CRUISE_MPS).min(CRUISE_MPS)
    }

    /// The fastest route from `from` in cell `start` to `to` in cell `goal`; `extra(cell, edge)` is
    /// added for crossing edge `edge` of `cell` (0 for none; the queue at a junction, say). None: the
    /// goal cannot be reached (one-way roads).
    pub fn route(
        &self,
        start: (usize, Vec2),
        goal: (usize, Vec2),
        extra: impl Fn(usize, usize) -> f64,
    ) -> Option<Route> {
        self.route_with(start, goal, extra, true)
    }

    /// [`Network::route`] that may also fly one-way roads backwards: the way back for a UAV pushed
    /// past its goal on one (`one_way` false), which no legal route has.
    pub fn route_back(
        &self,
        start: (usize, Vec2),
        goal: (usize, Vec2),
        extra: impl Fn(usize, usize) -> f64,
    ) -> Option<Route> {
        self.route_with(start, goal, extra, false)
    }

    /// The cost of flying through `cells` (a route's cells in order, `from` in the first, `to` in
    /// the last) as [`Network::route`] counts it, `extra` included; None when two cells in a row
    /// share no passage.
    pub fn route_cost(
        &self,
        cells: &[usize],
        from: Vec2,
        to: Vec2,
        extra: impl Fn(usize, usize) -> f64,
    ) -> Option<f64> {
        let (mut cost, mut at) = (0.0, from);
        for pair in cells.windows(2) {
            let edge = self.passages.get(pair[0])?.iter().find(|p| p.other == pair[1])?.edge;
            let next = self.edge_middle(pair[0], edge);
            cost += self.time_in(pair[0], (next - at).norm()) + extra(pair[0], edge);
            at = next;
        }
        Some(cost + self.time_in(*cells.last()?, (to - at).norm()))
    }

    fn route_with(
        &self,
        (start, from): (usize, Vec2),
        (goal, to): (usize, Vec2),
        extra: impl Fn(usize, usize) -> f64,
        one_way: bool,
    ) -> Option<Route> {
        let may_cross = |cell: usize, edge: usize| {
            if one_way {
                self.may_cross(cell, edge)
            } else {
                self.passages[cell].iter().any(|p| p.edge == edge)
            }
        };
        if start == goal {
            let cost = self.time_in(start, (to - from).norm());
            return Some(Route { cells: vec![start], waypoints: vec![from, to], cost });
        }
        let PassageIndex { nodes, offsets } = &self.passage_index;
        let passage = |n: usize| self.passages[nodes[n].0][nodes[n].1];
        let node_of = |cell: usize, edge: usize| {
            self.passages[cell].iter().position(|p| p.edge == edge).map(|k| offsets[cell] + k)
        };
        let (mut best, mut came) = (vec![f64::INFINITY; nodes.len()], vec![usize::MAX; nodes.len()]);
        let mut heap = BinaryHeap::new();
        for (k, p) in self.passages[start].iter().enumerate() {
            if may_cross(start, p.edge) {
                let at = self.edge_middle(start, p.edge);
                let cost = self.time_in(start, (at - from).norm()) + extra(start, p.edge);
                best[offsets[start] + k] = cost;
                heap.push(Queued { cost, node: offsets[start] + k });
            }
        }
        let (mut finish, mut finish_cost) = (None, f64::INFINITY);
        while let Some(Queued { cost, node }) = heap.pop() {
            if cost > best[node] || cost >= finish_cost {
                continue;
            }
            let (cell, p) = (nodes[node].0, passage(node));
            let (into, at) = (p.other, self.edge_middle(cell, p.edge));
            if into == goal {
                let total = cost + self.time_in(goal, (to - at).norm());
                if total < finish_cost {
                    (finish, finish_cost) = (Some(node), total);
                }
                continue;
            }
            for q in &self.passages[into] {
                if q.edge == p.other_edge || !may_cross(into, q.edge) {
                    continue;
                }
                let next = self.edge_middle(into, q.edge);
                let step = self.time_in(into, (next - at).norm()) + extra(into, q.edge);
                let Some(n) = node_of(into, q.edge) else { continue };
                if cost + step < best[n] {
                    best[n] = cost + step;
                    came[n] = node;
                    heap.push(Queued { cost: cost + step, node: n });
                }
            }
        }
        let mut node = finish?;
        let mut crossed = vec![node];
        while came[node] != usize::MAX {
            node = came[node];
            crossed.push(node);
        }
        crossed.reverse();
        let mut cells = vec![start];
        let mut waypoints = vec![from];
        for node in crossed {
            let (cell, p) = (nodes[node].0, passage(node));
            waypoints.push(self.edge_middle(cell, p.edge));
            cells.push(p.other);
        }
        waypoints.push(to);
        Some(Route { cells, waypoints, cost: finish_cost })
    }
}
