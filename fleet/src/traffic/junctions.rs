//! Junctions and merges of a network as conflict zones (docs/traffic.md, "Junctions and merges"):
//! every cell where three or more passages meet ([`roads::network::ConflictZone`]). A UAV whose way
//! crosses one asks for its movement through it (in by one arm, out by another) once it is
//! [`ASK_M`] from the zone's gate (farther if it could not stop [`HOLD_M`] before it: not from far
//! away, where a grant would keep crossing movements waiting while the UAV is still on its way), and
//! if it is refused it holds there, in line behind those of its arm refused before it:
//! - **first come**: requests are decided in the order the UAVs started waiting; a request is
//!   granted when no UAV holding a grant to the zone has a movement that crosses or merges with it,
//!   so movements that do not conflict (opposite straights in their lanes, right turns, UAVs from
//!   the same arm) pass together;
//! - **a merge zips in order**: two arms into one go one UAV at a time in the order they came;
//! - **maximum wait**: a request that has waited [`JUNCTION_MAX_WAIT_S`] blocks every later request
//!   whose movement crosses it; and an arm whose line's head has waited that long at the head goes
//!   before every other arm (the earliest such head first), while the grants of UAVs that can still
//!   stop before the gate are decided again each tick, before other requests, and given back when
//!   they conflict with it: only UAVs in the zone or too close to stop keep it waiting, so the
//!   head's wait is bounded at any fleet size (docs/traffic.md, 6.);
//! - a UAV already in the zone (pushed in, or starting there) is granted at once: it cannot wait
//!   inside; one that can no longer stop before the zone (braking at δ) goes when no holder
//!   conflicts with it; one past its hold point that can still stop goes back to it.
//!
//! A grant is held while the UAV is in the zone and until it is [`LEAVE_IN_DC`]·D_c past the gate
//! out of it. Cost per tick: O(UAVs + requests · holders), holders being those of one zone.

use crate::member::{ForeignUav, Uav, WaitReason};
use crate::traffic::FOLLOW_GAP_IN_DC;
use roads::network::{Conflict, ConflictZone, GateRule, Hold, Movement, Network, Way};
use uav::Params;

/// Longest wait (s) before a junction or merge after which no later crossing movement is granted,
/// and the head of a line that has waited it there goes before every conflicting movement.
pub const JUNCTION_MAX_WAIT_S: f64 = 15.0;

/// Distance (m) before a zone's gate at which UAVs wait for their turn.
pub const HOLD_M: f64 = 0.6;

/// Distance (m) from a zone's gate at which a UAV asks for its movement: the same for all, so that
/// the order they ask in is the order they come in (farther only for a UAV that could not stop in
/// time, [`ASK_MARGIN_M`]).
pub const ASK_M: f64 = 2.5;

/// Added to the braking distance (at δ/2) and [`HOLD_M`] to get the distance (m) from a zone's gate
/// at which a fast UAV asks for its movement.
pub const ASK_MARGIN_M: f64 = 0.5;

/// Kept (m) between the gate into a zone and where a UAV that asks could stop (braking at δ), for
/// it to count as able to wait.
pub const STOP_MARGIN_M: f64 = 0.05;

/// A grant is held until its UAV is this many D_c past the gate out of the zone.
pub const LEAVE_IN_DC: f64 = 0.0;

/// Who holds a zone when another region's UAV is in it (not one of the fleet's UAVs).
const FOREIGN: usize = usize::MAX;

/// A request for a movement through a zone this tick.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Request {
    zone: usize,
    movement: Movement,
    /// When the UAV started waiting (s); -∞ for one that holds a grant and can still stop.
    since: f64,
    /// Who asks (index of the UAV, id order: the tie break).
    who: usize,
    /// The index in its way's cells of the zone's cell.
    cell: usize,
    /// Its distance (m) along its way to the gate into the zone.
    distance: f64,
    /// It can still stop before the gate (braking at δ).
    can_stop: bool,
    /// Since when (s) the head of its arm's line has waited there, once that is
    /// [`JUNCTION_MAX_WAIT_S`] or more (infinite otherwise): such arms go first.
    overdue: f64,
}

