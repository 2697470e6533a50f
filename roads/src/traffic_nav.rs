//! The `traffic` target (docs/traffic.md): a point in the UAV's keep-right lane at most r_s
//! of arc length ahead, the farthest one whose straight path keeps a clearance from every wall and
//! vertex along the route, never past a hold point; the goal itself once it is that close and clear.

use crate::lanes::PROFILE_STEP_M;
use crate::nav::{Navigator, Restriction, RoutePosition};
use uav::Vec2;

/// Clearance (m) kept from walls beyond D_s and the braking distance, by paths and lanes.
pub const CLEARANCE_MARGIN_M: f64 = 0.1;

/// Clearance (m) beyond D_s that a path keeps when none ahead keeps the full clearance
/// ([`Navigator::clearance_at`]): half of [`CLEARANCE_MARGIN_M`].
pub const MIN_CLEARANCE_MARGIN_M: f64 = 0.05;

/// Gap (m) kept beyond D_c/2 between a lane and the centre line, so two opposite lanes are at
/// least D_c + 2·this apart.
pub const LANE_GAP_MARGIN_M: f64 = 0.1;

/// Lane width (m) beyond its narrowest that opposite UAVs need to pass each other at all (slowly);
/// narrower parts are single file.
pub const PASSING_MARGIN_M: f64 = 0.05;

/// Lane width (m) beyond its narrowest from which crowds pass each other without jamming: a tight
/// part (below this) is reserved like a single-file section where there are places to wait on both
/// sides of it.
pub const ROOMY_MARGIN_M: f64 = 0.2;

/// Sine of the smallest turn that counts as a sharp bend for [`Restriction::keep_lane`] (20°):
/// gentler bends are cut by less than the lane gap.
pub const SHARP_BEND_SIN: f64 = 0.34;

/// One UAV's situation on its route.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Route {
    /// Position.
    pub p: Vec2,
    /// Velocity.
    pub v: Vec2,
    /// Its segment.
    pub segment: usize,
    /// Its goal.
    pub goal: Vec2,
    /// The goal's segment.
    pub goal_segment: usize,
    /// Road coordinates of both.
    pub position: RoutePosition,
}

