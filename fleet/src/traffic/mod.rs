//! The fleet's traffic rules (`traffic` navigation, docs/traffic.md), run once per tick
//! before the targets are chosen, in O(UAVs + zones + neighbour pairs):
//! - **single-file sections**: the parts of the road where two opposite lanes do not fit are
//!   conflict zones ([`crate::traffic::zones`]); a UAV whose route crosses one holds before it until the
//!   zone admits its direction;
//! - **deadlock resolution**: a UAV stalled for [`DEADLOCK_AFTER_S`] next to a stalled neighbour
//!   with priority (stalled longer, then the smaller id) backs off for [`BACK_OFF_S`] to the far
//!   right of its lane, or, in a single-file part, back to the nearest place where two fit
//!   ([`crate::traffic::deadlocks`]);
//! - foreign UAVs (other regions') are seen too ([`crate::traffic::foreign`]).

pub(crate) mod along;
pub mod congestion;
pub mod cycles;
pub(crate) mod deadlocks;
pub mod following;
pub mod foreign;
pub mod junctions;
pub mod passing;
pub mod sections;
pub mod speed;
pub(crate) mod yielding;
pub mod zones;

pub use crate::member::{RouteChoice, UavTraffic, WaitReason};

use crate::member::Uav;
use crate::ragged::Ragged;
use crate::traffic::foreign::{ForeignNear, ForeignView};
use crate::traffic::sections::{HOLD_M, Section, next_section, sections};
use crate::traffic::speed::SpeedProfile;
use crate::traffic::zones::{Request, Reservations};
use roads::{Navigator, Restriction, RoutePosition};

/// A stall this long (s) next to a stalled neighbour with priority makes a UAV back off.
pub const DEADLOCK_AFTER_S: f64 = 3.0;

/// How long (s) a back-off lasts.
pub const BACK_OFF_S: f64 = 3.0;

/// How far (m) past its hold point a UAV must be to count as pushed past it (admitted at once if its
/// side is open, even when the phase admits no more): one hovering at its hold point sways a few
/// centimetres past it, and counted as pushed it was admitted past the maximum wait, so a side's
/// whole queue went in while the other side waited (60 UAVs each way: the head waited 209 s).
pub const PUSHED_PAST_HOLD_M: f64 = 0.3;

/// Gap (in D_c) a UAV admitted to a zone keeps behind the one ahead of it on the way in.
pub const FOLLOW_GAP_IN_DC: f64 = 2.0;

/// Neighbours closer than this many D_c count as blocking each other in the deadlock rule.
pub(crate) const BLOCKING_IN_DC: f64 = 3.0;

/// The state of one single-file section this tick (dashboard, Rerun).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SectionUse {
    /// The section.
    pub section: Section,
    /// The entry it admits from (0: its start, 1: its end), while in use.
    pub open: Option<usize>,
    /// UAVs holding a grant (inside or on their way in).
    pub admitted: u32,
    /// UAVs waiting for their turn.
    pub waiting: u32,
}

/// The rules' state between ticks.
#[derive(Debug, Default)]
pub struct TrafficRules {
    road_id: u64,
    sections: Vec<Section>,
    zones: Reservations,
    /// Scratch (kept between ticks, so the loop does not allocate): this tick's requests, and the
    /// admitted UAVs on their way in as (zone, entry, −progress, UAV).
    requests: Vec<Request>,
    entering: Vec<(usize, usize, f64, usize)>,
    /// Scratch: the UAVs not admitted as (zone, entry, −progress, UAV), to queue them up.
    queue: Vec<(usize, usize, f64, usize)>,
    /// Scratch: the section (zone, entry) each UAV must cross next, if it is near one.
    wanted: Vec<Option<(usize, usize)>>,
    /// The UAVs that want a zone this tick, in order, each with the (zone, entry) it wants.
    asking: Vec<(usize, (usize, usize))>,
    /// Scratch: per zone and entry, the queue order of the foremost UAV waiting there.
    front: Vec<f64>,
    /// Scratch: per UAV, whether it waits at the head of its entry's queue this tick.
    heads: Vec<bool>,
    /// Scratch: per UAV, whether it may back off this tick (one running, or stalled long enough).
    may_back_off: Vec<bool>,
    /// The speed limit along the road (rebuilt with the sections when the road changes).
    speeds: SpeedProfile,
    /// Scratch: where the UAVs are along the road by direction (`crate::traffic::following`).
    along: crate::traffic::along::TrafficAlong,
    /// On a network: the junctions and merges (`crate::traffic::junctions`).
    pub(crate) junctions: crate::traffic::junctions::JunctionRules,
    /// On a network: the queues at the conflict zones and the route choice they drive
    /// (`crate::traffic::congestion`).
    pub(crate) congestion: crate::traffic::congestion::CongestionCosts,
    /// On a network: the cycles of waits found and broken (`crate::traffic::cycles`).
    pub(crate) cycles: crate::traffic::cycles::WaitCycles,
}

