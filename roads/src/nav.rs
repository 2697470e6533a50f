//! Navigation: the temporary target p^r of Algorithm 1 (docs/safety.md §7), literal (`alg1`, with
//! the E8 initialisation fix), road-aware (`route`, `lanes`) or with the traffic rules (`traffic`,
//! the default: corner clearance and keep-right lanes here, holds and back-offs from the fleet).

use crate::airspace::Airspace;
use crate::network::Way;
use crate::road::{Road, SegmentTracker};
use crate::traffic_nav::Route;
use uav::{Params, Vec2};

/// Arc-length spacing (m) of the centre-line candidates the `route` target is chosen from.
const ROUTE_STEP_M: f64 = 0.25;

/// Fraction of a centre-line point's clearance by which `lanes` shifts its targets to the right of
/// the direction of travel (keep right: opposing traffic passes instead of meeting head on).
pub const LANE_FRACTION: f64 = 0.5;

/// How the temporary target p^r is chosen.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum NavMode {
    /// The traffic rules (default, docs/traffic.md): targets in a keep-right lane sized to the
    /// road's width, reached by straight paths that keep a clearance from every wall and vertex; the
    /// fleet adds holds before single-file sections and back-offs that resolve deadlocks.
    #[default]
    Traffic,
    /// Road-aware Algorithm 1 (docs/safety.md §7): the goal when it is within r_s and visible,
    /// otherwise the farthest visible centre-line point at most r_s of arc length ahead towards it.
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
            NavMode::Traffic => "traffic",
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
            "traffic" => Ok(NavMode::Traffic),
            "route" => Ok(NavMode::Route),
            "lanes" => Ok(NavMode::Lanes),
            "alg1" => Ok(NavMode::Alg1),
            other => {
                Err(format!("unknown navigation mode `{other}` (expected traffic, route, lanes or alg1)"))
            }
        }
    }
}

/// Where a UAV with a goal is along its route, in road coordinates (arc length s of its foot on the
/// centre line, lateral offset ℓ positive to the left of increasing s).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RoutePosition {
    /// Arc length of the UAV.
    pub s: f64,
    /// Lateral offset of the UAV.
    pub lateral: f64,
    /// Arc length of the goal.
    pub goal_s: f64,
    /// Lateral offset of the goal.
    pub goal_lateral: f64,
}

impl RoutePosition {
    /// +1 when the goal lies towards increasing arc length, −1 otherwise.
    pub fn direction(&self) -> f64 {
        if self.goal_s >= self.s { 1.0 } else { -1.0 }
    }

    /// What is left to fly in road coordinates, |Δs| + |Δℓ|: it decreases whenever the UAV moves
    /// towards its goal along the road or across it.
    pub fn remaining(&self) -> f64 {
        (self.goal_s - self.s).abs() + (self.goal_lateral - self.lateral).abs()
    }
}

/// A goal with its segment and road coordinates, cached when it is set (on a network: its cell,
/// and no road coordinates, which only a road's navigation reads).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Goal {
    pub(crate) p: Vec2,
    segment: usize,
    s: f64,
    lateral: f64,
}

impl Goal {
    fn new(road: &Road, p: Vec2) -> Self {
        let segment = road.locate(&p, None);
        let line = road.centerline();
        Self { p, segment, s: line.project_on_piece(segment, &p), lateral: line.lateral(segment, &p) }
    }

    fn on(airspace: &Airspace, p: Vec2) -> Self {
        match airspace {
            Airspace::Road(road) => Self::new(road, p),
            Airspace::Network(_) => Self { p, segment: airspace.locate(&p, None), s: 0.0, lateral: 0.0 },
        }
    }
}

/// Per-UAV navigation state.
#[derive(Debug, Clone, PartialEq)]
pub struct NavState {
    /// The current temporary target p^r (initialised to p(0), erratum E8).
    pub target: Vec2,
    /// True once ‖p − p_g‖ ≤ ε for the current goal; the UAV then hovers at p_g.
    pub arrived: bool,
    /// Segment membership of the UAV (hysteresis).
    pub tracker: SegmentTracker,
    /// Where it is along its route (None without a goal), as of the last [`Navigator::locate`].
    pub position: Option<RoutePosition>,
    pub(crate) goal: Option<Goal>,
    /// Its way through a network to its goal (None on a road, and until planned).
    pub(crate) way: Option<Way>,
}

impl NavState {
    /// State of a UAV starting at `p0` with no goal (it hovers at `p0`).
    pub fn new(p0: Vec2) -> Self {
        let tracker = SegmentTracker::default();
        Self { target: p0, arrived: false, tracker, position: None, goal: None, way: None }
    }

    /// The current goal p_g, if any.
    pub fn goal(&self) -> Option<Vec2> {
        self.goal.map(|g| g.p)
    }

    /// Its way through a network (None on a road, and until planned).
    pub fn way(&self) -> Option<&Way> {
        self.way.as_ref()
    }

