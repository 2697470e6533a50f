//! A UAV's way through a network (docs/safety.md §7.1): the cells of its route, the passages it
//! crosses between them as *gates* (each narrowed by a clearance at both ends, and to its right half
//! on two-way roads), where it is along them, and its temporary target p^r: the farthest point
//! within r_s along the taut path through the gates that it sees through them from where it is.
//!
//! The taut path is the string pulled through the gates (the funnel algorithm). A target is *seen*
//! when the straight path to it crosses each passage ahead within its *opening* (the gate 5 cm wider
//! at both ends, within half the clearance of the passage's: a UAV that stands a little outside its
//! gate, at a corner of the taut path, still sees past it); such a path lies in the union of the
//! route's convex cells and passes every wall corner at half the clearance at least, so the target
//! keeps the UAV off the corners of junctions as the chain's corner clearance does.

use super::space::margin;
use super::{CellKind, Network, Route};
use uav::{Vec2, cross};

/// Arc-length spacing (m) of the candidates on the taut path a target is chosen from.
const STEP_M: f64 = 0.25;

/// How much wider (m) than its gate a passage's opening is at each end (within half the clearance
/// of the passage's ends): a UAV that its policy or its neighbours left that close to a corner of
/// its taut path, outside its gate, still sees past the corner.
const SEEN_SLACK_M: f64 = 0.05;

/// Tolerance (m) of "in the cell" for a target and a UAV.
const IN_CELL_M: f64 = 1.0e-6;

/// How a way narrows the passages it crosses.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GateRule {
    /// Kept from each end of a passage (m): D_s, the UAV's clearance margin.
    pub clearance: f64,
    /// Keep right: on a two-way road, a gate is the part of its passage at least this far (m)
    /// right of the middle (D_c/2 and a gap) where that part is not empty; None: the whole passage.
    pub keep_right: Option<f64>,
}

/// A passage as crossed: its ends seen in the direction of travel, narrowed by a [`GateRule`].
#[derive(Debug, Clone, Copy, PartialEq)]
struct Gate {
    left: Vec2,
    right: Vec2,
}

/// A UAV's way to its goal through a network: its route and how far along it it is.
#[derive(Debug, Clone, PartialEq)]
pub struct Way {
    /// The route's cells, in the order flown.
    cells: Vec<usize>,
    /// `gates[k]`: the passage from `cells[k]` to `cells[k + 1]`, narrowed by the [`GateRule`].
    gates: Vec<Gate>,
    /// `openings[k]`: that gate a little wider (what a target is seen through, [`SEEN_SLACK_M`]).
    openings: Vec<Gate>,
    /// The index in `cells` of the cell the UAV is in.
    at: usize,
    /// The goal.
    goal: Vec2,
}

impl Network {
    /// The way from `from` to `to` (both in the network) with the gates of `rule`; `extra` is the
    /// route's added cost per passage ([`Network::route`]). Where one-way roads leave no route (a
    /// UAV pushed past its goal on one), the way back against them ([`Network::route_back`]). None:
    /// either point is outside the network.
    pub fn way(
        &self,
        from: Vec2,
        to: Vec2,
        rule: GateRule,
        extra: impl Fn(usize, usize) -> f64,
    ) -> Option<Way> {
        let (start, goal) = (self.locate(&from)?, self.locate(&to)?);
        let Route { cells, .. } = self
            .route((start, from), (goal, to), &extra)
            .or_else(|| self.route_back((start, from), (goal, to), &extra))?;
        let (gates, openings) = cells.windows(2).map(|pair| self.gate(pair[0], pair[1], rule)).unzip();
        Some(Way { cells, gates, openings, at: 0, goal: to })
    }

