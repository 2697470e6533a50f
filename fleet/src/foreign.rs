//! UAVs flown by another region's fleet loop (`airroads serve --region`): known only from that
//! region's messages, each as old as it is. The fleet never commands them and counts them in none
//! of its own metrics; its UAVs keep D_c from where each may be now, the disk
//! [`safety::flown_reach_disk`] of its last state after the message's age (any command up to δ since,
//! frozen after `lost_reach_horizon`), as for a stale link (`lost.rs`). A late or lost message only
//! makes the disk larger: the fleet gets more careful, never less safe.

use crate::fleet::Fleet;
pub use crate::member::ForeignUav;
#[cfg(test)]
use safety::ReachDisk;

impl Fleet {
    /// Replaces the foreign UAVs for the next ticks (call before each [`Fleet::tick`] with the ages
    /// at that moment). A state that is not finite is left out (nothing says where that UAV is);
    /// a negative age counts as 0 and an age that is not a number as the horizon (the largest disk).
    /// The list is rebuilt in place every tick, reusing its entries' ids (no allocation per
    /// foreign UAV in the 20 Hz loop once the ids have been seen).
    pub fn set_foreign(&mut self, foreign: &[ForeignUav]) {
        let horizon = self.config.lost_reach_horizon;
        let mut n = 0;
        for f in foreign.iter().filter(|f| f.state.is_finite()) {
            let age_s = if f.age_s.is_nan() { horizon } else { f.age_s.max(0.0) };
            if let Some(slot) = self.foreign.get_mut(n) {
                slot.id.clone_from(&f.id);
                (slot.state, slot.age_s) = (f.state, age_s);
            } else {
                self.foreign.push(ForeignUav { id: f.id.clone(), state: f.state, age_s });
            }
            n += 1;
        }
        self.foreign.truncate(n);
    }

    /// The foreign UAVs the ticks see (as last given to [`Fleet::set_foreign`]).
    pub fn foreign(&self) -> &[ForeignUav] {
        &self.foreign
    }

    /// Where foreign UAV f can be now.
    #[cfg(test)]
    fn foreign_disk(&self, f: usize) -> ReachDisk {
        self.foreign[f].disk(&self.config)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::FleetConfig;
    use roads::{Road, RoadLayout};
    use uav::UavState;
    use uav::Vec2;

    fn fleet() -> Fleet {
        let road = Road::new(RoadLayout::straight(0.0, 40.0, 6.0, 4)).unwrap(); // a valid layout
        let config = FleetConfig::default();
        Fleet::new(config, road, policies::PolicyRegistry::with_pd(config.params.delta))
    }

    fn foreign(age_s: f64) -> ForeignUav {
        ForeignUav {
            id: "f".into(),
            state: UavState { p: Vec2::new(5.0, 0.0), v: Vec2::new(1.0, 0.0) },
            age_s,
        }
    }

    #[test]
    fn an_older_message_gives_a_larger_disk() {
        let mut fleet = fleet();
        let mut last = fleet.foreign_disk_for(0.0);
        assert_eq!(last.radius, 0.0);
        for age in [0.05, 0.3, 0.6, 1.0, 1.9] {
            let disk = fleet.foreign_disk_for(age);
            assert!(disk.radius > last.radius, "age {age}: {} <= {}", disk.radius, last.radius);
            // It contains every place the UAV can reach at δ in that time.
            let delta = fleet.config.params.delta;
            assert!(disk.radius >= 0.5 * delta * age * age - 1e-12);
            last = disk;
        }
        // An age that is not a number is the horizon's disk, the largest.
        fleet.set_foreign(&[foreign(f64::NAN)]);
        assert!(fleet.foreign_disk(0).radius >= last.radius);
    }

    #[test]
    fn states_that_are_not_finite_are_left_out() {
        let mut fleet = fleet();
        let mut bad = foreign(0.1);
        bad.state.p.x = f64::INFINITY;
        fleet.set_foreign(&[foreign(0.3), foreign(0.4)]);
        fleet.set_foreign(&[bad, foreign(-1.0)]);
        assert_eq!(fleet.foreign().len(), 1, "each call replaces the list");
        assert_eq!(fleet.foreign()[0].age_s, 0.0);
    }

    impl Fleet {
        /// The disk of one foreign UAV given with `age_s`.
        fn foreign_disk_for(&mut self, age_s: f64) -> ReachDisk {
            self.set_foreign(&[foreign(age_s)]);
            self.foreign_disk(0)
        }
    }
}
