//! Foreign UAVs (flown by another region, [`crate::ForeignUav`]) as the traffic rules see them: known
//! only by position, velocity and the age of their state, never commanded and never moved by these
//! rules. Their goals and arrivals are unknown, so a foreign UAV flying along the road counts as a
//! flying neighbour heading for the road's end in its direction of travel (it can be followed, and
//! it is traffic coming the other way for those it meets; the direction it last flew is remembered
//! by id, for the single-file sections), and one that has hovered (< [`HOVER_SPEED_MPS`]) for
//! [`PARKED_AFTER_S`] counts as parked (it is passed, as an arrived UAV that cannot step aside is).
//! Each own UAV reads the foreign UAVs of its neighbour list only (`NeighbourSearch::foreign`): the
//! same grid as its own neighbours, no scan per UAV; each foreign UAV costs one segment lookup per
//! tick.

use crate::member::ForeignUav;
use crate::ragged::Ragged;
use crate::traffic::sections::{EXIT_M, Section};
use crate::traffic::zones::Reservations;
use roads::{Road, RoutePosition};
use safety::ReachDisk;
use std::collections::HashMap;
use uav::Vec2;

/// Speed (m/s) under which a foreign UAV counts as hovering.
pub const HOVER_SPEED_MPS: f64 = 0.1;

/// Speed (m/s) along the road from which a foreign UAV counts as flying along it, one way or the
/// other (and only while most of its velocity is along the road: one pushed around in a bend or
/// across the road gives no direction to follow or to meet).
pub const ALONG_SPEED_MPS: f64 = 0.3;

/// How long (s) a foreign UAV must have hovered to count as parked (a UAV stopped in a moving queue
/// sets off again well before; as long as a stall before the deadlock rule acts,
/// [`crate::traffic::DEADLOCK_AFTER_S`]).
pub const PARKED_AFTER_S: f64 = 3.0;

/// What the traffic rules know of one foreign UAV this tick.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ForeignView {
    /// Where it is now as far as is known: its last position moved on by its velocity for the
    /// state's age (the centre of its reach disk).
    pub p: Vec2,
    /// Its last velocity.
    pub v: Vec2,
    /// The road segment it is in (also the hint for the next tick's lookup).
    pub segment: usize,
    /// Its arc length along the road.
    pub s: f64,
    /// Its speed along the road (m/s, towards increasing arc length).
    pub along: f64,
    /// Where it is along the road once it has flown along it: the direction it last flew at
    /// [`ALONG_SPEED_MPS`] or more (kept while it slows down, hovers or is pushed about), its goal
    /// taken as the road's end that way (unknown, so it is never taken to stop short). None until
    /// it has flown along the road.
    pub route: Option<RoutePosition>,
    /// How long (s) it has hovered (0 while it moves).
    pub hovering_s: f64,
    /// It has hovered for at least [`PARKED_AFTER_S`].
    pub parked: bool,
}

impl ForeignView {
    /// It moves (not hovering): a flying neighbour.
    pub fn moving(&self) -> bool {
        self.v.norm() >= HOVER_SPEED_MPS
    }

    /// Where it is along the road while it flies along it now, at [`ALONG_SPEED_MPS`] or more with
    /// most of its velocity along the road (one pushed about in a bend or across the road gives no
    /// direction): a UAV to follow, or traffic coming the other way.
    pub fn flying_along(&self) -> Option<RoutePosition> {
        let along = self.along * self.route.map_or(0.0, |r| r.direction());
        self.route.filter(|_| along >= ALONG_SPEED_MPS && along >= 0.5 * self.v.norm())
    }
}

/// What the rules remember of one foreign UAV between ticks.
#[derive(Debug, Clone, Copy)]
struct Remembered {
    /// Since when (s) it hovers (None while it moves).
    hovering_since: Option<f64>,
    /// The direction (±1) it last flew along the road, 0 before it did.
    direction: f64,
    /// The update that last listed it.
    seen: u64,
}

/// What the rules remember of the foreign UAVs between ticks, by id (since when each hovers, which
/// way it last flew along the road), and this tick's views; kept between ticks so that no
/// allocation happens per foreign UAV once its id has been seen.
#[derive(Debug, Default)]
pub(crate) struct ForeignViews {
    by_id: HashMap<String, Remembered>,
    updates: u64,
    /// This tick's view of each foreign UAV, by its index in the fleet's foreign list.
    pub(crate) views: Vec<ForeignView>,
}