impl TrafficRules {
    /// The single-file sections of the current road.
    pub fn sections(&self) -> &[Section] {
        &self.sections
    }

    /// The speed limit (m/s) at arc length `s` for a UAV flying towards `direction` (±1) on the
    /// road of the last [`TrafficRules::plan`].
    pub fn speed_limit(&self, s: f64, direction: f64) -> f64 {
        self.speeds.at(s, direction)
    }

    /// Each single-file section with who uses it and who waits for it, as of the last tick.
    pub fn section_use<'a>(&'a self, uavs: &'a [Uav]) -> impl Iterator<Item = SectionUse> + 'a {
        let mut counts = vec![(0u32, 0u32); self.sections.len()];
        for u in uavs {
            if let Some((zone, _)) = u.traffic.grant {
                counts[zone].0 += 1;
            }
        }
        for r in &self.requests {
            if uavs.get(r.who).is_some_and(|u| u.traffic.grant.is_none()) {
                counts[r.zone].1 += 1;
            }
        }
        self.sections.iter().zip(counts).enumerate().map(|(z, (&section, (admitted, waiting)))| SectionUse {
            section,
            // One zone per section: both are rebuilt together when the road changes.
            open: self.zones.open(z),
            admitted,
            waiting,
        })
    }

    /// Applies the rules at time `now` and sets each UAV's `traffic.restriction`, from its
    /// `traffic.route` and progress (updated by the fleet). `neighbours[k]` lists the UAVs near UAV k,
    /// `foreign` the foreign UAVs near it (followed like own UAVs, [`crate::traffic::foreign`]).
    pub fn plan(
        &mut self,
        nav: &Navigator,
        now: f64,
        uavs: &mut [Uav],
        neighbours: &Ragged<usize>,
        foreign: ForeignNear<'_>,
    ) {
        if self.road_id != nav.road.id() {
            self.road_id = nav.road.id();
            self.sections = sections(nav.road, nav);
            self.zones = Reservations::new(self.sections.len());
            self.speeds = SpeedProfile::new(nav.road.profile());
            uavs.iter_mut().for_each(|u| u.traffic.passed = None);
        }
        // Each UAV's restriction and wait are cleared by the first pass of `reserve` (a sequential
        // pass over the fleet's records fewer: at 100,000 UAVs about 1 ms).
        self.reserve(nav, now, uavs, foreign.all());
        crate::traffic::following::follow(nav, uavs, neighbours, foreign, &mut self.along);
        self.resolve_deadlocks(nav, now, uavs, neighbours, foreign);
    }

