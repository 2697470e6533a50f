//! Congestion-aware routes on a network (docs/traffic.md 8.): what the queue at a conflict zone
//! costs a UAV that joins it, measured from the fleet, and when a UAV takes another way because of it.
//!
//! - **Service**, per *arm* of a zone (its passage in from one neighbour cell): the time a line of
//!   refused UAVs stood at the arm over the number of UAVs that crossed into the zone from it (plus
//!   [`SERVED_PRIOR`]), both forgotten with the time constant [`MEMORY_S`]: the mean wait per UAV
//!   through that arm, as observed (not capped at the junctions' maximum wait; 0 where nobody had
//!   to wait).
//! - **Load**, per arm: the UAVs whose way enters that zone next through it, and those that have
//!   chosen their way at the zone before it and enter this one next after it; counted once every
//!   [`PASS_S`] from the cells of each UAV's way (its two next zones at most).
//! - **Cost** of crossing into a zone by an arm: service × the load, or the load of the zone's
//!   other arms plus one if that is less (a UAV waits behind those of its arm only as long as other
//!   arms have UAVs to let through in turn): the time to drain the queue ahead
//!   ([`CongestionCosts::extra`], the route search's per-passage cost), less, for the UAV that
//!   chooses, the time it needs to get to that arm at cruise speed (the queue drains meanwhile;
//!   [`CongestionCosts::extra_from`]).
//! - **Choice**: a UAV chooses once per zone, on its way to it ([`decide_within`]), before it is
//!   granted its movement: when the queues on its way ahead cost at least the margin, it takes the
//!   fastest way at these costs if that is at least the margin faster than its own and goes through
//!   the same zone, never back ([`roads::NetworkNavigator::reroute`]). It is counted on its way
//!   beyond the zone at once, so the UAVs that choose after it see that way's load: not all of them
//!   switch together. The UAVs are looked at in shares, each once per pass, and at most
//!   [`SEARCHES_PER_TICK`] route search runs per tick (those waiting for one go first).
//!
//! Cost: O(UAVs · cells to their second zone + arms) per pass, O(UAVs / share + arms) per tick to
//! choose and O(UAVs + arms) to observe; route searches bounded per tick.

use crate::member::{Uav, WaitReason};
use crate::traffic::junctions::ASK_M;
use roads::NetworkNavigator;
use roads::network::{CRUISE_MPS, Network, Way};
use uav::Vec2;

/// What the route choice asks of a way to switch to it (s faster, with the queues counted), by
/// default ([`crate::FleetConfig::reroute_margin_s`]).
pub const REROUTE_MARGIN_S: f64 = 5.0;

/// Time constant (s) with which the service of an arm forgets what it observed.
pub const MEMORY_S: f64 = 30.0;

/// UAVs counted as crossed at every arm besides those observed: a line that has stood a while with
/// nobody through yet costs each UAV a third of that while (with 1, the whole while: at a merge
/// where the other arm went first, the first seconds of a line priced its UAVs at 30–45 s each and
/// sent 8 of 30 round the long branch of a ladder that drained in 42.5 s).
pub const SERVED_PRIOR: f64 = 3.0;

/// Seconds between two counts of the load (and the route choices made with them).
pub const PASS_S: f64 = 1.0;

/// Route searches at most per tick (a route search reads every passage of the network: with
/// queues everywhere in a city of 10,000 UAVs, a search for every UAV at a junction cost tens of
/// ms a pass); the UAVs that need one wait for it in turn.
pub const SEARCHES_PER_TICK: usize = 1;

/// UAVs at most that wait for a route search (others try again at the next pass).
pub const MAX_WAITING: usize = 64;

/// Seconds of flight (beyond [`ASK_M`] from the zone's gate) within which a UAV chooses its way at
/// the zone: at least two passes, so that it does not fly past the point between two of them.
pub const DECIDE_S: f64 = 2.0 * PASS_S;

/// Within this distance (m) of a zone's gate a UAV at speed `speed` (m/s) chooses its way at it.
pub fn decide_within(speed: f64) -> f64 {
    ASK_M + DECIDE_S * speed.max(1.0)
}

/// The time (s) from `p` to the passage from `cell` into `zone` at cruise speed in a straight
/// line: no UAV gets there sooner.
fn reach_s(net: &Network, p: Vec2, cell: usize, zone: usize) -> f64 {
    let edge = net.passages(cell).iter().find(|q| q.other == zone).map(|q| q.edge);
    let vertices = &net.cells()[cell].vertices;
    edge.map_or(0.0, |k| {
        let middle = (vertices[k] + vertices[(k + 1) % vertices.len()]) * 0.5;
        (middle - p).norm() / CRUISE_MPS
    })
}

/// One arm of a conflict zone: its load and what was observed of its queue.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
struct Arm {
    /// UAVs on their way in (the last pass's count and the choices since).
    load: u32,
    /// UAVs on their way in by the zone's other arms (the last pass's count).
    others: u32,
    /// Seconds during which a line of refused UAVs stood at the arm (forgotten with [`MEMORY_S`]).
    busy_s: f64,
    /// UAVs that crossed into the zone from it (forgotten alike).
    crossed: f64,
    /// A refused UAV waits at it this tick.
    lined: bool,
}

