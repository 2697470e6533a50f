//! Neighbours that do not fly the filter (taking off, landing, stale or lost links): where the fleet
//! thinks each may be (`safety::ReachDisk`, docs/safety.md §5 and `safety/src/neighbour_rows.rs`).

use super::TickState;
use crate::FleetConfig;
use crate::member::Uav;
use safety::{ReachDisk, point_disk, reach_disk};

/// Where `uav` can be now under `config`: its reach disk while its link is stale, else its last
/// state.
pub(crate) fn disk_of(uav: &Uav, config: &FleetConfig) -> ReachDisk {
    if uav.stale_ticks == 0 {
        return point_disk(uav.state.p);
    }
    let p = &config.params;
    let t = f64::from(uav.stale_ticks) * p.dt;
    reach_disk(uav.state, t, p.delta, config.lost_reach_horizon)
}

impl TickState<'_> {
    /// Where UAV d can be now ([`disk_of`]).
    pub(crate) fn disk_of(&self, d: usize) -> ReachDisk {
        disk_of(&self.uavs[d], self.config)
    }

    /// How far any stale UAV's disk reaches beyond its last position (widens the neighbour search).
    pub(crate) fn max_stale_reach(&self) -> f64 {
        (0..self.uavs.len())
            .filter(|&d| self.uavs[d].stale_ticks > 0)
            .map(|d| {
                let disk = self.disk_of(d);
                (disk.centre - self.uavs[d].state.p).norm() + disk.radius
            })
            .fold(0.0, f64::max)
    }
}
