//! What a region server adds to the fleet loop ([`LoopHook`]): a hook is called at fixed points of
//! every gap and tick, and a single server has none ([`NoHook`], whose calls do nothing). The loop
//! knows nothing else of regions; the regions' side (`regions::RegionLoop`) knows the loop
//! only through this trait and [`LoopEdits`].

use super::command::{ChangeError, Command};
use super::snapshot::Snapshot;
use fleet::Fleet;
use roads::Airspace;
use std::sync::Arc;
use std::time::{Duration, Instant};
use uav::UavState;

/// A UAV another server gives this one (a handover or a takeover), as its last owner flew it.
#[derive(Debug, Clone, PartialEq)]
pub struct Arrival {
    /// Its id (new here: the hook checks).
    pub id: String,
    /// Its state when the last owner let it go.
    pub state: UavState,
    /// Its goal (dropped when this road has no room for it).
    pub goal: Option<uav::Vec2>,
    /// Its policy (this server's default when the policy is not loaded here).
    pub policy: String,
    /// `sim` (None) or a Crazyflie URI: opened here only if this server's link rules allow it.
    pub link: Option<String>,
    /// A Crazyflie in the air: avoided as lost until its new link reports.
    pub airborne: bool,
}

/// Who a UAV's ownership record says it went to or came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Ownership<'a> {
    /// UAV `id` joined the fleet (`how`: "added", "start").
    Opened {
        /// The UAV.
        id: &'a str,
        /// How it came.
        how: &'static str,
    },
    /// UAV `id` left the fleet (`how`: "removed").
    Closed {
        /// The UAV.
        id: &'a str,
        /// How it went.
        how: &'static str,
    },
    /// Every UAV left the fleet (a scenario replaced it).
    ClosedAll,
}

/// What a hook may do to the fleet between two ticks: read it, adopt UAVs through the loop's edit
/// path ([`Command::Adopt`]), and let UAVs go to another server.
pub trait LoopEdits {
    /// The fleet as it flies.
    fn fleet(&self) -> &Fleet;
    /// Most UAVs this fleet may have.
    fn max_uavs(&self) -> usize;
    /// The version of the road flown.
    fn road_version(&self) -> u64;
    /// Adds a UAV from another server; false (nothing changed) when its link is not one this
    /// server may open or the fleet refuses it.
    fn adopt(&mut self, arrival: Arrival) -> bool;
    /// Takes UAV `id` out of the fleet for another server (None: not flown here).
    fn release(&mut self, id: &str) -> Option<fleet::Uav>;
    /// Takes every UAV out of the fleet (this server gives its region away).
    fn release_all(&mut self) -> Vec<fleet::Uav>;
}

/// The loop's hook: regions plug in here; each method's default does nothing (admits every
/// change, keeps the loop's own tick instants), which is a single server's [`NoHook`].
pub trait LoopHook: Send {
    /// Between two ticks, after the queued changes: UAVs leave and arrive.
    fn between_ticks(&mut self, _edits: &mut dyn LoopEdits) {}
    /// Just before a tick: the other servers' UAVs the fleet avoids.
    fn before_tick(&mut self, _fleet: &mut Fleet) {}
    /// After a tick, with its snapshot (before the readers get it); `read_at`: when the tick began.
    fn after_tick(&mut self, _snapshot: &Arc<Snapshot>, _fleet: &Fleet, _read_at: Instant) {}
    /// The loop flies `road` (a road or a network) from now on.
    fn road_changed(&mut self, _road: &Airspace) {}
    /// Whether `command` may be applied now (a standby refuses every change but its owner's road).
    fn admits(&self, _command: &Command) -> Result<(), ChangeError> {
        Ok(())
    }
    /// Records a change of ownership.
    fn ownership(&self, _change: Ownership<'_>) {}
    /// The tick instant that follows `next` (a region aligns it to the wall clock).
    fn next_tick(&self, next: Instant, _period: Duration) -> Instant {
        next
    }
}

/// A single server: no other server's UAVs, nobody to hand over to, every change admitted.
#[derive(Debug, Default, Clone, Copy)]
pub struct NoHook;

impl LoopHook for NoHook {}
