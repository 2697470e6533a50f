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

use super::space::within;
use super::{CellKind, Network, Route};
use std::cell::RefCell;
use uav::{Vec2, cross};

/// Arc-length spacing (m) of the candidates on the taut path a target is chosen from.
const STEP_M: f64 = 0.25;

/// How much wider (m) than its gate a passage's opening is at each end (within half the clearance
/// of the passage's ends): a UAV that its policy or its neighbours left that close to a corner of
/// its taut path, outside its gate, still sees past the corner.
const SEEN_SLACK_M: f64 = 0.05;

/// Within this distance (m) of the first corner of its taut path, a UAV turns there: it aims past
/// the corner through the passages' whole openings ([`Way::target`]).
const TURN_M: f64 = 1.0;

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
pub(super) struct Gate {
    pub(super) left: Vec2,
    pub(super) right: Vec2,
}

/// Where a UAV must stop on its way: before the cell at index `cell` of [`Way::cells`] (a conflict
/// zone it may not enter yet), `back_m` before the gate into it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Hold {
    /// The index in [`Way::cells`] of the cell not to enter.
    pub cell: usize,
    /// How far before the gate into it (m).
    pub back_m: f64,
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
    /// `wide[k]`: the opening of that passage without keeping right (what a UAV turning at a
    /// corner of its lane sees through, [`TURN_M`]).
    wide: Vec<Gate>,
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
        let whole = GateRule { keep_right: None, ..rule };
        let wide = cells.windows(2).map(|pair| self.gate(pair[0], pair[1], whole).1).collect();
        Some(Way { cells, gates, openings, wide, at: 0, goal: to })
    }

    /// The gate from cell `from` into its neighbour `into`, and its opening.
    pub(super) fn gate(&self, from: usize, into: usize, rule: GateRule) -> (Gate, Gate) {
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
        let inside = |k: usize| within(&net.cells[self.cells[k]].vertices, &p, IN_CELL_M);
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
        let (total, last) = through_middles(p, &self.gates[self.at..]);
        total + (self.goal - last).norm()
    }

    /// The temporary target p^r of a UAV at `p` (after [`Way::follow`]): the goal when it is within
    /// `r_s` and seen ([`Way::sees`]), else the farthest point within `r_s` of arc length along
    /// the taut path that is.
    pub fn target(&self, net: &Network, p: Vec2, r_s: f64) -> Vec2 {
        self.target_towards(net, p, r_s, self.gates.len(), self.goal)
    }

    /// As [`Way::target`], for a UAV held before the cell at `hold.cell` of its way (an index into
    /// [`Way::cells`], ahead of it): its way ends `hold.back_m` before the gate into that cell (in
    /// the middle of the gate, or nearer when the cell before is shorter). Without a hold, or one
    /// not ahead, the target of [`Way::target`].
    pub fn target_held(&self, net: &Network, p: Vec2, r_s: f64, hold: Option<Hold>) -> Vec2 {
        match hold.filter(|h| h.cell > self.at && h.cell < self.cells.len()) {
            Some(h) => self.target_towards(net, p, r_s, h.cell - 1, self.hold_point(net, h)),
            None => self.target(net, p, r_s),
        }
    }

    /// Where a UAV held by `hold` waits: `back_m` before the middle of the gate into its cell,
    /// straight back from the gate, in one of the cells of its way before it (halved until it is).
    pub fn hold_point(&self, net: &Network, hold: Hold) -> Vec2 {
        let gate = self.gates[hold.cell - 1];
        let across = gate.right - gate.left;
        let middle = (gate.left + gate.right) / 2.0;
        let forward = Vec2::new(-across.y, across.x).try_normalize(0.0).unwrap_or_default();
        let before = &self.cells[self.at.min(hold.cell - 1)..hold.cell];
        let mut back = hold.back_m;
        for _ in 0..8 {
            let x = middle - forward * back;
            if before.iter().any(|&c| within(&net.cells[c].vertices, &x, 0.0)) {
                return x;
            }
            back /= 2.0;
        }
        middle - forward * back
    }

    /// The target towards `end` through the gates ahead up to (not including) gate `last`.
    fn target_towards(&self, net: &Network, p: Vec2, r_s: f64, last: usize, end: Vec2) -> Vec2 {
        if (end - p).norm() <= r_s && self.sees(net, p, end) {
            return end;
        }
        SCRATCH.with_borrow_mut(|(portals, path)| {
            self.taut_path_into(p, r_s, last, end, portals, path);
            self.target_on(net, p, r_s, path)
        })
    }

    /// The target of a UAV at `p` on its taut path `path` (see [`Way::target_towards`]).
    fn target_on(&self, net: &Network, p: Vec2, r_s: f64, path: &[Vec2]) -> Vec2 {
        let length: f64 = path.windows(2).map(|w| (w[1] - w[0]).norm()).sum();
        let reach = length.min(r_s);
        let steps = (reach / STEP_M).ceil() as usize;
        let farthest_seen = |openings: &[Gate]| {
            (1..=steps)
                .rev()
                .map(|k| point_along(path, reach * k as f64 / steps as f64))
                .find(|&c| self.sees_through(net, p, c, openings))
        };
        // Within TURN_M of the first corner of the taut path, the UAV turns there: it aims past it as
        // far as it sees through the passages' whole openings (keeping off the walls, not to its
        // lane), rather than crawl to the corner's very point before it sees on.
        let corner = path.get(1).copied().unwrap_or(p);
        let turning = (corner - p).norm() <= TURN_M && path.len() > 2;
        if let Some(c) = farthest_seen(if turning { &self.wide } else { &self.openings }) {
            return c;
        }
        // The first corner: seen from p through the gates, hence the openings.
        corner
    }

    /// The index in [`Way::cells`] of the cell the UAV is in.
    pub fn at(&self) -> usize {
        self.at
    }

    /// The length (m) from `p` through the middles of the gates ahead to the middle of gate `gate`
    /// (the passage from cell `gate` to cell `gate + 1` of the way); 0 once that gate is behind.
    pub fn to_gate(&self, p: Vec2, gate: usize) -> f64 {
        through_middles(p, self.gates.get(self.at..=gate).unwrap_or_default()).0
    }

    /// The distance (m) from `p` to gate `gate`'s interval (0 past the end of the way).
    pub fn from_gate(&self, p: Vec2, gate: usize) -> f64 {
        self.gates.get(gate).map_or(0.0, |g| distance_to(p, g))
    }

    /// True when the straight path p→x crosses each passage ahead within its opening until x's cell.
    pub fn sees(&self, net: &Network, p: Vec2, x: Vec2) -> bool {
        self.sees_through(net, p, x, &self.openings)
    }

    /// [`Way::sees`] through `openings` (one per passage of the way).
    fn sees_through(&self, net: &Network, p: Vec2, x: Vec2, openings: &[Gate]) -> bool {
        for k in self.at..self.cells.len() {
            if within(&net.cells[self.cells[k]].vertices, &x, IN_CELL_M) {
                return true;
            }
            let Some(gate) = openings.get(k) else { return false };
            if !crosses_within(p, x, gate) {
                return false;
            }
        }
        false
    }

    /// The taut path from `p` through the gates ahead before gate `last` (those within `r_s` of it
    /// and one more) to `end`, or to the middle of the last gate taken when `end` is farther.
    #[cfg(test)]
    fn taut_path(&self, p: Vec2, r_s: f64, last: usize, end: Vec2) -> Vec<Vec2> {
        let (mut portals, mut path) = (Vec::new(), Vec::new());
        self.taut_path_into(p, r_s, last, end, &mut portals, &mut path);
        path
    }

    /// [`Way::taut_path`] into `path`, through the buffer `portals` (both cleared first).
    fn taut_path_into(
        &self,
        p: Vec2,
        r_s: f64,
        last: usize,
        end: Vec2,
        portals: &mut Vec<Gate>,
        path: &mut Vec<Vec2>,
    ) {
        let ahead = self.gates.get(self.at..last.min(self.gates.len())).unwrap_or_default();
        let near = ahead.iter().take_while(|g| distance_to(p, g) <= r_s).count();
        let (taken, end) = match ahead.get(near) {
            Some(g) => (&ahead[..=near], (g.left + g.right) / 2.0),
            None => (ahead, end),
        };
        portals.clear();
        portals.push(Gate { left: p, right: p });
        portals.extend_from_slice(taken);
        portals.push(Gate { left: end, right: end });
        funnel(portals, path);
    }
}

thread_local! {
    /// Each thread's buffers for [`Way::taut_path_into`] (the portals and the path): a target costs
    /// no allocation once they have grown to the longest path.
    static SCRATCH: RefCell<(Vec<Gate>, Vec<Vec2>)> = const { RefCell::new((Vec::new(), Vec::new())) };
}

/// The length (m) of the polyline from `p` through the middles of `gates`, and its last point.
fn through_middles(p: Vec2, gates: &[Gate]) -> (f64, Vec2) {
    let mut total = 0.0;
    let mut from = p;
    for g in gates {
        let middle = (g.left + g.right) / 2.0;
        total += (middle - from).norm();
        from = middle;
    }
    (total, from)
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

/// The shortest path through `portals` (the first and last of one point each) into `path`: the
/// funnel algorithm. The funnel's sides are the rays from its apex to its left and right points; a portal
/// end that narrows the funnel moves that side, one that crosses the other side makes that side's
/// point a corner of the path and the new apex.
fn funnel(portals: &[Gate], path: &mut Vec<Vec2>) {
    let start = portals[0].left;
    path.clear();
    path.push(start);
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
}

#[cfg(test)]
#[path = "way_tests.rs"]
mod tests;