impl Arm {
    /// The mean wait (s) per UAV through the arm, with [`SERVED_PRIOR`].
    fn service_s(&self) -> f64 {
        self.busy_s / (self.crossed + SERVED_PRIOR)
    }

    /// The time (s) to drain the queue at the arm: a UAV of its load waits behind another only as
    /// long as the other arms have UAVs to let through in turn.
    fn cost_s(&self) -> f64 {
        f64::from(self.load.min(self.others + 1)) * self.service_s()
    }
}

/// The measured queues at a network's conflict zones, between ticks.
#[derive(Debug, Default)]
pub struct CongestionCosts {
    /// The network they were found on (its id).
    network: u64,
    /// Per cell, the index in `arms` of its first arm (the arms follow in the order of its
    /// passages); None for a cell that is no conflict zone (fewer than three passages).
    first_arm: Vec<Option<usize>>,
    arms: Vec<Arm>,
    /// When (s) the next pass is due, and when the last one was.
    next_pass: f64,
    last_pass: f64,
    /// Ticks since the first (which share of the UAVs chooses this tick).
    ticks: usize,
    /// UAVs (indices) that wait for a route search, first come first served.
    waiting: Vec<usize>,
    /// Scratch: the last tick's `waiting`, served this tick.
    served: Vec<usize>,
}

impl CongestionCosts {
    /// Starts afresh on `net` unless it is the network of the last call.
    fn on(&mut self, net: &Network) {
        if self.network == net.id() && !self.first_arm.is_empty() {
            return;
        }
        self.network = net.id();
        self.first_arm.clear();
        self.arms.clear();
        for cell in 0..net.cells().len() {
            let arms = net.passages(cell).len();
            self.first_arm.push((arms >= 3).then_some(self.arms.len()));
            if arms >= 3 {
                self.arms.extend(std::iter::repeat_n(Arm::default(), arms));
            }
        }
        (self.next_pass, self.last_pass) = (0.0, 0.0);
    }

    /// The arm of zone `zone` (a cell) that leads in from its neighbour `from`.
    fn arm(&self, net: &Network, zone: usize, from: usize) -> Option<usize> {
        let first = (*self.first_arm.get(zone)?)?;
        net.passages(zone).iter().position(|p| p.other == from).map(|k| first + k)
    }

    /// The route search's added cost (s) for crossing edge `edge` of cell `cell`: the queue's at
    /// the arm it enters a conflict zone by, 0 elsewhere.
    pub fn extra(&self, net: &Network, cell: usize, edge: usize) -> f64 {
        let into = net.passages(cell).iter().find(|p| p.edge == edge).map(|p| p.other);
        into.and_then(|zone| self.arm(net, zone, cell)).map_or(0.0, |a| self.arms[a].cost_s())
    }

    /// [`CongestionCosts::extra`] as it costs a UAV at `p`: less the time it takes to get there,
    /// during which the queue drains (at cruise speed on the straight line, a lower bound).
    pub fn extra_from(&self, net: &Network, p: Vec2, cell: usize, edge: usize) -> f64 {
        let into = net.passages(cell).iter().find(|q| q.edge == edge).map(|q| q.other);
        let queue = self.extra(net, cell, edge);
        match into {
            Some(zone) if queue > 0.0 => (queue - reach_s(net, p, cell, zone)).max(0.0),
            _ => queue,
        }
    }

    /// The arms by which `way` enters its next zones from index `from` of its cells on: up to `n`
    /// of them, as (index in the way's cells of the zone, arm).
    fn arms_ahead(&self, net: &Network, way: &Way, n: usize) -> impl Iterator<Item = (usize, usize)> {
        let cells = way.cells();
        (way.at() + 1..cells.len())
            .filter_map(move |i| self.arm(net, cells[i], cells[i - 1]).map(|a| (i, a)))
            .take(n)
    }

    /// The first two of [`CongestionCosts::arms_ahead`].
    fn next_two(&self, net: &Network, way: &Way) -> [Option<(usize, usize)>; 2] {
        let mut ahead = self.arms_ahead(net, way, 2);
        [ahead.next(), ahead.next()]
    }

    /// Observes this tick, after the junction rules: each UAV that crossed into a zone, and each
    /// arm at which a refused UAV waits. `dt` is the tick's length (s).
    pub(crate) fn observe(&mut self, net: &Network, dt: f64, uavs: &mut [Uav]) {
        self.on(net);
        for u in uavs.iter_mut() {
            let way = u.nav.way();
            let cell = way.map(Way::cell);
            if let (Some(before), Some(now)) = (u.traffic.choice.cell, cell)
                && before != now
                && let Some(a) = self.arm(net, now, before)
            {
                self.arms[a].crossed += 1.0;
            }
            u.traffic.choice.cell = cell;
            let refused = matches!(u.traffic.waiting, Some(WaitReason::Junction | WaitReason::Merge));
            if let (true, Some(hold), Some(way)) = (refused, u.traffic.hold, way) {
                let cells = way.cells();
                if hold.cell >= 1
                    && hold.cell < cells.len()
                    && let Some(a) = self.arm(net, cells[hold.cell], cells[hold.cell - 1])
                {
                    self.arms[a].lined = true;
                }
            }
        }
        for arm in self.arms.iter_mut().filter(|a| a.lined) {
            arm.busy_s += dt;
            arm.lined = false;
        }
    }

