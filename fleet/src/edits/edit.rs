//! Changes to a fleet between ticks (the server's commands): UAVs in and out, goals, the road, the
//! policy of a UAV, hold. Each either applies completely or returns why it cannot and changes nothing.

use crate::fleet::Fleet;
use crate::member::{Uav, UavPolicy};
use crate::runs::margins::{TickMargins, collision_margin, road_margin};
use links::Link;
use roads::{Airspace, NavState};
use uav::{UavState, Vec2};

/// Why a change to the fleet was refused; `field` names the offending request field.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum EditError {
    /// No UAV has this id.
    #[error("no UAV with id `{0}`")]
    UnknownUav(String),
    /// A UAV with this id exists already.
    #[error("a UAV with id `{0}` exists already")]
    DuplicateId(String),
    /// The id breaks the rule of [`uav::check_uav_id`] (1 to 64 of `A-Z a-z 0-9 _ - .`); the
    /// string is the reason, which never repeats the id.
    #[error("id: {0}")]
    InvalidId(String),
    /// The change would put a UAV (or a goal) where it may not be.
    #[error("{field}: {reason}")]
    Unsafe {
        /// The request field at fault (e.g. `position`, `goal`, `segments`).
        field: String,
        /// What is wrong.
        reason: String,
    },
    /// The policy name is not loaded.
    #[error("policy: {0}")]
    UnknownPolicy(String),
    /// A new road would leave a flying UAV outside it or closer than D_s to a wall.
    #[error("segments: {0}")]
    RoadConflict(String),
}

/// `x < min`, and true for a NaN `x` (a margin computed from absurd coordinates is refused too).
fn below(x: f64, min: f64) -> bool {
    x.is_nan() || x < min
}

fn unsafe_at(field: &str, reason: String) -> EditError {
    EditError::Unsafe { field: field.to_string(), reason }
}

impl Fleet {
    /// The UAV with this id.
    pub fn uav(&self, id: &str) -> Option<&Uav> {
        self.uavs.iter().find(|u| u.id == id)
    }

    fn index(&self, id: &str) -> Result<usize, EditError> {
        self.uavs.iter().position(|u| u.id == id).ok_or_else(|| EditError::UnknownUav(id.to_string()))
    }

    /// The neighbour lists of the last tick (`[k]`: indices of UAVs near UAV k).
    pub fn neighbour_lists(&self) -> &crate::Ragged<usize> {
        &self.pipeline.neighbours.lists
    }

