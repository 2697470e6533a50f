//! Navigation: the temporary target p^r of Algorithm 1 (docs/safety.md §7), literal (`alg1`, with
//! the E8 initialisation fix) or road-aware (`route`, the default).

use crate::road::{Road, SegmentTracker};
use uav::Vec2;

/// Arc-length spacing (m) of the centre-line candidates the `route` target is chosen from.
const ROUTE_STEP_M: f64 = 0.25;

/// Fraction of a centre-line point's clearance by which `lanes` shifts its targets to the right of
/// the direction of travel (keep right: opposing traffic passes instead of meeting head on).
pub const LANE_FRACTION: f64 = 0.5;

/// How the temporary target p^r is chosen.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum NavMode {
    /// Road-aware Algorithm 1 (default, docs/safety.md §7): the goal when it is within r_s and visible,
    /// otherwise the farthest visible centre-line point at most r_s of arc length ahead towards it.
    #[default]
    Route,
    /// `route` with keep-right lanes (docs/safety.md §10.4): each centre-line candidate is shifted
    /// right of the travel direction by [`LANE_FRACTION`] of its clearance, so opposing traffic
    /// passes side by side.
    Lanes,
    /// The paper's Algorithm 1: p^r = p + r_s·(goal direction), moved only when ‖p − p^r‖ ≤ r_s/2.
    Alg1,
}

impl NavMode {
    /// The CLI/JSON name.
    pub fn name(&self) -> &'static str {
        match self {
            NavMode::Route => "route",
            NavMode::Lanes => "lanes",
            NavMode::Alg1 => "alg1",
        }
    }
}

impl std::str::FromStr for NavMode {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "route" => Ok(NavMode::Route),
            "lanes" => Ok(NavMode::Lanes),
            "alg1" => Ok(NavMode::Alg1),
            other => Err(format!("unknown navigation mode `{other}` (expected route, lanes or alg1)")),
        }
    }
}

/// Per-UAV navigation state.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NavState {
    /// The current temporary target p^r (initialised to p(0), erratum E8).
    pub target: Vec2,
    /// True once ‖p − p_g‖ ≤ ε for the current goal; the UAV then hovers at p_g.
    pub arrived: bool,
    /// Segment membership of the UAV (hysteresis).
    pub tracker: SegmentTracker,
    /// The goal and its segment, cached when the goal is set.
    goal: Option<(Vec2, usize)>,
}

impl NavState {
    /// State of a UAV starting at `p0` with no goal (it hovers at `p0`).
    pub fn new(p0: Vec2) -> Self {
        Self { target: p0, arrived: false, tracker: SegmentTracker::default(), goal: None }
    }

    /// The current goal p_g, if any.
    pub fn goal(&self) -> Option<Vec2> {
        self.goal.map(|(g, _)| g)
    }

    /// Sets a new goal (clears `arrived`), or clears it so the UAV hovers where it is (`p`).
    pub fn set_goal(&mut self, road: &Road, goal: Option<Vec2>, p: Vec2) {
        self.arrived = false;
        self.goal = goal.map(|g| (g, road.locate(&g, None)));
        if goal.is_none() {
            self.target = p;
        }
    }

    /// Re-locates the goal after the road changed.
    pub fn road_changed(&mut self, road: &Road) {
        self.tracker = SegmentTracker::default();
        self.goal = self.goal.map(|(g, _)| (g, road.locate(&g, None)));
    }
}

/// Chooses temporary targets on one road.
#[derive(Debug, Clone, Copy)]
pub struct Navigator<'a> {
    /// The road.
    pub road: &'a Road,
    /// Target selection rule.
    pub mode: NavMode,
    /// Target radius r_s (m).
    pub r_s: f64,
    /// Arrival tolerance ε (m).
    pub epsilon: f64,
}

impl Navigator<'_> {
    /// Updates `state` for a UAV at `p` and returns its temporary target p^r.
    pub fn target(&self, state: &mut NavState, p: Vec2) -> Vec2 {
        let segment = state.tracker.update(self.road, &p);
        let Some((goal, goal_segment)) = state.goal else {
            return state.target;
        };
        if (p - goal).norm() <= self.epsilon {
            state.arrived = true;
        }
        if state.arrived {
            state.target = goal;
            return goal;
        }
        state.target = match self.mode {
            NavMode::Route => self.route_target(p, segment, goal, goal_segment, 0.0),
            NavMode::Lanes => self.route_target(p, segment, goal, goal_segment, LANE_FRACTION),
            NavMode::Alg1 => self.alg1_target(state.target, p, goal),
        };
        state.target
    }

    fn alg1_target(&self, previous: Vec2, p: Vec2, goal: Vec2) -> Vec2 {
        if (p - previous).norm() > self.r_s / 2.0 {
            return previous;
        }
        let d = goal - p;
        let dist = d.norm();
        if dist <= self.r_s { goal } else { p + d * (self.r_s / dist) }
    }

    fn route_target(&self, p: Vec2, segment: usize, goal: Vec2, goal_segment: usize, lane: f64) -> Vec2 {
        if (goal - p).norm() <= self.r_s && self.road.visible(&p, &goal) {
            return goal;
        }
        let line = self.road.centerline();
        let s_p = line.project_on_piece(segment, &p);
        let s_g = line.project_on_piece(goal_segment, &goal);
        let ahead = (s_g - s_p).clamp(-self.r_s, self.r_s);
        let candidates = (ahead.abs() / ROUTE_STEP_M).ceil() as usize;
        for k in (1..=candidates).rev() {
            let s = s_p + ahead * (k as f64 / candidates as f64);
            let c = self.lane_point(s, ahead.signum(), lane);
            if self.road.visible(&p, &c) {
                return c;
            }
        }
        // The foot of p on its own segment's centre piece: p and it lie in one convex quad.
        line.point_at(s_p)
    }

    /// The centre-line point at arc length `s`, shifted right of the travel direction `forward` (±1)
    /// by `lane` times its clearance (it stays inside the road, at least (1 − lane)·clearance from walls).
    fn lane_point(&self, s: f64, forward: f64, lane: f64) -> Vec2 {
        let line = self.road.centerline();
        let c = line.point_at(s);
        if lane == 0.0 {
            return c;
        }
        let t = line.tangent_at(s) * forward;
        let right = Vec2::new(t.y, -t.x);
        c + right * (lane * self.road.boundary_distance(&c).max(0.0))
    }
}