/// The junction rules' state between ticks.
#[derive(Debug, Default)]
pub struct JunctionRules {
    /// The network the zones were found on (its id).
    network: u64,
    zones: Vec<ConflictZone>,
    /// Per cell of the network, its zone.
    zone_of_cell: Vec<Option<usize>>,
    /// Per zone, the movements granted (held) this tick, with who holds each.
    held: Vec<Vec<(Movement, usize)>>,
    /// Scratch: this tick's requests; one zone's refused requests with their wait and who asked.
    requests: Vec<Request>,
    refused: Vec<(Movement, f64, usize)>,
    /// Per UAV, the UAV it waits for this tick when it was refused: a conflicting holder, the one
    /// ahead of it in its arm's line, or an earlier request that goes first.
    waits_for: Vec<Option<usize>>,
    /// Scratch: per UAV, whether it waits at the head of its arm's line this tick.
    heads: Vec<bool>,
    /// Scratch: one zone's lines of refused UAVs, per arm: the arm, the last place taken, who took
    /// it and why its head waits.
    lines: Vec<(usize, u32, usize, Conflict)>,
}

impl JunctionRules {
    /// Applies the rules at time `now` to the UAVs that `tracked` says fly to a goal: sets each one's
    /// `traffic.junction` (its grant), `traffic.hold` (where its way stops this tick) and
    /// `traffic.waiting`. `rule` narrows the passages as the UAVs' ways do; movements closer than
    /// D_c (as kept) cross; δ gives the braking distance. A `foreign` UAV (another region's) in a
    /// zone holds it against every movement from an arm.
    pub fn plan(
        &mut self,
        net: &Network,
        (rule, params): (GateRule, &Params),
        now: f64,
        (uavs, foreign): (&mut [Uav], &[ForeignUav]),
        tracked: impl Fn(&Uav) -> bool,
    ) {
        let (d_c, delta) = (params.kept_d_c(), params.delta);
        if self.network != net.id() {
            self.network = net.id();
            self.zones = net.conflict_zones(rule, d_c);
            self.zone_of_cell = vec![None; net.cells().len()];
            for (k, z) in self.zones.iter().enumerate() {
                self.zone_of_cell[z.cell] = Some(k);
            }
            self.held = vec![Vec::new(); self.zones.len()];
            uavs.iter_mut().for_each(|u| u.traffic.junction = None);
        }
        self.held.iter_mut().for_each(Vec::clear);
        // Another region's UAV in a zone (where it is now as far as is known) holds it against
        // every movement from an arm: its way through the zone is not known here.
        for f in foreign {
            let p = f.state.p + f.state.v * f.age_s;
            if let Some(zone) = net.locate(&p).and_then(|c| self.zone_of_cell[c]) {
                let inside = self.zones[zone].arms.len();
                self.held[zone].push((Movement { entry: inside, exit: inside }, FOREIGN));
            }
        }
        self.requests.clear();
        for (k, u) in uavs.iter_mut().enumerate() {
            u.traffic.hold = None;
            let way = u.nav.way().filter(|_| tracked(u));
            let Some(way) = way else {
                (u.traffic.junction, u.traffic.waiting_since) = (None, None);
                continue;
            };
            let p = u.state.p;
            // At ASK_M (or farther when it could not stop in time); once it asked or was granted, it
            // keeps its place (in a line behind others, say) or its grant within r_s.
            let ask = ASK_M.max(HOLD_M + ASK_MARGIN_M + u.state.v.norm_squared() / delta);
            let asked = u.traffic.waiting_since.is_some() || u.traffic.junction.is_some();
            let ask = if asked { ask.max(params.r_s) } else { ask };
            let ahead = self.zone_ahead(way, p, ask);
            let stops_in = u.state.v.norm_squared() / (2.0 * delta);
            if let Some((zone, movement)) = u.traffic.junction {
                let crossing = ahead.is_some_and(|(z, m, ..)| (z, m) == (zone, movement));
                match ahead {
                    // One that can still stop before the gate is decided again, before every request
                    // that has not waited the maximum: it gives its grant back to such a one.
                    Some((_, _, cell, distance)) if crossing && distance - STOP_MARGIN_M >= stops_in => {
                        let (since, overdue) = (f64::NEG_INFINITY, f64::INFINITY);
                        let request = Request {
                            zone,
                            movement,
                            since,
                            who: k,
                            cell,
                            distance,
                            can_stop: true,
                            overdue,
                        };
                        self.requests.push(request);
                        continue;
                    }
                    _ if crossing || just_left(way, self.zones[zone].cell, p, LEAVE_IN_DC * d_c) => {
                        self.held[zone].push((movement, k));
                        continue;
                    }
                    _ => u.traffic.junction = None,
                }
            }
            let Some((zone, movement, cell, distance)) = ahead else {
                u.traffic.waiting_since = None;
                continue;
            };
            let since = *u.traffic.waiting_since.get_or_insert(now);
            let can_stop = distance - STOP_MARGIN_M >= stops_in;
            // (front_since is the last tick's: whether it waited at the head of its line.)
            let overdue =
                u.traffic.front_since.filter(|s| now - s >= JUNCTION_MAX_WAIT_S).unwrap_or(f64::INFINITY);
            self.requests.push(Request { zone, movement, since, who: k, cell, distance, can_stop, overdue });
        }
        self.heads.clear();
        self.heads.resize(uavs.len(), false);
        self.waits_for.clear();
        self.waits_for.resize(uavs.len(), None);
        self.decide(now, d_c, uavs);
        crate::member::mark_fronts(uavs, &self.heads, now);
    }