    /// Sets a new goal on `road` (clears `arrived`), or clears it so the UAV hovers where it is (`p`).
    pub fn set_goal(&mut self, road: &Road, goal: Option<Vec2>, p: Vec2) {
        self.put_goal(goal.map(|g| Goal::new(road, g)), p);
    }

    /// [`NavState::set_goal`] on a road or a network.
    pub fn set_goal_in(&mut self, airspace: &Airspace, goal: Option<Vec2>, p: Vec2) {
        self.put_goal(goal.map(|g| Goal::on(airspace, g)), p);
    }

    fn put_goal(&mut self, goal: Option<Goal>, p: Vec2) {
        self.arrived = false;
        self.goal = goal;
        self.position = None;
        self.way = None;
        if goal.is_none() {
            self.target = p;
        }
    }
}

/// What the fleet's traffic rules ask of one UAV's next target (`traffic` navigation).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Restriction {
    /// Hold: the target may not pass this arc length in the direction of travel (the hold point
    /// before a section reserved for the other direction).
    pub hold_at: Option<f64>,
    /// Back off: fly to this point instead (deadlock resolution).
    pub back_off: Option<Vec2>,
    /// When past `hold_at`: wait where it is (beside, in its lane) rather than go back to it.
    pub wait_here: bool,
    /// Follow: the target may not pass this arc length in the direction of travel (a follow gap
    /// behind the UAV ahead in its lane); when past it, wait where it is.
    pub follow_at: Option<f64>,
    /// Keep to the lane through sharp left bends (traffic comes the other way): the straight path to
    /// the target may not cut a bend's inside corner across the centre line into the oncoming lane.
    pub keep_lane: bool,
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
    /// Road safety distance D_s (m), for lanes and clearances.
    pub d_s: f64,
    /// Collision distance D_c (m), for the gap between opposite lanes.
    pub d_c: f64,
    /// Input bound δ (m/s²), for the braking margin of the clearance.
    pub delta: f64,
}

impl<'a> Navigator<'a> {
    /// A navigator on `road` with the parameters of `params`; its D_s and D_c are the distances the
    /// filter keeps at rest, with the model-error allowances (`Params::kept_d_s`, `kept_d_c`).
    pub fn new(road: &'a Road, mode: NavMode, params: &Params) -> Self {
        let (r_s, epsilon, d_s, d_c, delta) =
            (params.r_s, params.epsilon, params.kept_d_s(), params.kept_d_c(), params.delta);
        Self { road, mode, r_s, epsilon, d_s, d_c, delta }
    }

    /// Updates the segment, arrival and road coordinates of a UAV at `p`; returns its segment.
    pub fn locate(&self, state: &mut NavState, p: Vec2) -> usize {
        let segment = state.tracker.update(self.road, &p);
        let Some(goal) = state.goal else {
            state.position = None;
            return segment;
        };
        if (p - goal.p).norm() <= self.epsilon {
            state.arrived = true;
        }
        let line = self.road.centerline();
        state.position = Some(RoutePosition {
            s: line.project_on_piece(segment, &p),
            lateral: line.lateral(segment, &p),
            goal_s: goal.s,
            goal_lateral: goal.lateral,
        });
        segment
    }

    /// Updates `state` for a UAV at `p` at rest with no restriction and returns its target p^r.
    pub fn target(&self, state: &mut NavState, p: Vec2) -> Vec2 {
        self.target_with(state, p, Vec2::zeros(), &Restriction::default())
    }

    /// Updates `state` for a UAV at `p` flying at `v` and returns its temporary target p^r; with
    /// `traffic` navigation, `restriction` is what the fleet's traffic rules ask (holds, back-offs).
    pub fn target_with(&self, state: &mut NavState, p: Vec2, v: Vec2, restriction: &Restriction) -> Vec2 {
        let segment = self.locate(state, p);
        self.choose(state, p, v, segment, restriction)
    }

    /// The target of a UAV that [`Navigator::locate`] has just placed in `segment` (as
    /// [`Navigator::target_with`] without locating it again).
    pub fn choose(
        &self,
        state: &mut NavState,
        p: Vec2,
        v: Vec2,
        segment: usize,
        restriction: &Restriction,
    ) -> Vec2 {
        let (Some(goal), Some(position)) = (state.goal, state.position) else {
            return state.target;
        };
        if state.arrived {
            state.target = goal.p;
            return goal.p;
        }
        state.target = match self.mode {
            NavMode::Traffic => {
                let (goal_segment, goal) = (goal.segment, goal.p);
                self.traffic_target(&Route { p, v, segment, goal, goal_segment, position }, restriction)
            }
            NavMode::Route => self.route_target(p, segment, goal.p, goal.segment, 0.0),
            NavMode::Lanes => self.route_target(p, segment, goal.p, goal.segment, LANE_FRACTION),
            NavMode::Alg1 => self.alg1_target(state.target, p, goal.p),
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