    fn reserve(&mut self, nav: &Navigator, now: f64, uavs: &mut [Uav], foreign: &[ForeignView]) {
        self.zones.begin();
        self.requests.clear();
        let approach = 2.0 * nav.r_s + HOLD_M;
        crate::traffic::foreign::occupy(&self.sections, &mut self.zones, foreign, approach);
        let gap = FOLLOW_GAP_IN_DC * nav.d_c;
        // Each UAV's next section, not the one it last crossed while it is on that one's exit side;
        // a grant it no longer wants marks its zone as crossed. No restriction or wait yet. Per UAV
        // (each writes only its own record): in parallel for large fleets.
        let (sections, zones) = (&self.sections, &self.zones);
        let wanted_by = |u: &mut Uav| {
            let pos = u.traffic.route?;
            let wanted = next_section(sections, &pos, approach).filter(|&(zone, entry)| {
                (u.traffic.passed != Some((zone, entry)) || !sections[zone].exit_side(entry, pos.s))
                    && !flies_on_inside(
                        &sections[zone],
                        zones.open(zone),
                        (zone, entry),
                        &pos,
                        u.traffic.grant,
                    )
            });
            if let Some(granted) = u.traffic.grant.filter(|&g| wanted != Some(g)) {
                u.traffic.passed = Some(granted);
            }
            wanted
        };
        let want = |u: &mut Uav| {
            u.traffic.restriction = Restriction::default();
            u.traffic.waiting = None;
            if u.traffic.route.is_none() {
                u.traffic.passed = None;
            }
            let wanted = wanted_by(u);
            if wanted.is_none() {
                // Wanting no zone, it keeps no grant and waits for none; the passes below skip it.
                u.traffic.grant = None;
                u.traffic.waiting_since = None;
            }
            wanted
        };
        crate::tick::map_mut_into(uavs, want, &mut self.wanted);
        // The UAVs that want a zone, in order: the only records the passes below read.
        self.asking.clear();
        self.asking.extend(self.wanted.iter().enumerate().filter_map(|(k, w)| w.map(|w| (k, w))));
        // The foremost UAV waiting at each entry (without its grant).
        self.front.clear();
        self.front.resize(2 * self.sections.len(), f64::INFINITY);
        for &(k, (zone, entry)) in &self.asking {
            let u = &uavs[k];
            if let Some(pos) = u.traffic.route
                && u.traffic.grant != Some((zone, entry))
            {
                let front = &mut self.front[2 * zone + entry];
                *front = front.min(queue_order(&pos));
            }
        }
        for &(k, (zone, entry)) in &self.asking {
            let u = &mut uavs[k];
            let position = u.traffic.route;
            if u.traffic.grant == Some((zone, entry))
                && let Some(pos) = position
            {
                // Clear of its entry (the next may follow, lined up behind it) once a follow gap past
                // its hold point.
                let z = self.sections[zone];
                let entering =
                    if entry == 0 { pos.s < z.hold_before + gap } else { pos.s > z.hold_after - gap };
                // A UAV on its way in with a waiting UAV more than D_c ahead of it (they swapped
                // places before it got there) gives its grant back: the grant goes to the head of the
                // queue, the one it would otherwise follow for good while that one waits.
                let overtaken = entering && self.front[2 * zone + entry] < queue_order(&pos) - nav.d_c;
                if !overtaken {
                    self.zones.held(zone, entry, entering);
                    continue;
                }
            }
            u.traffic.grant = None;
            let since = *u.traffic.waiting_since.get_or_insert(now);
            let z = self.sections[zone];
            let pushed = PUSHED_PAST_HOLD_M;
            let past_hold = position.is_some_and(|p| {
                if entry == 0 { p.s > z.hold_before + pushed } else { p.s < z.hold_after - pushed }
            });
            let order = position.map_or(f64::INFINITY, |p| queue_order(&p));
            let inside = position.is_some_and(|p| (z.start..=z.end).contains(&p.s));
            self.requests.push(Request { zone, entry, since, order, rank: k, who: k, past_hold, inside });
        }
        self.line_up(nav, uavs);
        self.zones.decide(&mut self.requests, now, |r| {
            uavs[r.who].traffic.grant = Some((r.zone, r.entry));
            uavs[r.who].traffic.waiting_since = None;
        });
        self.queue_up(nav, uavs);
        crate::member::mark_fronts(uavs, &self.heads, now);
    }