    /// Decides this tick's requests, zone by zone in the order they came (the order the UAVs came
    /// within [`ASK_M`] of the zone, which is the order they are in along an arm): one behind a
    /// refused UAV of its arm is refused too and waits in line behind it.
    fn decide(&mut self, now: f64, d_c: f64, uavs: &mut [Uav]) {
        let requests = &mut self.requests;
        // Along an arm the order is the order on it: a UAV counts as having asked no later than any
        // UAV of its arm behind it (one that asked again after a grant it gave back, say, would
        // otherwise be decided after those behind it, and one of them granted would stand behind it
        // holding the zone while it is refused for that grant: a merge stuck for good).
        requests.sort_by(|a, b| {
            (a.zone, a.movement.entry)
                .cmp(&(b.zone, b.movement.entry))
                .then(b.distance.total_cmp(&a.distance))
        });
        // An arm whose line's head has waited the maximum there goes before every other arm (the
        // earliest such head first), the whole arm in its order.
        let mut start = 0;
        while start < requests.len() {
            let arm = (requests[start].zone, requests[start].movement.entry);
            let same = requests[start..].iter().take_while(|r| (r.zone, r.movement.entry) == arm).count();
            let group = &mut requests[start..start + same];
            let overdue = group.iter().map(|r| r.overdue).fold(f64::INFINITY, f64::min);
            let mut since = f64::INFINITY;
            for r in group.iter_mut() {
                since = since.min(r.since);
                (r.since, r.overdue) = (since, overdue);
            }
            start += same;
        }
        requests.sort_by(|a, b| {
            (a.zone, a.overdue, a.since, a.movement.entry)
                .partial_cmp(&(b.zone, b.overdue, b.since, b.movement.entry))
                .unwrap_or(std::cmp::Ordering::Equal)
                .then(a.distance.total_cmp(&b.distance))
        });
        let mut zone = usize::MAX;
        for r in requests.iter() {
            if r.zone != zone {
                zone = r.zone;
                self.refused.clear();
                self.lines.clear();
            }
            let z = &self.zones[zone];
            let conflicts = |m: &Movement| z.conflict(*m, r.movement);
            let by_holder = self.held[zone].iter().find_map(|(m, who)| match conflicts(m) {
                Conflict::None => None,
                c => Some((c, *who)),
            });
            // Earlier refused requests: a merging one always goes first (a zip), a crossing one once
            // it has waited the maximum.
            let by_queue = self.refused.iter().find_map(|(m, since, who)| match conflicts(m) {
                Conflict::Merge => Some((Conflict::Merge, *who)),
                Conflict::Cross if now - since >= JUNCTION_MAX_WAIT_S => Some((Conflict::Cross, *who)),
                _ => None,
            });
            // Behind a refused UAV of its arm: in line after it.
            let line = self.lines.iter_mut().find(|l| l.0 == r.movement.entry);
            let by_line = line.as_ref().map(|l| (l.3, l.2));
            // In the zone, it cannot wait; unable to stop before it, it goes unless a holder conflicts.
            let blocked = if r.distance <= 0.0 {
                None
            } else if !r.can_stop {
                by_holder
            } else {
                by_line.or(by_holder).or(by_queue)
            };
            let u = &mut uavs[r.who];
            let Some((conflict, waits_for)) = blocked else {
                u.traffic.junction = Some((zone, r.movement));
                u.traffic.waiting_since = None;
                self.held[zone].push((r.movement, r.who));
                continue;
            };
            // One that gives its grant back waits from now.
            let asked = *u.traffic.waiting_since.get_or_insert(now);
            u.traffic.junction = None;
            self.refused.push((r.movement, if r.since.is_finite() { r.since } else { asked }, r.who));
            self.waits_for[r.who] = (waits_for != FOREIGN).then_some(waits_for);
            // Its place in the line of its arm: FOLLOW_GAP_IN_DC·D_c behind the one ahead of it.
            let place = match line {
                Some(l) => {
                    (l.1, l.2) = (l.1 + 1, r.who);
                    l.1
                }
                None => {
                    self.lines.push((r.movement.entry, 0, r.who, conflict));
                    0
                }
            };
            self.heads[r.who] = place == 0;
            let back_m = HOLD_M + f64::from(place) * FOLLOW_GAP_IN_DC * d_c;
            u.traffic.hold = Some(Hold { cell: r.cell, back_m });
            let reason = if conflict == Conflict::Merge { WaitReason::Merge } else { WaitReason::Junction };
            u.traffic.waiting = Some(reason);
        }
    }

