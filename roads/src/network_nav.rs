//! Navigation on a network (docs/safety.md §7.1): each UAV follows its way ([`Way`]) through the
//! cells to its goal, planned when its goal is set and again whenever it is pushed off its route or
//! the network changes; its temporary target p^r is the farthest point within r_s along the taut
//! path through the gates that it sees through them, the goal once it is that close and seen.

use crate::nav::NavState;
use crate::network::{GateRule, Hold, Network};
use crate::traffic_nav::{CLEARANCE_MARGIN_M, LANE_GAP_MARGIN_M};
use uav::{Params, Vec2};

/// Chooses temporary targets on a network.
#[derive(Debug, Clone, Copy)]
pub struct NetworkNavigator<'a> {
    /// The network.
    pub net: &'a Network,
    /// Target radius r_s (m).
    pub r_s: f64,
    /// Arrival tolerance ε (m).
    pub epsilon: f64,
    /// How passages are narrowed into gates: D_s and a margin from their ends, and to the right of
    /// the middle by D_c/2 and a gap on two-way roads (keep right, as a road's lanes).
    pub gates: GateRule,
}

impl<'a> NetworkNavigator<'a> {
    /// A navigator on `net` with the parameters of `params` (its D_s and D_c as the filter keeps
    /// them at rest, `Params::kept_d_s`, `kept_d_c`).
    pub fn new(net: &'a Network, params: &Params) -> Self {
        let gates = GateRule {
            clearance: params.kept_d_s() + CLEARANCE_MARGIN_M,
            keep_right: Some(params.kept_d_c() / 2.0 + LANE_GAP_MARGIN_M),
        };
        Self { net, r_s: params.r_s, epsilon: params.epsilon, gates }
    }

    /// Updates `state` for a UAV at `p` (arrival, its way: followed, or planned afresh when it has
    /// none or has left it) and returns its temporary target p^r. Without a goal the target stays;
    /// when no way can be planned (`p` outside the network, or the goal behind one-way roads) it is
    /// `p`: the UAV holds where it is.
    pub fn target(&self, state: &mut NavState, p: Vec2) -> Vec2 {
        self.follow(state, p);
        self.choose(state, p, None)
    }

    /// The first half of [`NetworkNavigator::target`]: arrival, and the way followed or planned.
    pub fn follow(&self, state: &mut NavState, p: Vec2) {
        let Some(goal) = state.goal.map(|g| g.p) else {
            state.way = None;
            return;
        };
        if (p - goal).norm() <= self.epsilon {
            state.arrived = true;
        }
        if state.arrived {
            return;
        }
        let on_way = state.way.as_mut().is_some_and(|w| w.follow(self.net, p));
        if !on_way {
            state.way = self.net.way(p, goal, self.gates, |_, _| 0.0);
        }
    }

    /// The second half of [`NetworkNavigator::target`]: the target of a UAV at `p` after
    /// [`NetworkNavigator::follow`], its way stopped by `hold` (a conflict zone it may not enter yet).
    pub fn choose(&self, state: &mut NavState, p: Vec2, hold: Option<Hold>) -> Vec2 {
        let Some(goal) = state.goal.map(|g| g.p) else {
            return state.target;
        };
        state.target = if state.arrived {
            goal
        } else {
            match &state.way {
                Some(way) => way.target_held(self.net, p, self.r_s, hold),
                None => p,
            }
        };
        state.target
    }

    /// What is left for a UAV at `p` to fly along its way (m); None without a way or once arrived.
    pub fn remaining(&self, state: &NavState, p: Vec2) -> Option<f64> {
        state.way.as_ref().filter(|_| !state.arrived).map(|w| w.remaining(p))
    }
}