    /// UAVs not admitted wait in a column in their lane: the k-th nearest to the section holds
    /// k·[`FOLLOW_GAP_IN_DC`]·D_c before the hold point, so that a queue does not crowd the hold
    /// point across the road and block those leaving the section in the other lane.
    fn queue_up(&mut self, nav: &Navigator, uavs: &mut [Uav]) {
        let queue = &mut self.queue;
        queue.clear();
        for r in &self.requests {
            let u = &uavs[r.who];
            if let (None, Some(pos)) = (u.traffic.grant, u.traffic.route) {
                let along = if r.entry == 0 { pos.s } else { -pos.s };
                queue.push((r.zone, r.entry, -along, r.who));
            }
        }

        queue.sort_by(|a, b| (a.0, a.1).cmp(&(b.0, b.1)).then(a.2.total_cmp(&b.2)).then(a.3.cmp(&b.3)));
        let gap = FOLLOW_GAP_IN_DC * nav.d_c;
        let mut place = 0;
        self.heads.clear();
        self.heads.resize(uavs.len(), false);
        for k in 0..queue.len() {
            let (zone, entry, _, who) = queue[k];
            place = if k > 0 && (queue[k - 1].0, queue[k - 1].1) == (zone, entry) { place + 1 } else { 0 };
            self.heads[who] = place == 0;
            let z = self.sections[zone];
            let (hold, direction) = if entry == 0 { (z.hold_before, 1.0) } else { (z.hold_after, -1.0) };
            let hold = hold - direction * gap * place as f64;
            let u = &mut uavs[who];
            u.traffic.restriction.hold_at = Some(hold);
            // Waiting once its place limits its target (within r_s), not while far away.
            if u.traffic.route.is_some_and(|p| (hold - p.s) * p.direction() <= nav.r_s) {
                u.traffic.waiting = Some(WaitReason::SingleFile);
            }
        }
    }

    /// UAVs admitted to a zone and still on their way in go in single file: each one but the first
    /// (the farthest along) waits [`FOLLOW_GAP_IN_DC`]·D_c behind the one ahead of it, so a group
    /// admitted together does not squeeze into the entry side by side and clog it.
    fn line_up(&mut self, nav: &Navigator, uavs: &mut [Uav]) {
        let entering = &mut self.entering;
        entering.clear();
        // Only a UAV that wants a zone still holds a grant here (`reserve`).
        for &(k, _) in &self.asking {
            let u = &uavs[k];
            if let (Some((zone, entry)), Some(pos)) = (u.traffic.grant, u.traffic.route) {
                let z = self.sections[zone];
                let along = if entry == 0 { pos.s } else { -pos.s };
                let edge = if entry == 0 { z.start } else { -z.end };
                if along < edge + nav.d_c {
                    entering.push((zone, entry, -along, k));
                }
            }
        }
        entering.sort_by(|a, b| (a.0, a.1).cmp(&(b.0, b.1)).then(a.2.total_cmp(&b.2)));
        for pair in entering.windows(2) {
            let (ahead, behind) = (pair[0], pair[1]);
            if (ahead.0, ahead.1) == (behind.0, behind.1) {
                let direction = if behind.1 == 0 { 1.0 } else { -1.0 };
                let wait = -ahead.2 * direction - direction * FOLLOW_GAP_IN_DC * nav.d_c;
                uavs[behind.3].traffic.restriction.hold_at = Some(wait);
                uavs[behind.3].traffic.restriction.wait_here = true;
                uavs[behind.3].traffic.waiting = Some(WaitReason::SingleFile);
            }
        }
    }
}

/// True when a UAV at `pos` inside a passable section, without a grant to it and with the section
/// open to its other entry, flies on through it in its lane instead of queueing: it cannot wait
/// inside, and going back out to the hold point means flying against everyone admitted (`mixed`
/// seed 68: a UAV that started inside flew 8 m back and lost 25 s). Opposite UAVs can pass there.
fn flies_on_inside(
    z: &Section,
    open: Option<usize>,
    (zone, entry): (usize, usize),
    pos: &RoutePosition,
    grant: Option<(usize, usize)>,
) -> bool {
    z.passable
        && z.start < pos.s
        && pos.s < z.end
        && grant != Some((zone, entry))
        && open.is_some_and(|e| e != entry)
}