    /// The gate from cell `from` into its neighbour `into`, and its opening.
    fn gate(&self, from: usize, into: usize, rule: GateRule) -> (Gate, Gate) {
        let v = &self.cells[from].vertices;
        // A route only steps between cells that share a passage.
        let edge = self.passages[from].iter().find(|p| p.other == into).map_or(0, |p| p.edge);
        let (a, b) = (v[edge], v[(edge + 1) % v.len()]);
        let middle = (a + b) / 2.0;
        let inside = v.iter().sum::<Vec2>() / v.len() as f64;
        let ahead = middle - inside;
        let (left, right) = if cross(&ahead, &(a - middle)) > 0.0 { (a, b) } else { (b, a) };
        let width = (right - left).norm();
        let across = (right - left) / width;
        // The gate as distances from `left` along the passage: the clearance off both ends, and keep
        // right of the middle where there is room.
        let (mut from_m, mut to_m) = (rule.clearance, width - rule.clearance);
        let two_way = |c: usize| match self.cells[c].kind {
            CellKind::Segment { road, .. } => !self.layout.roads[road].one_way,
            CellKind::Junction { .. } => true,
        };
        if let Some(gap) = rule.keep_right.filter(|_| two_way(from) && two_way(into)) {
            let lane = width / 2.0 + gap;
            if lane > from_m && lane < to_m {
                from_m = lane;
            }
        }
        if from_m > to_m {
            (from_m, to_m) = (width / 2.0, width / 2.0);
        }
        // Its opening: SEEN_SLACK_M wider at both ends, within half the clearance of the passage's.
        let (lo, hi) = (rule.clearance / 2.0, width - rule.clearance / 2.0);
        let (open_from, open_to) = if lo > hi {
            (width / 2.0, width / 2.0)
        } else {
            ((from_m - SEEN_SLACK_M).max(lo), (to_m + SEEN_SLACK_M).min(hi))
        };
        let at = |m: f64| left + across * m;
        (Gate { left: at(from_m), right: at(to_m) }, Gate { left: at(open_from), right: at(open_to) })
    }
}

impl Way {
    /// The route's cells, in the order flown.
    pub fn cells(&self) -> &[usize] {
        &self.cells
    }

    /// The cell the UAV was last found in (an index into the network's cells).
    pub fn cell(&self) -> usize {
        self.cells[self.at]
    }

    /// The goal.
    pub fn goal(&self) -> Vec2 {
        self.goal
    }

    /// Follows a UAV now at `p`: finds it in its cell, the next ones or the previous one. False when
    /// it is in none of them (pushed off its route: plan a new way).
    pub fn follow(&mut self, net: &Network, p: Vec2) -> bool {
        let inside = |k: usize| margin(&net.cells[self.cells[k]].vertices, &p) >= -IN_CELL_M;
        if inside(self.at) {
            return true;
        }
        let ahead = (self.at + 1..self.cells.len()).take(3);
        let found = ahead.chain(self.at.checked_sub(1)).find(|&k| inside(k));
        if let Some(k) = found {
            self.at = k;
        }
        found.is_some()
    }

    /// What is left to fly (m): from `p` through the middle of every gate still ahead to the goal.
    pub fn remaining(&self, p: Vec2) -> f64 {
        let mut total = 0.0;
        let mut from = p;
        for gate in &self.gates[self.at..] {
            let middle = (gate.left + gate.right) / 2.0;
            total += (middle - from).norm();
            from = middle;
        }
        total + (self.goal - from).norm()
    }

    /// The temporary target p^r of a UAV at `p` (after [`Way::follow`]): the goal when it is within
    /// `r_s` and seen ([`Way::sees`]), else the farthest point within `r_s` of arc length along
    /// the taut path that is.
    pub fn target(&self, net: &Network, p: Vec2, r_s: f64) -> Vec2 {
        if (self.goal - p).norm() <= r_s && self.sees(net, p, self.goal) {
            return self.goal;
        }
        let path = self.taut_path(p, r_s);
        let length: f64 = path.windows(2).map(|w| (w[1] - w[0]).norm()).sum();
        let reach = length.min(r_s);
        let steps = (reach / STEP_M).ceil() as usize;
        for k in (1..=steps).rev() {
            let c = point_along(&path, reach * k as f64 / steps as f64);
            if self.sees(net, p, c) {
                return c;
            }
        }
        // The first corner of the taut path: seen from p through the gates, hence the openings.
        path.get(1).copied().unwrap_or(p)
    }

    /// True when the straight path p→x crosses each passage ahead within its opening until x's cell.
    pub fn sees(&self, net: &Network, p: Vec2, x: Vec2) -> bool {
        for k in self.at..self.cells.len() {
            if margin(&net.cells[self.cells[k]].vertices, &x) >= -IN_CELL_M {
                return true;
            }
            let Some(gate) = self.openings.get(k) else { return false };
            if !crosses_within(p, x, gate) {
                return false;
            }
        }
        false
    }

