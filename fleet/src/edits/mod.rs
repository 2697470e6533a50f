//! Changes to the fleet between ticks: one entry, [`Fleet::apply`], takes an [`Edit`], checks it
//! and applies it all or nothing ([`edit`] holds the checks and the changes), and returns the
//! record that takes it back ([`undo`]).

pub(crate) mod edit;
pub(crate) mod undo;

use crate::fleet::Fleet;
use links::Link;
use roads::Airspace;
use uav::{Params, UavState, Vec2};
use undo::Undo;

/// A change to the fleet between two ticks.
pub enum Edit {
    /// Add a UAV, checked first: a valid new id, a loaded policy, a safe start, a goal on the road.
    Add {
        /// Its id.
        id: String,
        /// Its policy.
        policy: String,
        /// Where its commands go.
        link: Box<dyn Link>,
        /// Where it starts.
        state: UavState,
        /// Its goal (None: hover).
        goal: Option<Vec2>,
    },
    /// Remove a UAV (the undo record keeps it, link and all, until it is dropped).
    Remove(String),
    /// Set (Some) or clear (None: it hovers where it is) a UAV's goal.
    SetGoal(String, Option<Vec2>),
    /// Give a UAV another loaded policy.
    SetPolicy(String, String),
    /// Replace the road, if every UAV in the air would be safe on it; goals it has no room for are
    /// cleared ([`Applied::cleared_goals`]).
    ReplaceRoad(Airspace),
    /// Start over with these parameters on this road, with no UAVs and not paused (a scenario).
    Reset(Params, Airspace),
    /// Pause (every UAV brakes to a hover) or resume.
    Pause(bool),
}

/// An applied edit: what takes it back, and what it did beyond the edit itself.
pub struct Applied {
    /// Restores the fleet as the edit found it (undo newest first).
    pub undo: Undo,
    /// The UAVs whose goals a new road had no room for (they hover).
    pub cleared_goals: Vec<String>,
}

impl Fleet {
    /// Applies `edit`: on an error nothing changed.
    pub fn apply(&mut self, edit: Edit) -> Result<Applied, EditError> {
        let mut cleared_goals = Vec::new();
        let undo = match edit {
            Edit::Add { id, policy, link, state, goal } => {
                self.try_add(id.clone(), policy, link, state, goal)?;
                Undo::Added(id)
            }
            Edit::Remove(id) => {
                let index = self.position_of(&id)?;
                let uav = self.uavs.remove(index);
                Undo::Removed { index, uav: Box::new(uav) }
            }
            Edit::SetGoal(id, goal) => {
                let nav = self.uavs[self.position_of(&id)?].nav.clone();
                self.set_goal(&id, goal)?;
                Undo::Nav { id, nav }
            }
            Edit::SetPolicy(id, policy) => {
                let before = self.uavs[self.position_of(&id)?].policy.clone();
                self.set_policy(&id, &policy)?;
                Undo::Policy { id, policy: before.into_name() }
            }
            Edit::ReplaceRoad(road) => {
                let navs = self.uavs.iter().map(|u| (u.id.clone(), u.nav.clone())).collect();
                let before = self.road.clone();
                cleared_goals = self.replace_road(road)?;
                Undo::Road { road: before, navs }
            }
            Edit::Reset(params, road) => {
                let uavs = std::mem::take(&mut self.uavs);
                let before_params = std::mem::replace(&mut self.config.params, params);
                let before_road = std::mem::replace(&mut self.road, road);
                let paused = std::mem::replace(&mut self.paused, false);
                Undo::Fleet { params: before_params, road: before_road, uavs, paused }
            }
            Edit::Pause(paused) => Undo::Pause(std::mem::replace(&mut self.paused, paused)),
        };
        Ok(Applied { undo, cleared_goals })
    }
}

pub use edit::EditError;