impl ForeignViews {
    /// Rebuilds the views for the `foreign` UAVs with their reach `disks` on `road` at time `now`;
    /// forgets the ids not listed.
    pub(crate) fn update(&mut self, road: &Road, foreign: &[ForeignUav], disks: &[ReachDisk], now: f64) {
        self.updates += 1;
        let line = road.centerline();
        self.views.truncate(foreign.len());
        for (f, (uav, disk)) in foreign.iter().zip(disks).enumerate() {
            let (p, v) = (disk.centre, uav.state.v);
            let segment = road.locate(&p, self.views.get(f).map(|v| v.segment));
            let s = line.project_on_piece(segment, &p);
            let along = v.dot(&line.tangent_at(s));
            let hovers = v.norm() < HOVER_SPEED_MPS;
            let flies_along = along.abs() >= ALONG_SPEED_MPS && along.abs() >= 0.5 * v.norm();
            let updates = self.updates;
            let remember = |last: Option<Remembered>| Remembered {
                hovering_since: hovers.then(|| last.and_then(|m| m.hovering_since).unwrap_or(now)),
                // The direction it flies along the road now; else the last one; else a first guess.
                direction: match last.map_or(0.0, |m| m.direction) {
                    _ if flies_along => along.signum(),
                    0.0 if along.abs() >= HOVER_SPEED_MPS => along.signum(),
                    last => last,
                },
                seen: updates,
            };
            // One lookup per UAV; an id is stored once, when first seen.
            let memory = match self.by_id.get_mut(uav.id.as_str()) {
                Some(slot) => {
                    *slot = remember(Some(*slot));
                    *slot
                }
                None => {
                    let memory = remember(None);
                    self.by_id.insert(uav.id.clone(), memory);
                    memory
                }
            };
            let direction = memory.direction;
            let route = (direction != 0.0).then(|| {
                let lateral = line.lateral(segment, &p);
                let goal_s = if direction > 0.0 { line.length().max(s) } else { 0.0f64.min(s) };
                RoutePosition { s, lateral, goal_s, goal_lateral: lateral }
            });
            let hovering_s = memory.hovering_since.map_or(0.0, |since| (now - since).max(0.0));
            let parked = hovering_s >= PARKED_AFTER_S;
            let view = ForeignView { p, v, segment, s, along, route, hovering_s, parked };
            match self.views.get_mut(f) {
                Some(slot) => *slot = view,
                None => self.views.push(view),
            }
        }
        let updates = self.updates;
        self.by_id.retain(|_, memory| memory.seen == updates);
    }

    /// Forgets every view (no foreign UAVs seen this tick).
    pub(crate) fn clear(&mut self) {
        self.views.clear();
    }
}

/// How far (m) beyond its hold point a foreign UAV hovering there counts as waiting at that entry
/// of a section (the head of its queue; farther back, a hovering UAV may be parked for good).
pub const WAITING_AT_HOLD_M: f64 = 1.0;

/// Reports to `zones` how foreign UAVs use every single-file section (`sections`, in order along
/// the road). One that has flown along the road ([`ForeignView::route`]) inside it, past its hold
/// point on its way in, or within [`EXIT_M`] beyond its far end on its way out uses it from the
/// entry its direction gives; before a hold point within `approach` (once parked, within
/// [`WAITING_AT_HOLD_M`]) it waits at that entry. One hovering near a hold point without a
/// direction waits there too. A section that spans a border is then used one way at a time by
/// both regions. O(log sections) per foreign UAV.
pub(crate) fn occupy(sections: &[Section], zones: &mut Reservations, views: &[ForeignView], approach: f64) {
    for view in views {
        let s = view.s;
        // A UAV hovering near a section waits for it until it has hovered long enough to count as
        // parked; at the head of a queue, however long.
        let reach = if view.parked { WAITING_AT_HOLD_M } else { approach };
        let next = sections.partition_point(|z| z.start <= s);
        let first = next.saturating_sub(1);
        for (zone, z) in sections.iter().enumerate().skip(first).take(next + 1 - first) {
            match view.route.map(|r| r.direction()) {
                Some(d) if d > 0.0 && (z.hold_before..=z.end + EXIT_M).contains(&s) => {
                    zones.foreign_inside(zone, 0)
                }
                Some(d) if d < 0.0 && (z.start - EXIT_M..=z.hold_after).contains(&s) => {
                    zones.foreign_inside(zone, 1)
                }
                Some(d) if d > 0.0 && (z.hold_before - reach..z.hold_before).contains(&s) => {
                    zones.foreign_waiting(zone, 0)
                }
                Some(d) if d < 0.0 && (z.hold_after..z.hold_after + reach).contains(&s) => {
                    zones.foreign_waiting(zone, 1)
                }
                Some(_) => {}
                None if (z.hold_before - reach..=z.hold_before + EXIT_M).contains(&s) => {
                    zones.foreign_waiting(zone, 0)
                }
                None if (z.hold_after - EXIT_M..=z.hold_after + reach).contains(&s) => {
                    zones.foreign_waiting(zone, 1)
                }
                None => {}
            }
        }
    }
}

