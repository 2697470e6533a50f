//! One UAV of the fleet ([`Uav`]): its link, navigation and state, what happened to it in the last
//! tick ([`UavTick`]) and its standing with the traffic rules ([`UavTraffic`]). A leaf: the tick's
//! stages and the traffic rules read and write it; it knows neither.

use crate::condition::Condition;
use crate::config::FleetConfig;
use crate::progress::Progress;
use links::{Link, LinkPhase};
use rayon::prelude::*;
use roads::{NavState, Restriction, RoutePosition};
use safety::{ReachDisk, flown_reach_disk};
use uav::{UavState, Vec2};

/// What happened to one UAV in the last tick.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct UavTick {
    /// Temporary target p^r.
    pub target: Vec2,
    /// The policy's nominal input u_r (after saturation; braking if the policy failed).
    pub u_ref: Vec2,
    /// The filtered input u sent to the link.
    pub u: Vec2,
    /// Number of CBF rows built.
    pub rows: usize,
    /// Rows binding at u.
    pub active_rows: usize,
    /// Largest slack of the QP (0 when skipped).
    pub max_slack: f64,
    /// Smallest barrier value among the rows (∞ when there are none).
    pub min_barrier: f64,
    /// A QP was solved.
    pub solved: bool,
    /// The QP failed and the UAV braked.
    pub failed: bool,
    /// The policy produced no finite action and the UAV braked instead.
    pub policy_fallback: bool,
    /// Wall time of the filter for this UAV (µs), when a QP was solved.
    pub solve_us: f64,
    /// Length (s) of the stall it is in (no progress towards its goal for a while), 0 when none.
    pub stall_s: f64,
}

/// One UAV of the fleet.
pub struct Uav {
    /// Unique id.
    pub id: String,
    /// Name of its policy in the registry.
    pub policy: String,
    /// Where its commands go and its states come from.
    pub link: Box<dyn Link>,
    /// Navigation state (target, goal, arrival, segment).
    pub nav: NavState,
    /// The latest known state.
    pub state: UavState,
    /// What happened in the last tick.
    pub last: UavTick,
    /// Where it is in its flight, as its link said at the start of the last tick.
    pub phase: LinkPhase,
    /// Consecutive ticks without a fresh state from the link.
    pub stale_ticks: u32,
    /// What it is this tick (from `phase`, `stale_ticks` and whether it was airborne when last
    /// heard from), for every stage of the tick.
    pub condition: Condition,
    /// Its progress and standing with the traffic rules.
    pub traffic: UavTraffic,
    /// It was airborne when last heard from, so while lost it may still be in the air.
    pub(crate) was_airborne: bool,
}

impl Uav {
    /// It is known to be in the air (taken over from another server): until its link reports,
    /// e.g. while it connects, it is avoided as lost (its reach disk), never taken for grounded.
    pub fn mark_airborne(&mut self) {
        self.was_airborne = true;
        self.condition = Condition::of(self.phase, true, self.stale_ticks, false);
    }
}

/// Why the traffic rules keep a UAV from its way this tick (the snapshot's `wait_reason`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum WaitReason {
    /// It waits for its turn at a single-file section, or behind the UAV admitted before it.
    SingleFile,
    /// It backs off out of a deadlocked neighbour's way.
    DeadlockBackoff,
    /// It waits before a junction of a network for a movement that crosses its own to clear it.
    Junction,
    /// It waits before a merge of a network for its turn (the merging arms go in order).
    Merge,
}

impl WaitReason {
    /// The name in the API (`single_file`, `deadlock_backoff`, `junction`, `merge`).
    pub fn name(&self) -> &'static str {
        match self {
            WaitReason::SingleFile => "single_file",
            WaitReason::DeadlockBackoff => "deadlock_backoff",
            WaitReason::Junction => "junction",
            WaitReason::Merge => "merge",
        }
    }
}

/// One UAV's standing with the traffic rules.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct UavTraffic {
    /// Progress towards its goal (stalls).
    pub progress: Progress,
    /// The zone it may enter (or is in), with its entry.
    pub grant: Option<(usize, usize)>,
    /// Since when (s) it waits for a zone.
    pub waiting_since: Option<f64>,
    /// Since when (s) it waits at the head of its line for a zone (the first of its entry or arm
    /// not admitted): the wait the rules bound, whatever the number of UAVs in line behind it.
    pub front_since: Option<f64>,
    /// On a network: the conflict zone it may cross (or crosses), with its movement through it
    /// (`crate::traffic::junctions`).
    pub junction: Option<(usize, roads::network::Movement)>,
    /// On a network: where its way stops this tick (before a conflict zone it may not enter yet).
    pub hold: Option<roads::network::Hold>,
    /// The zone (with its entry) it last crossed with a grant: pushed back over that zone's exit
    /// edge, it does not queue for it again (the queue's hold point is on the far side: `mixed`
    /// seed 68 with `rl` flew 12 m back through a section it had crossed).
    pub passed: Option<(usize, usize)>,
    /// Where it is along its route this tick, while the rules apply to it (flying towards a goal,
    /// not arrived, not held by the operator); set by the fleet before [`TrafficRules::plan`].
    pub route: Option<RoutePosition>,
    /// It backs off towards this point until the time given.
    pub back_off: Option<(Vec2, f64)>,
    /// What the rules ask of its target this tick.
    pub restriction: Restriction,
    /// Why the rules keep it from its way this tick, if they do.
    pub waiting: Option<WaitReason>,
    /// The following rule applies to it this tick (traffic comes the other way, or a crowd funnels
    /// into a narrower part: `fleet::following`), which also lowers its speed limit in a dense
    /// crowd ([`crate::traffic::speed::crowd_limit`]).
    pub in_traffic: bool,
    /// On a network: its standing with the congestion-aware route choice.
    pub choice: RouteChoice,
}

/// One UAV's standing with the congestion-aware route choice on a network
/// (`crate::traffic::congestion`).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct RouteChoice {
    /// The cell it was in at the last tick (so that each crossing into a conflict zone counts once).
    pub cell: Option<usize>,
    /// The conflict zone (its cell) at which it last chose its way: it chooses once per zone.
    pub chosen_at: Option<usize>,
}

/// Sets each UAV's `front_since` from `front` (whether it waits at the head of its line this tick,
/// by index): kept while it stays there, started now when it gets there, cleared otherwise.
pub(crate) fn mark_fronts(uavs: &mut [Uav], front: &[bool], now: f64) {
    let mark = |(k, u): (usize, &mut Uav)| {
        u.traffic.front_since = if front.get(k).copied().unwrap_or(false) {
            Some(u.traffic.front_since.unwrap_or(now))
        } else {
            None
        };
    };
    // Each UAV's own record: in parallel for large fleets.
    if crate::tick::parallel(uavs.len()) {
        uavs.par_iter_mut().enumerate().for_each(mark);
    } else {
        uavs.iter_mut().enumerate().for_each(mark);
    }
}

/// A UAV flown by another region, as that region's last message gave it.
#[derive(Debug, Clone, PartialEq)]
pub struct ForeignUav {
    /// Its id.
    pub id: String,
    /// Its state in the last message.
    pub state: UavState,
    /// How old that state is now (s): measured on this side's clock.
    pub age_s: f64,
}

impl ForeignUav {
    /// Where it can be now: the reach disk of its last state after the message's age.
    pub(crate) fn disk(&self, config: &FleetConfig) -> ReachDisk {
        flown_reach_disk(self.state, self.age_s, config.params.delta, config.lost_reach_horizon)
    }
}