impl Navigator<'_> {
    /// The clearance a path must keep at speed `speed`: D_s, the braking distance v²/(2δ) and a margin.
    pub fn clearance_at(&self, speed: f64) -> f64 {
        self.d_s + speed * speed / (2.0 * self.delta) + CLEARANCE_MARGIN_M
    }

    /// The lateral offset ℓ of the lane at arc length `s` for a UAV travelling towards `direction`
    /// (±1) that is now at offset `lateral`: its own offset kept within the right half of the road,
    /// between D_c/2 + margin from the centre and D_s + margin from the wall; where the right half is
    /// narrower than that (a single-file part), the middle of the road.
    pub fn lane_offset(&self, s: f64, direction: f64, lateral: f64) -> f64 {
        let (right, left) = self.road.profile().at(s);
        let (near, far) = if direction > 0.0 { (right, left) } else { (left, right) };
        let outer = near - self.d_s - CLEARANCE_MARGIN_M;
        let inner = self.d_c / 2.0 + LANE_GAP_MARGIN_M;
        let towards_right =
            if outer >= inner { (-direction * lateral).clamp(inner, outer) } else { (near - far) / 2.0 };
        -direction * towards_right
    }

    /// True when two opposite UAVs fit side by side at arc length `s` (both lanes exist there).
    pub fn two_way_at(&self, s: f64) -> bool {
        self.lane_room_at(s) >= PASSING_MARGIN_M
    }

    /// True when the lanes at arc length `s` are wide enough for crowds to pass ([`ROOMY_MARGIN_M`]).
    pub fn roomy_at(&self, s: f64) -> bool {
        self.lane_room_at(s) >= ROOMY_MARGIN_M
    }

    /// Width (m) of the narrower lane at arc length `s`, beyond its smallest (negative: no lanes).
    fn lane_room_at(&self, s: f64) -> f64 {
        let (right, left) = self.road.profile().at(s);
        let inner = self.d_c / 2.0 + LANE_GAP_MARGIN_M;
        right.min(left) - self.d_s - CLEARANCE_MARGIN_M - inner
    }

    /// True when the straight path p→c, for a UAV travelling towards `direction` (±1) from arc
    /// length `s0` to `s1`, keeps the centre-line vertex of every sharp left bend between them on its
    /// left, where the road is two-way there: it does not cut the bend's inside corner through the
    /// oncoming lane.
    pub fn keeps_lane(&self, p: Vec2, c: Vec2, s0: f64, s1: f64, direction: f64) -> bool {
        let hint = self.road.centerline().piece_at(s0);
        self.cut_bend(p, c, (s0, s1, hint), direction).is_none()
    }

    /// The first centre-line vertex between arc lengths `s0` and `s1` of a sharp left bend (for
    /// `direction`) in a two-way part that the straight path p→c passes on its right, if any.
    /// The vertices between are found by walking from piece `hint` (any piece gives the same
    /// answer; the UAV's tracked segment is near).
    fn cut_bend(&self, p: Vec2, c: Vec2, (s0, s1, hint): (f64, f64, usize), direction: f64) -> Option<usize> {
        let line = self.road.centerline();
        let (points, arc, turns) = (line.points(), line.arc(), line.turns());
        let (lo, hi) = (s0.min(s1), s0.max(s1));
        let path = c - p;
        let mut between = line.vertices_near(hint, |a| a <= lo)..line.vertices_near(hint, |a| a < hi);
        let cut = |&k: &usize| {
            direction * turns[k] >= SHARP_BEND_SIN
                && self.two_way_at(arc[k])
                && uav::cross(&path, &(points[k] - p)) < 0.0
        };
        if direction > 0.0 { between.find(cut) } else { between.rev().find(cut) }
    }

    /// Where the UAV's lane turns at the sharp left bend at centre-line vertex `k` (outside the
    /// bend, where the lanes of both pieces meet), when a path from `route` reaches it with
    /// clearance `need`: the way round a bend that [`Self::keeps_lane`] forbids cutting. Without it,
    /// the lane points on both sides of the vertex jump across the bend's outer corner, and a UAV
    /// that has reached the last one before the vertex sees the next one only on and off.
    fn lane_corner(&self, route: &Route, k: usize, need: f64) -> Option<Vec2> {
        let line = self.road.centerline();
        // The lane's inner edge (nearest the centre line), whatever the UAV's own offset: the corner
        // of a lane hugging the inside wall would stand as close to the inner vertex as the UAV.
        let offset = self.lane_offset(line.arc()[k], route.position.direction(), 0.0);
        let corner = line.lane_corner(k, offset)?;
        let clear = |piece: usize| self.road.path_clear(&route.p, route.segment, &corner, piece, need);
        (clear(k - 1) && clear(k)).then_some(corner)
    }

    /// The farthest lane corner ([`Self::lane_corner`], reached with clearance `need`) of a sharp
    /// bend from D_c behind the UAV to `ahead` of arc length in front of it. The farthest, so that
    /// a UAV between two close bends (a jog) goes on to the second rather than back and forth.
    fn bend_corner_near(&self, route: &Route, ahead: f64, need: f64) -> Option<Vec2> {
        let line = self.road.centerline();
        let (arc, turns) = (line.arc(), line.turns());
        let (pos, direction) = (route.position, route.position.direction());
        let (lo, hi) = if direction > 0.0 {
            (pos.s - self.d_c, pos.s + ahead)
        } else {
            (pos.s - ahead, pos.s + self.d_c)
        };
        let near = arc.partition_point(|&a| a < lo)..arc.partition_point(|&a| a <= hi);
        let corner = |k: usize| {
            if turns[k].abs() < SHARP_BEND_SIN { None } else { self.lane_corner(route, k, need) }
        };
        if direction > 0.0 { near.rev().find_map(corner) } else { near.into_iter().find_map(corner) }
    }

    pub(crate) fn traffic_target(&self, route: &Route, restriction: &Restriction) -> Vec2 {
        if let Some(back_off) = restriction.back_off {
            return back_off;
        }
        let pos = route.position;
        let direction = pos.direction();
        let need = self.clearance_at(route.v.norm());
        let line = self.road.centerline();
        let mut ahead = (pos.goal_s - pos.s).abs().min(self.r_s);
        // The nearer of the hold point and the follow point binds; a hold point already passed binds
        // first (back to it, or wait level with it). Past a follow point the UAV waits where it is.
        let hold = restriction.hold_at.map(|at| (at, restriction.wait_here));
        let follow = restriction.follow_at.map(|at| (at, true));
        let room_to = |(at, _): (f64, bool)| direction * (at - pos.s);
        let stop = match (hold, follow) {
            (Some(h), Some(f)) if room_to(h) > 0.0 && room_to(f) < room_to(h) => Some(f),
            (h, f) => h.or(f),
        };
        let goal_allowed = stop.is_none_or(|stop| (pos.goal_s - pos.s).abs() <= room_to(stop).max(0.0));
        // Level with the goal there is no lane point left to aim at: any path that crosses no wall.
        let level = (pos.goal_s - pos.s).abs() <= PROFILE_STEP_M;
        let goal_need = if level { 0.0 } else { need };
        let to_goal = route.goal - route.p;
        if goal_allowed
            && to_goal.norm() <= self.r_s
            && self.road.path_clear(&route.p, route.segment, &route.goal, route.goal_segment, goal_need)
        {
            return route.goal;
        }
        // Level with a goal farther than r_s across a wide road, the lane ends beside the UAV: go
        // r_s straight across towards the goal instead of hovering there.
        if goal_allowed && level && to_goal.norm() > self.r_s {
            let across = route.p + to_goal * (self.r_s / to_goal.norm());
            if self.road.path_clear(&route.p, route.segment, &across, route.goal_segment, 0.0) {
                return across;
            }
        }
        if let Some((at, wait_here)) = stop {
            let room = room_to((at, wait_here));
            if room <= 0.0 {
                // Past it (pushed, too fast to stop, or too close behind the UAV ahead): back to a
                // hold point in the lane, or stay level with where it is.
                let at = if wait_here { pos.s } else { at };
                return line.point_beside(at, self.lane_offset(at, direction, pos.lateral));
            }
            ahead = ahead.min(room);
        }
        // Candidate k of `count`, with its segment (piece i of the centre line runs through segment i;
        // an offset point may lie in a neighbour, which the route's walls include).
        let arc_at = |k: usize, count: usize| pos.s + direction * ahead * (k as f64 / count as f64);
        let candidate = |k: usize, count: usize| {
            let s = arc_at(k, count);
            line.point_beside_near(s, self.lane_offset(s, direction, pos.lateral), route.segment)
        };
        // Whether candidate k (found at `(c, segment)`) is clear.
        let clear_at = |(c, segment): (Vec2, usize), k: usize, count: usize, need: f64| {
            self.road.path_clear(&route.p, route.segment, &c, segment, need)
                && (!restriction.keep_lane
                    || self
                        .cut_bend(route.p, c, (pos.s, arc_at(k, count), route.segment), direction)
                        .is_none())
        };
        let clear = |k: usize, count: usize, need: f64| clear_at(candidate(k, count), k, count, need);
        // The farthest clear candidate, by bisection: a candidate behind an occluding vertex hides the
        // ones beyond it too, so "clear" holds for a prefix of the candidates (up to the rare exception).
        let count = (ahead / PROFILE_STEP_M).ceil() as usize;
        // Most of the time (straight or gentle roads) the farthest one is clear: one test.
        if count > 0 {
            let farthest = candidate(count, count);
            if clear_at(farthest, count, count, need) {
                return farthest.0;
            }
        }
        let farthest = |need: f64| {
            let (mut lo, mut hi) = (0, count.saturating_sub(1));
            while lo < hi {
                let mid = (lo + hi).div_ceil(2);
                if clear(mid, count, need) { lo = mid } else { hi = mid - 1 }
            }
            lo
        };
        let mut lo = farthest(need);
        if lo == 0 && count > 1 {
            // Nothing ahead is clear: the UAV stands at its lane's edge beside an inner vertex, where
            // every path onwards passes the vertex a little closer than the clearance it keeps. Go on
            // with the smallest clearance a path may have instead of hovering there.
            lo = farthest(self.d_s + MIN_CLEARANCE_MARGIN_M);
        }
        // The farthest clear point is where the UAV already is: it stands in a bend's corner, where
        // the lane points near it jump across the vertex (one piece's lane, then the other's, from
        // tick to tick: `mixed` seed 1002 with `rl` hovered 100 s 0.2 m from an inner vertex). Go
        // through the lane's corner of that bend.
        if lo < count
            && (candidate(lo, count.max(1)).0 - route.p).norm() < PROFILE_STEP_M
            && let Some(corner) = self.bend_corner_near(route, ahead, self.d_s + MIN_CLEARANCE_MARGIN_M)
        {
            return corner;
        }
        // Held short of a sharp left bend by the lane rule alone: round it through the lane's corner.
        if restriction.keep_lane && lo < count {
            let (c, segment) = candidate(lo + 1, count);
            if self.road.path_clear(&route.p, route.segment, &c, segment, need)
                && let Some(k) =
                    self.cut_bend(route.p, c, (pos.s, arc_at(lo + 1, count), route.segment), direction)
                && let Some(corner) = self.lane_corner(route, k, need)
            {
                return corner;
            }
        }
        // lo = 0: the lane point beside the UAV (it and the UAV share a segment, or nearly).
        candidate(lo, count.max(1)).0
    }
}