    /// Once every [`PASS_S`] (at time `now`, s): forgets, and counts the load from the ways of the
    /// UAVs that `tracked` says fly to a goal. Every tick (of `dt` s): a share of the UAVs, each
    /// once per pass, and first those that wait for a route search, choose their way at their next
    /// zone if they come to it without a grant through it, with `margin_s`
    /// ([`crate::FleetConfig::reroute_margin_s`]).
    pub(crate) fn choose(
        &mut self,
        nav: &NetworkNavigator,
        margin_s: f64,
        (now, dt): (f64, f64),
        uavs: &mut [Uav],
        tracked: impl Fn(&Uav) -> bool,
    ) {
        let net = nav.net;
        self.on(net);
        if now >= self.next_pass {
            self.count(net, now, uavs, &tracked);
        }
        let share = ((PASS_S / dt).round() as usize).max(1);
        let slot = self.ticks % share;
        self.ticks = self.ticks.wrapping_add(1);
        let mut searches = SEARCHES_PER_TICK;
        // Last tick's waiting list is served first; this tick's is built afresh (buffers reused).
        std::mem::swap(&mut self.waiting, &mut self.served);
        self.waiting.clear();
        let served = std::mem::take(&mut self.served);
        for k in served.iter().copied().chain((slot..uavs.len()).step_by(share)) {
            let Some(u) = uavs.get_mut(k).filter(|u| tracked(u)) else { continue };
            if !self.choose_one(nav, margin_s, u, &mut searches)
                && !self.waiting.contains(&k)
                && self.waiting.len() < MAX_WAITING
            {
                self.waiting.push(k);
            }
        }
        self.served = served;
    }

    /// Forgets what was observed by the time since the last pass and counts the load afresh.
    fn count(&mut self, net: &Network, now: f64, uavs: &[Uav], tracked: impl Fn(&Uav) -> bool) {
        let forget = (-(now - self.last_pass) / MEMORY_S).exp();
        (self.next_pass, self.last_pass) = (now + PASS_S - 1e-9, now);
        for arm in &mut self.arms {
            arm.load = 0;
            arm.busy_s *= forget;
            arm.crossed *= forget;
        }
        for u in uavs.iter().filter(|u| tracked(u)) {
            let Some(way) = u.nav.way() else { continue };
            let [first, second] = self.next_two(net, way);
            // Beyond its next zone only once it has chosen its way there.
            let chosen = first.is_some_and(|(i, _)| u.traffic.choice.chosen_at == Some(way.cells()[i]));
            for (_, a) in first.into_iter().chain(second.filter(|_| chosen)) {
                self.arms[a].load += 1;
            }
        }
        for (cell, first) in self.first_arm.iter().enumerate() {
            let Some(first) = *first else { continue };
            let arms = &mut self.arms[first..first + net.passages(cell).len()];
            let total: u32 = arms.iter().map(|a| a.load).sum();
            arms.iter_mut().for_each(|a| a.others = total - a.load);
        }
    }

    /// Lets `u` choose its way at its next zone if it comes to it ([`decide_within`]) without a
    /// grant and has not chosen there yet, using one of `searches` if the queues on its way cost
    /// `margin_s` or more. False when it needs a search and none is left (it waits for one).
    fn choose_one(
        &mut self,
        nav: &NetworkNavigator,
        margin_s: f64,
        u: &mut Uav,
        searches: &mut usize,
    ) -> bool {
        let net = nav.net;
        let Some(way) = u.nav.way().filter(|_| u.traffic.junction.is_none()) else { return true };
        let [Some((i, _)), _] = self.next_two(net, way) else { return true };
        let (p, zone) = (u.state.p, way.cells()[i]);
        if u.traffic.choice.chosen_at == Some(zone) || way.to_gate(p, i - 1) > decide_within(u.state.v.norm())
        {
            return true;
        }
        let cells = way.cells();
        let queued: f64 = (self.arms_ahead(net, way, usize::MAX))
            .map(|(i, a)| self.arms[a].cost_s() - reach_s(net, p, cells[i - 1], cells[i]))
            .map(|cost| cost.max(0.0))
            .sum();
        if queued >= margin_s {
            if *searches == 0 {
                return false;
            }
            *searches -= 1;
            let costs = &*self;
            let keep = i - way.at() + 1;
            nav.reroute(&mut u.nav, p, keep, |cell, edge| costs.extra_from(net, p, cell, edge), margin_s);
        }
        // Counted on its way beyond the zone at once (the zone it chose at is its new way's next).
        let Some(way) = u.nav.way() else { return true };
        let [first, second] = self.next_two(net, way);
        if let Some((_, a)) = second {
            self.arms[a].load += 1;
        }
        u.traffic.choice.chosen_at = first.map(|(i, _)| way.cells()[i]);
        true
    }
}
