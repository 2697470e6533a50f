//! Reversible changes: each edit that [`Fleet::apply`] applies comes with the record that undoes it exactly,
//! so a caller that applies a change first and makes it durable afterwards (the server's group
//! commit) can take it back when the disk refuses it. Undo records are applied newest first.

use crate::edits::edit::EditError;
use crate::fleet::Fleet;
use crate::member::{Uav, UavPolicy};
use roads::{Airspace, NavState};
use uav::Params;

/// What restores the fleet to its state before one change.
pub enum Undo {
    /// A UAV was added: remove it (its link is dropped).
    Added(String),
    /// A UAV was removed from `index`: put it back there, link and all.
    Removed {
        /// Its index in the fleet before the removal.
        index: usize,
        /// The UAV as it was removed.
        uav: Box<Uav>,
    },
    /// A UAV's navigation (goal, route progress) changed.
    Nav {
        /// The UAV.
        id: String,
        /// Its navigation state before the change.
        nav: NavState,
    },
    /// A UAV's policy changed.
    Policy {
        /// The UAV.
        id: String,
        /// Its policy before the change.
        policy: String,
    },
    /// The road was replaced (every UAV's navigation was reset with it).
    Road {
        /// The road before.
        road: Airspace,
        /// Every UAV's navigation state before, by id.
        navs: Vec<(String, NavState)>,
    },
    /// Parameters, road and UAVs were replaced (a scenario load).
    Fleet {
        /// Parameters before.
        params: Params,
        /// Road before.
        road: Airspace,
        /// The UAVs before, links and all.
        uavs: Vec<Uav>,
        /// Paused before.
        paused: bool,
    },
    /// Pause was switched (the value before).
    Pause(bool),
}

impl Undo {
    /// The UAVs this record keeps alive (removed ones whose links must stay open until the change
    /// is durable); dropping the record drops them.
    pub fn kept_uavs(&self) -> usize {
        match self {
            Undo::Removed { .. } => 1,
            Undo::Fleet { uavs, .. } => uavs.len(),
            _ => 0,
        }
    }
}

impl Fleet {
    pub(super) fn position_of(&self, id: &str) -> Result<usize, EditError> {
        self.uavs.iter().position(|u| u.id == id).ok_or_else(|| EditError::UnknownUav(id.to_string()))
    }

    /// Takes a change back. Records must be undone newest first: each restores exactly the state
    /// its change found (UAVs keep the positions they flew to meanwhile).
    pub fn undo(&mut self, undo: Undo) {
        match undo {
            Undo::Added(id) => {
                if let Ok(k) = self.position_of(&id) {
                    drop(self.uavs.remove(k));
                }
            }
            Undo::Removed { index, uav } => {
                let index = index.min(self.uavs.len());
                self.uavs.insert(index, *uav);
            }
            Undo::Nav { id, nav } => {
                if let Ok(k) = self.position_of(&id) {
                    self.uavs[k].nav = nav;
                }
            }
            Undo::Policy { id, policy } => {
                if let Ok(k) = self.position_of(&id) {
                    self.uavs[k].policy = UavPolicy::new(policy);
                }
            }
            Undo::Road { road, navs } => {
                self.road = road;
                for (id, nav) in navs {
                    if let Ok(k) = self.position_of(&id) {
                        self.uavs[k].nav = nav;
                    }
                }
            }
            Undo::Fleet { params, road, uavs, paused } => {
                self.config.params = params;
                self.road = road;
                self.uavs = uavs;
                self.paused = paused;
            }
            Undo::Pause(paused) => self.paused = paused,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Edit;
    use crate::FleetConfig;
    use links::SimLink;
    use policies::PolicyRegistry;
    use roads::{Road, RoadLayout};
    use uav::{UavState, Vec2};

    fn fleet() -> Fleet {
        let road = Road::new(RoadLayout::straight(0.0, 20.0, 4.0, 2)).expect("a straight road is valid");
        let config = FleetConfig::default();
        let mut fleet = Fleet::new(config, road, PolicyRegistry::with_pd(config.params.delta));
        for (i, y) in [-1.0, 1.0].into_iter().enumerate() {
            let state = UavState::at_rest(Vec2::new(2.0, y));
            let link = Box::new(SimLink::new(state, config.params.dt));
            fleet.add(format!("u{i}"), "pd".into(), link, state, Some(Vec2::new(15.0, y)));
        }
        fleet
    }

    /// What a change may touch: ids in order, policies, goals, pause, road and params.
    fn summary(f: &Fleet) -> String {
        let uavs: Vec<String> = f
            .uavs()
            .iter()
            .map(|u| format!("{}:{}:{:?}:{:?}", u.id, u.policy, u.nav.goal(), u.state.p))
            .collect();
        format!(
            "{uavs:?} paused={} road={:?} dt={}",
            f.paused(),
            f.road().map(|r| r.layout()),
            f.config.params.dt
        )
    }

    #[test]
    fn every_change_undone_newest_first_restores_the_fleet() {
        let mut f = fleet();
        let before = summary(&f);
        let mut undos = Vec::new();
        let state = UavState::at_rest(Vec2::new(8.0, 0.0));
        let link = Box::new(SimLink::new(state, 0.05));
        let longer = Road::new(RoadLayout::straight(0.0, 30.0, 4.0, 3)).unwrap();
        let other = Road::new(RoadLayout::straight(-5.0, 5.0, 3.0, 1)).unwrap();
        let edits = [
            Edit::Add { id: "new".into(), policy: "pd".into(), link, state, goal: None },
            Edit::SetGoal("u0".into(), Some(Vec2::new(10.0, 1.5))),
            Edit::SetPolicy("u1".into(), "pd".into()),
            Edit::Remove("u0".into()),
            Edit::Pause(true),
            Edit::ReplaceRoad(longer.into()),
            Edit::Reset(Params { dt: 0.02, ..Params::default() }, other.into()),
        ];
        for edit in edits {
            undos.push(f.apply(edit).unwrap().undo);
        }
        assert_ne!(summary(&f), before);
        while let Some(undo) = undos.pop() {
            f.undo(undo);
        }
        assert_eq!(summary(&f), before);
        // The restored fleet still ticks.
        f.tick();
    }

    #[test]
    fn a_refused_change_gives_no_undo_record_and_changes_nothing() {
        let mut f = fleet();
        let before = summary(&f);
        assert!(f.apply(Edit::Remove("nope".into())).is_err());
        assert!(f.apply(Edit::SetGoal("u0".into(), Some(Vec2::new(100.0, 0.0)))).is_err());
        assert!(f.apply(Edit::SetPolicy("u0".into(), "nope".into())).is_err());
        assert_eq!(summary(&f), before);
    }
}
