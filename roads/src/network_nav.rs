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

    /// Plans the way of a UAV at `p` afresh with `extra` added per passage ([`Network::route`]: the
    /// queues ahead, say) and takes it when it keeps the next `keep` cells of its current way (the
    /// way to the branch point: no turning back) and costs at least `margin_s` less than the rest of
    /// its current way at the same costs. True when it took the new way.
    pub fn reroute(
        &self,
        state: &mut NavState,
        p: Vec2,
        keep: usize,
        extra: impl Fn(usize, usize) -> f64,
        margin_s: f64,
    ) -> bool {
        let (Some(way), Some(goal)) = (state.way.as_ref(), state.goal.map(|g| g.p)) else {
            return false;
        };
        if state.arrived {
            return false;
        }
        let ahead = &way.cells()[way.at()..];
        let Some(current) = self.net.route_cost(ahead, p, goal, &extra) else { return false };
        let Some(start) = self.net.locate(&p) else { return false };
        let Some(goal_cell) = self.net.locate(&goal) else { return false };
        let Some(best) = self.net.route((start, p), (goal_cell, goal), &extra) else { return false };
        let kept = best.cells.get(..keep).is_some_and(|c| Some(c) == ahead.get(..keep));
        if !kept || best.cells.as_slice() == ahead || best.cost + margin_s > current {
            return false;
        }
        match self.net.way(p, goal, self.gates, &extra) {
            Some(new) => {
                state.way = Some(new);
                true
            }
            None => false,
        }
    }

    /// What is left for a UAV at `p` to fly along its way (m); None without a way or once arrived.
    pub fn remaining(&self, state: &NavState, p: Vec2) -> Option<f64> {
        state.way.as_ref().filter(|_| !state.arrived).map(|w| w.remaining(p))
    }
}