    /// Per UAV (this tick), the UAV it waits for when a junction or merge refused it.
    pub fn waits_for(&self) -> &[Option<usize>] {
        &self.waits_for
    }

    /// The first zone on `way` ahead of a UAV at `p` within `approach` (m) of it: the zone, the
    /// movement through it, the index of its cell in the way and the distance to its gate (0 inside).
    fn zone_ahead(&self, way: &Way, p: uav::Vec2, approach: f64) -> Option<(usize, Movement, usize, f64)> {
        let cells = way.cells();
        for i in way.at()..cells.len() {
            let distance = if i == way.at() { 0.0 } else { way.to_gate(p, i - 1) };
            if distance > approach {
                return None;
            }
            if let Some(zone) = self.zone_of_cell[cells[i]] {
                let z = &self.zones[zone];
                let entry = z.arm(i.checked_sub(1).map(|b| cells[b]));
                let exit = z.arm(cells.get(i + 1).copied());
                return Some((zone, Movement { entry, exit }, i, distance));
            }
        }
        None
    }
}

/// True when a UAV at `p` on `way` has just left `cell`: it is in the next cell of its way, within
/// `leave` (m) of the gate between them.
fn just_left(way: &Way, cell: usize, p: uav::Vec2, leave: f64) -> bool {
    let at = way.at();
    at >= 1 && way.cells()[at - 1] == cell && way.from_gate(p, at - 1) < leave
}