/// A UAV's place in the queue of an entry, lower first: how far along its route it is (UAVs wait in
/// a column, the foremost at the head).
fn queue_order(pos: &RoutePosition) -> f64 {
    -pos.direction() * pos.s
}

#[cfg(test)]
mod tests {
    use super::*;
    use roads::{NavMode, Road, RoadLayout};
    use uav::{Params, Vec2};

    /// Two UAVs nose to nose on a 2 m wide road, each heading for the other's side.
    fn head_on(ids: [&str; 2]) -> (Road, Vec<(String, Vec2, Vec2)>) {
        let road = Road::new(RoadLayout::from_centerline(&[[0.0, 0.0], [20.0, 0.0]], &[2.0, 2.0])).unwrap();
        let a = (ids[0].to_string(), Vec2::new(10.0, 0.0), Vec2::new(18.0, 0.0));
        let b = (ids[1].to_string(), Vec2::new(10.4, 0.0), Vec2::new(2.0, 0.0));
        (road, vec![a, b])
    }

    /// Runs the rules for `seconds` on UAVs that do not move; returns each one's standing.
    fn stand_still(road: &Road, uavs: &[(String, Vec2, Vec2)], seconds: f64) -> Vec<UavTraffic> {
        let params = Params::default();
        let config = crate::FleetConfig { params, ..crate::FleetConfig::default() };
        let mut fleet =
            crate::Fleet::new(config, road.clone(), policies::PolicyRegistry::with_pd(params.delta));
        for (id, p, goal) in uavs {
            let state = uav::UavState::at_rest(*p);
            fleet.add(
                id.clone(),
                "pd".into(),
                Box::new(links::SimLink::new(state, params.dt)),
                state,
                Some(*goal),
            );
        }
        let nav = Navigator::new(
            fleet.road.road().expect("the test fleet flies a road"),
            NavMode::Traffic,
            &params,
        );
        let mut rules = TrafficRules::default();
        let neighbours: Ragged<usize> =
            (0..uavs.len()).map(|k| (0..uavs.len()).filter(|&d| d != k).collect()).collect();
        let mut t = 0.0;
        while t <= seconds {
            for u in &mut fleet.uavs {
                nav.locate(&mut u.nav, u.state.p);
                u.traffic.route = u.nav.position;
                u.traffic.progress.update(u.traffic.route.map(|r| r.remaining()), t);
                let goal = u.nav.goal().unwrap_or(u.state.p);
                u.last.target = u.state.p + (goal - u.state.p).normalize();
            }
            rules.plan(&nav, t, &mut fleet.uavs, &neighbours, ForeignNear::none());
            t += params.dt;
        }
        fleet.uavs.iter().map(|u| u.traffic).collect()
    }

    #[test]
    fn of_two_stalled_uavs_nose_to_nose_the_lower_priority_one_steps_aside() {
        for ids in [["a", "b"], ["b", "a"]] {
            let (road, uavs) = head_on(ids);
            // Before DEADLOCK_AFTER_S nobody moves aside.
            let early = stand_still(&road, &uavs, DEADLOCK_AFTER_S - 0.2);
            assert!(early.iter().all(|s| s.back_off.is_none()));
            let late = stand_still(&road, &uavs, DEADLOCK_AFTER_S + 0.2);
            // Equal stalls: the smaller id goes first, the other steps aside, inside the road.
            let (winner, loser) = if ids[0] == "a" { (0, 1) } else { (1, 0) };
            assert!(late[winner].back_off.is_none(), "{ids:?}: {late:?}");
            let (target, _) = late[loser].back_off.expect("the other one steps aside");
            assert!((target - uavs[loser].1).norm() > 0.2, "{target:?}");
            assert!(road.boundary_distance(&target) >= 0.1 + 0.1 - 1e-9, "{target:?}");
            // Off the winner's way: to the side of the line it flies along (y = 0).
            assert!(target.y.abs() >= 0.2, "{target:?}");
        }
    }
}
