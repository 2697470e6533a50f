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
    /// Its policy (a name in the registry).
    pub policy: UavPolicy,
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

/// A UAV's policy: its name in the registry, and its place among the registry's names where the
/// policies stage last looked it up. A new name is a new value, so the place found for the old one
/// is never taken for it. Two are equal when their names are.
#[derive(Debug, Clone)]
pub struct UavPolicy {
    /// The name.
    name: String,
    /// The names' generation (unique to one list of names, [`UavPolicy::place_in`]) and the place
    /// found in it (None: not among them). A new policy starts at generation 0, the empty list's,
    /// where it is in no place: true without a look-up.
    place: (u64, Option<usize>),
}

impl UavPolicy {
    /// The policy named `name`.
    pub fn new(name: String) -> Self {
        Self { name, place: (0, None) }
    }

    /// Its name, taken.
    pub fn into_name(self) -> String {
        self.name
    }

    /// A generation for a new list of names, no other's (the empty list of a new tick pipeline is
    /// generation 0).
    pub(crate) fn next_generation() -> u64 {
        static LAST: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
        LAST.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1
    }

    /// Its place among `names`, whose `generation` no other list of names has: looked up when the
    /// last look-up was in another generation, else the place found then (no string compared).
    pub(crate) fn place_in(&mut self, generation: u64, names: &[String]) -> Option<usize> {
        let (seen, place) = self.place;
        if seen == generation {
            return place;
        }
        let place = names.iter().position(|n| *n == self.name);
        self.place = (generation, place);
        place
    }
}

impl std::ops::Deref for UavPolicy {
    type Target = str;

    fn deref(&self) -> &str {
        &self.name
    }
}

impl std::fmt::Display for UavPolicy {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.name)
    }
}

impl PartialEq for UavPolicy {
    fn eq(&self, other: &Self) -> bool {
        self.name == other.name
    }
}

impl Eq for UavPolicy {}

impl PartialEq<str> for UavPolicy {
    fn eq(&self, other: &str) -> bool {
        self.name == other
    }
}

impl PartialEq<&str> for UavPolicy {
    fn eq(&self, other: &&str) -> bool {
        self.name == *other
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

#[cfg(test)]
mod tests {
    use super::UavPolicy;

    #[test]
    fn a_policy_keeps_its_place_for_one_list_of_names_and_a_new_name_is_looked_up_again() {
        let names = |list: &[&str]| list.iter().map(|s| s.to_string()).collect::<Vec<_>>();
        let (first, second) = (UavPolicy::next_generation(), UavPolicy::next_generation());
        assert_ne!(first, second);
        let mut policy = UavPolicy::new("rl".into());
        assert_eq!(policy.place_in(first, &names(&["pd", "rl"])), Some(1));
        // The same generation: the place found, without looking (these names are not its list).
        assert_eq!(policy.place_in(first, &names(&["rl"])), Some(1));
        // Another list of names: looked up in it.
        assert_eq!(policy.place_in(second, &names(&["rl", "pd"])), Some(0));
        assert_eq!(policy.place_in(second, &names(&[])), Some(0));
        // A new name is a new value: looked up again, in the same generation too.
        policy = UavPolicy::new("mine".into());
        assert_eq!(policy.place_in(second, &names(&["rl", "pd"])), None);
        assert_eq!(policy, UavPolicy::new("mine".into()));
        assert!(policy == "mine" && &*policy == "mine");
        assert_eq!(format!("{policy}"), "mine");
    }
}