/// True when a stalled UAV at `me` (temporary target `my_target`, id `my_id`) gives way to a foreign
/// UAV `f` (id `id`) in the deadlock rule: within `blocking` and in its way, hovering as long as a
/// stall that calls for the rule, and first by id (both regions apply the rule to the pair, each
/// to its own UAV, and ids are unique: exactly one of two stalled UAVs steps aside). What the
/// foreign UAV heads for is unknown: it is taken to head for the UAV (which steps to its right).
pub(crate) fn stalled_ahead(
    f: &ForeignView,
    id: &str,
    (me, my_target, my_id): (Vec2, Vec2, &str),
    blocking: f64,
) -> bool {
    let near = (f.p - me).norm() <= blocking;
    let in_my_way = (my_target - me).dot(&(f.p - me)) > 0.0;
    near && in_my_way && f.hovering_s >= crate::traffic::DEADLOCK_AFTER_S && id < my_id
}

/// The foreign UAVs near each own UAV: its foreign neighbour list and every foreign UAV's view.
#[derive(Debug, Clone, Copy, Default)]
pub struct ForeignNear<'a> {
    /// `lists[k]`: indices into `views` of the foreign UAVs near own UAV k (None: none anywhere).
    lists: Option<&'a Ragged<usize>>,
    /// Every foreign UAV's view, by its index in the fleet's foreign list.
    views: &'a [ForeignView],
    /// The foreign UAVs themselves, by the same index (their ids).
    uavs: &'a [ForeignUav],
}

impl<'a> ForeignNear<'a> {
    /// The foreign neighbours in `lists` (by own UAV) with their `views` and the `uavs` they show.
    pub fn new(lists: &'a Ragged<usize>, views: &'a [ForeignView], uavs: &'a [ForeignUav]) -> Self {
        Self { lists: Some(lists), views, uavs }
    }

    /// No foreign UAVs.
    pub fn none() -> Self {
        Self::default()
    }

    /// The foreign UAVs near own UAV `k`.
    pub fn of(&self, k: usize) -> impl Iterator<Item = &'a ForeignView> + 'a {
        self.with_ids(k).map(|(view, _)| view)
    }

