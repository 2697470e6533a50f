//! Neighbours that do not fly the filter (taking off, landing, stale or lost links): where the fleet
//! thinks each may be (`safety::ReachDisk`, docs/safety.md §5 and `safety/src/neighbour_rows.rs`).

use super::{TickState, parallel};
use crate::FleetConfig;
use crate::member::Uav;
use rayon::prelude::*;
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
    /// How far any stale UAV's disk reaches beyond its last position (widens the neighbour search).
    /// A maximum, the same in any order: in parallel for large fleets.
    pub(crate) fn max_stale_reach(&self) -> f64 {
        let reach = |u: &Uav| {
            let disk = disk_of(u, self.config);
            (disk.centre - u.state.p).norm() + disk.radius
        };
        let stale = |u: &&Uav| u.stale_ticks > 0;
        if parallel(self.uavs.len()) {
            self.uavs.par_iter().filter(stale).map(reach).reduce(|| 0.0, f64::max)
        } else {
            self.uavs.iter().filter(stale).map(reach).fold(0.0, f64::max)
        }
    }
}