    /// Each UAV's margins as the last tick's rows stage measured them ([`TickMargins`]); None when
    /// the fleet no longer holds the states that tick read (a UAV added, removed or moved since):
    /// measure them again then. One pass over the fleet.
    pub fn tick_margins(&self) -> Option<TickMargins<'_>> {
        let rows = &self.pipeline.rows;
        rows.margins_hold_for(&self.uavs).then_some(TickMargins { rows })
    }

    /// Pause (every UAV brakes to a hover; the filter still runs) or fly the policies again.
    pub(crate) fn set_paused(&mut self, paused: bool) {
        self.paused = paused;
    }

    /// True while the fleet is paused.
    pub fn paused(&self) -> bool {
        self.paused
    }

    /// The names of the loaded policies.
    pub fn policy_names(&self) -> impl Iterator<Item = &str> {
        self.policies.names()
    }

    /// Checks that a UAV in `state` would start safely: inside the road at least D_s from every wall
    /// (braking margin, eq. 6) and at least D_c from every other UAV (braking margin, eq. 2).
    pub fn check_start(&self, state: &UavState, field: &str) -> Result<(), EditError> {
        let p = self.config.params;
        if !state.is_finite() {
            return Err(unsafe_at(field, "must be finite numbers".into()));
        }
        let margin = road_margin(&self.road, state, p.delta);
        if below(margin, p.d_s) {
            let (x, y) = (state.p.x, state.p.y);
            let reason = if self.road.contains(&state.p) {
                format!("[{x}, {y}] is {margin:.3} m from the road's boundary, closer than D_s = {} m", p.d_s)
            } else {
                format!("[{x}, {y}] is outside the road")
            };
            return Err(unsafe_at(field, reason));
        }
        for other in &self.uavs {
            let m = collision_margin(state, &other.state, 2.0 * p.delta);
            if below(m, p.d_c) {
                let reason = format!("{m:.3} m from UAV `{}`, closer than D_c = {} m", other.id, p.d_c);
                return Err(unsafe_at(field, reason));
            }
        }
        Ok(())
    }

    /// Checks that `goal` is a finite point inside the road, at least D_s from every wall (the
    /// filter keeps UAVs that far from the walls, so a goal nearer to one is never reached).
    pub fn check_goal(&self, goal: Vec2, field: &str) -> Result<(), EditError> {
        check_goal_on(&self.road, goal, field, self.config.params.d_s)
    }

    /// Checks what [`Fleet::try_add`] checks: a valid and new id, a loaded policy, a safe start, a
    /// goal on the road.
    pub fn check_new(
        &self,
        id: &str,
        policy: &str,
        state: &UavState,
        goal: Option<Vec2>,
    ) -> Result<(), EditError> {
        uav::check_uav_id(id).map_err(EditError::InvalidId)?;
        if self.uav(id).is_some() {
            return Err(EditError::DuplicateId(id.to_string()));
        }
        self.policies.check(policy).map_err(|e| EditError::UnknownPolicy(e.to_string()))?;
        self.check_start(state, "position")?;
        if let Some(g) = goal {
            self.check_goal(g, "goal")?;
        }
        Ok(())
    }

    /// Adds a UAV after checking its id, policy, start and goal.
    pub(crate) fn try_add(
        &mut self,
        id: String,
        policy: String,
        link: Box<dyn Link>,
        state: UavState,
        goal: Option<Vec2>,
    ) -> Result<(), EditError> {
        self.check_new(&id, &policy, &state, goal)?;
        self.add(id, policy, link, state, goal);
        Ok(())
    }

    /// Removes a UAV and returns it (its link is dropped by the caller).
    pub fn remove(&mut self, id: &str) -> Result<Uav, EditError> {
        let k = self.index(id)?;
        Ok(self.uavs.remove(k))
    }

    /// Removes every UAV (a region server giving way to another owner) and returns them.
    pub fn take_all(&mut self) -> Vec<Uav> {
        std::mem::take(&mut self.uavs)
    }

    /// Sets (Some) or clears (None: the UAV hovers where it is) the goal of a UAV.
    pub(crate) fn set_goal(&mut self, id: &str, goal: Option<Vec2>) -> Result<(), EditError> {
        let k = self.index(id)?;
        if let Some(g) = goal {
            self.check_goal(g, "goal")?;
        }
        let uav = &mut self.uavs[k];
        uav.nav.set_goal_in(&self.road, goal, uav.state.p);
        Ok(())
    }

    /// Gives a UAV another loaded policy.
    pub(crate) fn set_policy(&mut self, id: &str, policy: &str) -> Result<(), EditError> {
        let k = self.index(id)?;
        self.policies.check(policy).map_err(|e| EditError::UnknownPolicy(e.to_string()))?;
        self.uavs[k].policy = UavPolicy::new(policy.to_string());
        Ok(())
    }

    /// Lands one UAV through its link, ahead of its next command; it leaves the filter and its
    /// neighbours avoid it until it is down.
    pub fn land(&mut self, id: &str) -> Result<(), EditError> {
        let k = self.index(id)?;
        self.uavs[k].link.land();
        Ok(())
    }

    /// Lands every UAV.
    pub fn land_all(&mut self) {
        for uav in &mut self.uavs {
            uav.link.land();
        }
    }

    /// Emergency stop: cuts every UAV's motors at once.
    pub fn emergency_stop_all(&mut self) {
        for uav in &mut self.uavs {
            uav.link.emergency_stop();
        }
    }

    /// Replaces the road if every UAV would be safe on it (the same test as [`Fleet::check_start`]
    /// against the walls, with its current velocity). Goals outside the new road are cleared (those
    /// UAVs hover); their ids are returned.
    pub(crate) fn replace_road(&mut self, road: Airspace) -> Result<Vec<String>, EditError> {
        self.check_road(&road)?;
        let d_s = self.config.params.d_s;
        let mut cleared = Vec::new();
        for uav in &mut self.uavs {
            let goal = uav.nav.goal().filter(|g| check_goal_on(&road, *g, "goal", d_s).is_ok());
            if goal.is_none() && uav.nav.goal().is_some() {
                cleared.push(uav.id.clone());
            }
            let arrived = uav.nav.arrived && goal.is_some();
            uav.nav = NavState::new(uav.state.p);
            uav.nav.set_goal_in(&road, goal, uav.state.p);
            uav.nav.arrived = arrived;
        }
        self.road = road;
        Ok(cleared)
    }

    /// Whether every UAV in the air would be safe on `road` now (what [`Fleet::replace_road`]
    /// checks first); changes nothing.
    pub fn check_road(&self, road: &impl roads::Boundary) -> Result<(), EditError> {
        let p = self.config.params;
        // UAVs on the ground (landed, stopped, not yet taken off) are not in the road's airspace.
        for uav in self.uavs.iter().filter(|u| u.condition.in_the_air()) {
            let margin = road_margin(road, &uav.state, p.delta);
            if below(margin, p.d_s) {
                let reason = format!(
                    "UAV `{}` at [{:.3}, {:.3}] would be {margin:.3} m from the new road's boundary \
                     (braking margin), less than D_s = {} m",
                    uav.id, uav.state.p.x, uav.state.p.y, p.d_s
                );
                return Err(EditError::RoadConflict(reason));
            }
        }
        Ok(())
    }
}

fn check_goal_on(road: &Airspace, goal: Vec2, field: &str, d_s: f64) -> Result<(), EditError> {
    if !uav::is_finite(&goal) {
        return Err(unsafe_at(field, "must be two finite numbers".into()));
    }
    let d = road.boundary_distance(&goal);
    if d < 0.0 {
        return Err(unsafe_at(field, format!("[{}, {}] is outside the road", goal.x, goal.y)));
    }
    if d < d_s {
        let reason = format!(
            "[{}, {}] is {d:.3} m from a wall, closer than D_s = {d_s} m: no UAV can get there",
            goal.x, goal.y
        );
        return Err(unsafe_at(field, reason));
    }
    Ok(())
}