    /// The foreign UAVs near own UAV `k`, each with its id.
    pub fn with_ids(&self, k: usize) -> impl Iterator<Item = (&'a ForeignView, &'a str)> + 'a {
        let (views, uavs) = (self.views, self.uavs);
        let list: &'a [usize] = match self.lists {
            Some(lists) if k < lists.len() => &lists[k],
            _ => &[],
        };
        list.iter().filter_map(move |&f| Some((views.get(f)?, uavs.get(f)?.id.as_str())))
    }

    /// Every foreign UAV's view.
    pub fn all(&self) -> &'a [ForeignView] {
        self.views
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use roads::RoadLayout;
    use safety::flown_reach_disk;
    use uav::UavState;

    /// One update: its time and the UAVs it lists (id, position, velocity).
    type Update<'a> = (f64, Vec<(&'a str, Vec2, Vec2)>);

    /// The views after updates at the given times, each listing the given UAVs (id, position,
    /// velocity; fresh states) on a straight road along x from 0 to 40.
    fn views_after(updates: &[Update]) -> Vec<ForeignView> {
        let road = Road::new(RoadLayout::straight(0.0, 40.0, 6.0, 4)).unwrap(); // a valid layout
        let mut views = ForeignViews::default();
        for (now, uavs) in updates {
            let foreign: Vec<ForeignUav> = uavs
                .iter()
                .map(|&(id, p, v)| ForeignUav { id: id.into(), state: UavState { p, v }, age_s: 0.1 })
                .collect();
            let disks: Vec<ReachDisk> =
                foreign.iter().map(|f| flown_reach_disk(f.state, f.age_s, 5.0, 2.0)).collect();
            views.update(&road, &foreign, &disks, *now);
        }
        views.views
    }

    #[test]
    fn a_foreign_uav_flying_along_heads_for_the_road_end_it_flies_towards() {
        let east = views_after(&[(0.0, vec![("f", Vec2::new(12.0, -1.0), Vec2::new(1.0, 0.1))])])[0];
        let route = east.flying_along().expect("it flies along the road");
        assert!((route.s - 12.1).abs() < 1e-9, "moved on by its velocity for the age: {route:?}");
        assert!((route.lateral + 0.99).abs() < 1e-9, "{route:?}");
        assert_eq!((route.direction(), route.goal_s), (1.0, 40.0));
        let west = views_after(&[(0.0, vec![("f", Vec2::new(12.0, -1.0), Vec2::new(-1.0, 0.0))])])[0];
        let west = west.flying_along().expect("it flies along the road");
        assert_eq!((west.direction(), west.goal_s), (-1.0, 0.0));
        // Mostly across the road: nothing to follow or meet, its direction only a first guess.
        let across = views_after(&[(0.0, vec![("f", Vec2::new(12.0, -1.0), Vec2::new(0.3, 0.8))])])[0];
        assert_eq!(across.flying_along(), None);
        assert_eq!(across.route.map(|r| r.direction()), Some(1.0));
        assert!(!east.parked && across.moving());
    }

    #[test]
    fn the_direction_is_kept_while_it_hovers_and_forgotten_with_its_id() {
        let (p, east, still) = (Vec2::new(12.0, -1.0), Vec2::new(1.0, 0.0), Vec2::zeros());
        let hovering = views_after(&[(0.0, vec![("f", p, east)]), (1.0, vec![("f", p, still)])])[0];
        assert_eq!(hovering.route.map(|r| r.direction()), Some(1.0), "{hovering:?}");
        assert_eq!(hovering.flying_along(), None, "hovering: nobody follows it");
        let forgotten = views_after(&[
            (0.0, vec![("f", p, east)]),
            (1.0, vec![("g", p, still)]),
            (2.0, vec![("f", p, still)]),
        ]);
        assert_eq!(forgotten[0].route, None);
    }

    #[test]
    fn of_two_stalled_uavs_of_two_regions_exactly_one_gives_way() {
        let hovering = |p: Vec2, hovering_s: f64| ForeignView {
            p,
            v: Vec2::zeros(),
            segment: 0,
            s: p.x,
            along: 0.0,
            route: None,
            hovering_s,
            parked: hovering_s >= PARKED_AFTER_S,
        };
        let (a, b, east) = (Vec2::new(10.0, 0.0), Vec2::new(10.6, 0.0), Vec2::new(1.0, 0.0));
        let stall = crate::traffic::DEADLOCK_AFTER_S;
        // Each region sees its own UAV stalled and the other's hovering in its way.
        let a_gives_way = stalled_ahead(&hovering(b, stall), "b", (a, a + east, "a"), 0.9);
        let b_gives_way = stalled_ahead(&hovering(a, stall), "a", (b, b - east, "b"), 0.9);
        assert!(!a_gives_way && b_gives_way, "the larger id steps aside");
        // Not for one hovering behind it, too far, or not yet as long as a deadlock stall.
        assert!(!stalled_ahead(&hovering(a, stall), "a", (b, b + east, "b"), 0.9));
        assert!(!stalled_ahead(&hovering(a, stall), "a", (b, b - east, "b"), 0.5));
        assert!(!stalled_ahead(&hovering(a, stall - 0.1), "a", (b, b - east, "b"), 0.9));
    }

    #[test]
    fn a_foreign_uav_is_parked_only_after_hovering_a_while() {
        let (p, still) = (Vec2::new(12.0, -1.0), Vec2::zeros());
        let hover = |times: &[f64]| {
            let updates: Vec<Update> = times.iter().map(|&t| (t, vec![("f", p, still)])).collect();
            views_after(&updates)[0]
        };
        assert!(!hover(&[1.0, 1.0 + PARKED_AFTER_S - 0.05]).parked);
        assert!(hover(&[1.0, 2.0, 1.0 + PARKED_AFTER_S]).parked);
        // A move in between starts the hover again.
        let moved = views_after(&[
            (0.0, vec![("f", p, still)]),
            (1.0, vec![("f", p, Vec2::new(0.5, 0.0))]),
            (PARKED_AFTER_S + 0.5, vec![("f", p, still)]),
        ])[0];
        assert!(!moved.parked && moved.hovering_s == 0.0, "{moved:?}");
    }
}
