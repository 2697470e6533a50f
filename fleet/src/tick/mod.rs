//! One tick of the fleet, stage by stage ([`pipeline`], ARCHITECTURE.md "One tick"): reading the
//! links, the neighbour search ([`neighbours`]), the rows ([`rows`]), the filter level by level
//! ([`filtering`]) with its repair pass ([`repair`]), and where lost UAVs may be ([`lost`]).

pub(crate) mod filtering;
pub(crate) mod lost;
pub(crate) mod neighbours;
pub(crate) mod pipeline;
pub(crate) mod repair;
pub(crate) mod rows;

use crate::config::FleetConfig;
use crate::member::{ForeignUav, Uav};
use crate::traffic::TrafficRules;
use policies::PolicyRegistry;
use rayon::prelude::*;
use roads::Airspace;

/// What one tick reads and writes of the fleet, borrowed field by field: the stages know the fleet
/// only through this (the fields are named as the fleet's).
pub(crate) struct TickState<'a> {
    /// Configuration.
    pub config: &'a FleetConfig,
    /// The road or network.
    pub road: &'a Airspace,
    /// The UAVs.
    pub uavs: &'a mut Vec<Uav>,
    /// The policies.
    pub policies: &'a mut PolicyRegistry,
    /// Every UAV brakes to a hover.
    pub paused: bool,
    /// The traffic rules' state.
    pub traffic: &'a mut TrafficRules,
    /// The UAVs other regions fly.
    pub foreign: &'a [ForeignUav],
    /// Ticks run before this one.
    pub tick: u64,
}

/// Fleets at least this large run the per-UAV stages on all worker threads; smaller ones stay on the
/// calling thread (handing a few UAVs to other threads costs more than it saves, and waking them
/// on a busy machine can take milliseconds). Either way the results are the same.
pub const PARALLEL_FROM_UAVS: usize = 256;

/// True when a stage over `n` UAVs runs in parallel ([`PARALLEL_FROM_UAVS`]).
pub(crate) fn parallel(n: usize) -> bool {
    n >= PARALLEL_FROM_UAVS
}

/// `out[k] = f(&items[k])` for every item, `out`'s buffer reused: in parallel for large fleets
/// ([`parallel`]), the same on any number of threads (each call reads only its own item).
pub(crate) fn map_into<T: Sync, R: Send>(items: &[T], f: impl Fn(&T) -> R + Sync + Send, out: &mut Vec<R>) {
    if parallel(items.len()) {
        items.par_iter().map(f).collect_into_vec(out);
    } else {
        out.clear();
        out.extend(items.iter().map(f));
    }
}

/// [`map_into`] with `f` changing each item (its own only).
pub(crate) fn map_mut_into<T: Send, R: Send>(
    items: &mut [T],
    f: impl Fn(&mut T) -> R + Sync + Send,
    out: &mut Vec<R>,
) {
    if parallel(items.len()) {
        items.par_iter_mut().map(f).collect_into_vec(out);
    } else {
        out.clear();
        out.extend(items.iter_mut().map(f));
    }
}

/// Wall time (µs) of each stage of the last tick (ARCHITECTURE.md, "One tick").
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct StageTimes {
    /// Reading every link's state.
    pub read_us: f64,
    /// The neighbour search.
    pub neighbours_us: f64,
    /// Navigation and traffic rules: locating each UAV on its route, progress, reservations,
    /// deadlock resolution, targets, arrived UAVs making way.
    pub navigation_us: f64,
    /// The policies (batched).
    pub policies_us: f64,
    /// Building every UAV's rows (road, neighbours, lost UAVs' disks).
    pub rows_us: f64,
    /// The CBF-QP filter of every UAV (without building its rows).
    pub filter_us: f64,
    /// Sending every command.
    pub send_us: f64,
}