    /// The taut path from `p` through the gates ahead (those within `r_s` of it and one more) to
    /// the goal, or to the middle of the last gate taken when the goal is farther.
    fn taut_path(&self, p: Vec2, r_s: f64) -> Vec<Vec2> {
        let ahead = &self.gates[self.at..];
        let near = ahead.iter().take_while(|g| distance_to(p, g) <= r_s).count();
        let (taken, end) = match ahead.get(near) {
            Some(g) => (&ahead[..=near], (g.left + g.right) / 2.0),
            None => (ahead, self.goal),
        };
        let mut portals = Vec::with_capacity(taken.len() + 2);
        portals.push(Gate { left: p, right: p });
        portals.extend_from_slice(taken);
        portals.push(Gate { left: end, right: end });
        funnel(&portals)
    }
}

/// The distance from `p` to the gate's interval.
fn distance_to(p: Vec2, gate: &Gate) -> f64 {
    crate::geometry::nearest_on_segment(&p, &gate.left, &gate.right).0.metric_distance(&p)
}

/// True when the segment p→x crosses the line of `gate` within its interval, from its back to its
/// front (a gate of one point: through that point, within 1 µm).
fn crosses_within(p: Vec2, x: Vec2, gate: &Gate) -> bool {
    let d = x - p;
    let along = gate.right - gate.left;
    if along.norm() < IN_CELL_M {
        // A point gate: the path must pass through it.
        let (nearest, _) = crate::geometry::nearest_on_segment(&gate.left, &p, &x);
        return nearest.metric_distance(&gate.left) <= IN_CELL_M;
    }
    let denom = cross(&d, &along);
    if denom.abs() < 1e-15 {
        return false;
    }
    // p + t·d = left + s·along.
    let w = gate.left - p;
    let t = cross(&w, &along) / denom;
    let s = cross(&w, &d) / denom;
    (-IN_CELL_M..=1.0 + IN_CELL_M).contains(&t) && (-IN_CELL_M..=1.0 + IN_CELL_M).contains(&s)
}

/// The point at arc length `s` along the polyline `path`.
fn point_along(path: &[Vec2], s: f64) -> Vec2 {
    let mut left = s;
    for w in path.windows(2) {
        let length = (w[1] - w[0]).norm();
        if left <= length && length > 0.0 {
            return w[0] + (w[1] - w[0]) * (left / length);
        }
        left -= length;
    }
    path.last().copied().unwrap_or_default()
}

/// The shortest path through `portals` (the first and last of one point each): the funnel
/// algorithm. The funnel's sides are the rays from its apex to its left and right points; a portal
/// end that narrows the funnel moves that side, one that crosses the other side makes that side's
/// point a corner of the path and the new apex.
fn funnel(portals: &[Gate]) -> Vec<Vec2> {
    let start = portals[0].left;
    let mut path = vec![start];
    let (mut apex, mut left, mut right) = (start, start, start);
    let (mut left_at, mut right_at) = (0, 0);
    let mut i = 1;
    while i < portals.len() {
        let Gate { left: l, right: r } = portals[i];
        // Right side: r narrows the funnel when it is left of (or on) the right ray.
        if cross(&(right - apex), &(r - apex)) >= 0.0 {
            if apex == right || cross(&(left - apex), &(r - apex)) <= 0.0 {
                (right, right_at) = (r, i);
            } else {
                // r crosses the left ray: the left point is a corner.
                path.push(left);
                (apex, right, right_at) = (left, left, left_at);
                i = left_at + 1;
                continue;
            }
        }
        // Left side: l narrows the funnel when it is right of (or on) the left ray.
        if cross(&(left - apex), &(l - apex)) <= 0.0 {
            if apex == left || cross(&(right - apex), &(l - apex)) >= 0.0 {
                (left, left_at) = (l, i);
            } else {
                path.push(right);
                (apex, left, left_at) = (right, right, right_at);
                i = right_at + 1;
                continue;
            }
        }
        i += 1;
    }
    let end = portals[portals.len() - 1].left;
    if path.last() != Some(&end) {
        path.push(end);
    }
    path
}

#[cfg(test)]
#[path = "way_tests.rs"]
mod tests;
