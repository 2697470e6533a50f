//! Following in a lane (docs/traffic.md): where traffic is dense or comes the other way, a
//! UAV keeps a follow gap behind the UAV ahead of it in its lane, going the same way, instead of
//! pressing into it. A block of UAVs funnelling into a narrower part merges one behind the other,
//! in the order they are along the road, rather than side by side into a lane that holds one, and
//! two groups meeting head-on stay in their lanes rather than squeeze into each other's (the
//! `headon` and `crowd` families showed both, with the filter out of input and into its slack).
//!
//! Invariant: "ahead" is a strict total order per direction (arc length along the direction of
//! travel, then the smaller index first), so following never forms a cycle: the first UAV of
//! every column follows nobody, and following alone cannot deadlock.
//!
//! Foreign UAVs moving along the road ([`crate::traffic::foreign`]) count as well: one ahead in the
//! lane is followed (only when strictly ahead: the other region's rules follow ours the same way),
//! and one coming the other way is oncoming traffic.

use crate::member::Uav;
use crate::ragged::Ragged;
use crate::traffic::FOLLOW_GAP_IN_DC;
use crate::traffic::along::{Seen, TrafficAlong};
use crate::traffic::foreign::ForeignNear;
#[cfg(test)]
use crate::traffic::foreign::ForeignViews;
use crate::traffic::speed::KEEP_MARGIN_M;
use rayon::prelude::*;
use roads::{Navigator, RoutePosition};

/// Lateral distance (m) beyond D_c under which the UAV ahead counts as in the same lane.
pub const SAME_LANE_MARGIN_M: f64 = 0.15;

/// How far ahead in time (s) the follow point moves with the leader's speed along the road, so a
/// follower keeps pace instead of lagging behind a point that would stop it.
pub const LEAD_TIME_S: f64 = 1.0;

/// Radius (m) within which [`CROWD_NEIGHBOURS`] neighbours make a UAV's surroundings dense.
pub const CROWD_RADIUS_M: f64 = 1.0;

/// Neighbours within [`CROWD_RADIUS_M`] from which a UAV follows without oncoming traffic where
/// the road narrows ahead (elsewhere a one-way stream flies free: following there only slowed it
/// down and jammed the goal areas of the `bends` family).
pub const CROWD_NEIGHBOURS: usize = 3;

/// Share of its width the road ahead must narrow to for a crowd to follow without oncoming
/// traffic.
pub const NARROWING: f64 = 0.8;

/// Sets `traffic.restriction.follow_at` of every UAV on a route that has a UAV ahead of it in its
/// lane (among `neighbours[k]` and the foreign UAVs near it, `foreign`), when the rule applies to
/// it: a follow gap of [`FOLLOW_GAP_IN_DC`]·D_c behind the nearest one, moved on by [`LEAD_TIME_S`]
/// of the leader's speed, but never closer to the leader than D_c plus the margin the UAVs keep.
pub fn follow(
    nav: &Navigator,
    uavs: &mut [Uav],
    neighbours: &Ragged<usize>,
    foreign: ForeignNear<'_>,
    traffic: &mut TrafficAlong,
) {
    let gap = FOLLOW_GAP_IN_DC * nav.d_c;
    let keep = nav.d_c + KEEP_MARGIN_M;
    traffic.update(uavs, foreign.all(), nav.road.centerline().length(), nav.r_s);
    let traffic = &*traffic;
    // Per UAV, reading the others from the plain copies (`TrafficAlong::seen`) and writing only its
    // own restriction: in parallel for large fleets, the same on any number of threads.
    let follow_one = |(k, uav): (usize, &mut Uav)| {
        uav.traffic.restriction.follow_at = None;
        uav.traffic.restriction.keep_lane = false;
        uav.traffic.in_traffic = false;
        let Some(me) = uav.traffic.route else { return };
        let seen = &traffic.seen;
        let Some(oncoming) = applies(nav, seen, k, &me, (&neighbours[k], foreign), traffic) else {
            return;
        };
        uav.traffic.restriction.keep_lane = oncoming;
        uav.traffic.in_traffic = true;
        let direction = me.direction();
        let own = neighbours[k].iter().filter_map(|&d| {
            let other = seen[d].route?;
            let ahead = direction * (other.s - me.s);
            (leads(nav, &me, &other) && (ahead > 0.0 || (ahead == 0.0 && d < k)))
                .then_some((ahead, seen[d].v))
        });
        let foreign_leaders = foreign.of(k).filter_map(|f| {
            let other = f.flying_along()?;
            let ahead = direction * (other.s - me.s);
            (leads(nav, &me, &other) && ahead > 0.0).then_some((ahead, f.v))
        });
        let leader = own.chain(foreign_leaders).min_by(|a, b| a.0.total_cmp(&b.0));
        uav.traffic.restriction.follow_at = leader.map(|(ahead, v)| {
            // The UAV's tracked segment is its piece, or next to it: a walk of a step or two.
            let hint = uav.nav.tracker.current.unwrap_or(0);
            let tangent = nav.road.centerline().tangent_near(me.s, hint) * direction;
            let lead = LEAD_TIME_S * v.dot(&tangent).max(0.0);
            me.s + direction * (ahead - gap + lead).min(ahead - keep)
        });
    };
    if crate::tick::parallel(uavs.len()) {
        uavs.par_iter_mut().enumerate().for_each(follow_one);
    } else {
        uavs.iter_mut().enumerate().for_each(follow_one);
    }
}

/// Whether UAV k (at `me` on its route) follows at all: not within r_s of its goal (where it slows
/// down to park among others), and only with oncoming traffic among its neighbours or within r_s
/// ahead along the road, or with [`CROWD_NEIGHBOURS`] neighbours within [`CROWD_RADIUS_M`] where
/// the road narrows ahead (own `neighbours` and `foreign` ones alike). `Some(true)` when traffic
/// comes the other way (the UAV also keeps to its lane through bends), `None` when it does not
/// follow.
fn applies(
    nav: &Navigator,
    uavs: &[Seen],
    k: usize,
    me: &RoutePosition,
    (neighbours, foreign): (&[usize], ForeignNear<'_>),
    traffic: &TrafficAlong,
) -> Option<bool> {
    if (me.goal_s - me.s).abs() < nav.r_s {
        return None;
    }
    let other_way = |o: Option<RoutePosition>| o.is_some_and(|o| o.direction() != me.direction());
    let oncoming = traffic.oncoming_within(me)
        || neighbours.iter().any(|&d| other_way(uavs[d].route))
        || foreign.of(k).any(|f| other_way(f.flying_along()));
    let p = uavs[k].p;
    let close = || {
        let own = neighbours.iter().filter(|&&d| (uavs[d].p - p).norm() < CROWD_RADIUS_M).count();
        own + foreign.of(k).filter(|f| (f.p - p).norm() < CROWD_RADIUS_M).count()
    };
    (oncoming || (narrows_ahead(nav, me) && close() >= CROWD_NEIGHBOURS)).then_some(oncoming)
}

/// True when the road within r_s ahead of `me` gets narrower than [`NARROWING`] of its width here
/// (a funnel into a narrower part, where a crowd has to merge).
fn narrows_ahead(nav: &Navigator, me: &RoutePosition) -> bool {
    let profile = nav.road.profile();
    let here = profile.min_width(me.s, me.s);
    profile.min_width(me.s, me.s + me.direction() * nav.r_s) < NARROWING * here
}

/// Whether a UAV at `other` can lead one at `me` (ahead or not): going the same way, in the same
/// lane (laterally within D_c + [`SAME_LANE_MARGIN_M`]), in the way to `me`'s goal and not about to
/// stop short of it (its goal beyond `me`'s or more than r_s on; one about to stop short is to be
/// passed, not followed).
fn leads(nav: &Navigator, me: &RoutePosition, other: &RoutePosition) -> bool {
    let direction = me.direction();
    let same_way = other.direction() == direction;
    let same_lane = (other.lateral - me.lateral).abs() < nav.d_c + SAME_LANE_MARGIN_M;
    let in_the_way = direction * (me.goal_s - other.s) > 0.0;
    let goes_on =
        direction * (other.goal_s - me.goal_s) >= 0.0 || direction * (other.goal_s - other.s) > nav.r_s;
    same_way && same_lane && in_the_way && goes_on
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;
    use roads::{NavMode, Road, RoadLayout};
    use uav::{Params, Vec2};

    /// `follow_at` of each UAV (start, goal) at rest on a straight road 4 m wide along x from 0 to 40.
    fn follow_points(uavs: &[(Vec2, Vec2)]) -> Vec<Option<f64>> {
        follow_points_with(uavs, &[])
    }

    /// [`follow_points`] with foreign UAVs (position, velocity; fresh states, moving) near every UAV.
    fn follow_points_with(uavs: &[(Vec2, Vec2)], foreign: &[(Vec2, Vec2)]) -> Vec<Option<f64>> {
        let road = Road::new(RoadLayout::from_centerline(&[[0.0, 0.0], [40.0, 0.0]], &[4.0, 4.0])).unwrap();
        let params = Params::default();
        let config = crate::FleetConfig { params, ..crate::FleetConfig::default() };
        let mut fleet = crate::Fleet::new(config, road, policies::PolicyRegistry::with_pd(params.delta));
        for (k, (p, goal)) in uavs.iter().enumerate() {
            let state = uav::UavState::at_rest(*p);
            let link = Box::new(links::SimLink::new(state, params.dt));
            fleet.add(format!("u{k}"), "pd".into(), link, state, Some(*goal));
        }
        let nav = Navigator::new(
            fleet.road.road().expect("the test fleet flies a road"),
            NavMode::Traffic,
            &params,
        );
        for u in &mut fleet.uavs {
            nav.locate(&mut u.nav, u.state.p);
            u.traffic.route = u.nav.position;
        }
        let n = uavs.len();
        let neighbours: Ragged<usize> = (0..n).map(|k| (0..n).filter(|&d| d != k).collect()).collect();
        let uavs_foreign: Vec<crate::ForeignUav> = foreign
            .iter()
            .map(|&(p, v)| crate::ForeignUav { id: "f".into(), state: uav::UavState { p, v }, age_s: 0.0 })
            .collect();
        let disks: Vec<safety::ReachDisk> =
            uavs_foreign.iter().map(|f| safety::point_disk(f.state.p)).collect();
        let mut views = ForeignViews::default();
        views.update(nav.road, &uavs_foreign, &disks, 0.0);
        let views = views.views;
        let foreign_lists: Ragged<usize> = (0..n).map(|_| (0..views.len()).collect()).collect();
        let near = ForeignNear::new(&foreign_lists, &views, &uavs_foreign);
        follow(&nav, &mut fleet.uavs, &neighbours, near, &mut TrafficAlong::default());
        fleet.uavs.iter().map(|u| u.traffic.restriction.follow_at).collect()
    }

    fn at(x: f64, y: f64) -> Vec2 {
        Vec2::new(x, y)
    }

    #[test]
    fn with_oncoming_traffic_each_follows_the_one_ahead_in_its_lane() {
        let far = at(38.0, -1.0);
        // A column of three going east in the right lane, one beside it in another lane, and one
        // coming the other way.
        let uavs =
            [(at(10.0, -1.0), far), (at(11.0, -1.0), far), (at(12.0, -1.0), far), (at(11.5, 0.2), far)];
        let oncoming = (at(13.0, 1.0), at(2.0, 1.0));
        let points = follow_points(&[uavs[0], uavs[1], uavs[2], uavs[3], oncoming]);
        let keep = 0.3 + KEEP_MARGIN_M;
        let behind = |p: Option<f64>, leader_x: f64| p.is_some_and(|s| s <= leader_x - keep + 1e-9);
        assert!(behind(points[0], 11.0) && points[0].unwrap() > 10.0 - 1e-9, "{points:?}");
        assert!(behind(points[1], 12.0), "{points:?}");
        assert_eq!(points[2], None, "the front of the column follows nobody: {points:?}");
        assert_eq!(points[3], None, "1.2 m to the side is another lane: {points:?}");
    }

    #[test]
    fn a_column_follows_a_foreign_leader_with_foreign_traffic_coming_the_other_way() {
        let far = at(38.0, -1.0);
        let leader = (at(11.0, -1.0), Vec2::new(1.0, 0.0));
        let oncoming = (at(13.0, 1.0), Vec2::new(-1.0, 0.0));
        let points = follow_points_with(&[(at(10.0, -1.0), far), (at(9.0, -1.0), far)], &[leader, oncoming]);
        let keep = 0.3 + KEEP_MARGIN_M;
        assert!(points[0].is_some_and(|s| s <= 11.0 - keep + 1e-9 && s > 10.0 - 1e-9), "{points:?}");
        assert!(points[1].is_some_and(|s| s <= 10.0 - keep + 1e-9), "{points:?}");
        // Hovering, the one ahead is not followed (it is passed once parked); nor one going away.
        let hovering = (leader.0, Vec2::zeros());
        assert_eq!(follow_points_with(&[(at(10.0, -1.0), far)], &[hovering, oncoming]), vec![None]);
        let away = (leader.0, Vec2::new(-1.0, 0.0));
        assert_eq!(follow_points_with(&[(at(10.0, -1.0), far)], &[away]), vec![None]);
    }

    #[test]
    fn a_sparse_one_way_column_flies_free() {
        let far = at(38.0, -1.0);
        let points = follow_points(&[(at(10.0, -1.0), far), (at(11.0, -1.0), far)]);
        assert_eq!(points, vec![None, None]);
    }

    #[test]
    fn a_leader_stopping_short_of_the_goal_or_one_past_it_is_not_followed() {
        let oncoming = (at(13.0, 1.0), at(2.0, 1.0));
        // The one ahead parks 1 m on; the follower's goal is farther: it passes.
        let points =
            follow_points(&[(at(10.0, -1.0), at(38.0, -1.0)), (at(11.0, -1.0), at(12.0, -1.0)), oncoming]);
        assert_eq!(points[0], None, "{points:?}");
        // The one ahead is beyond the follower's own goal: not in its way.
        let points =
            follow_points(&[(at(10.0, -1.0), at(10.8, -1.0)), (at(11.0, -1.0), at(38.0, -1.0)), oncoming]);
        assert_eq!(points[0], None, "{points:?}");
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(500))]

        /// However the UAVs stand, the one farthest along in each direction follows nobody, and
        /// nobody is sent past the UAV it follows: following alone never stops everyone.
        #[test]
        fn the_front_of_each_direction_is_free(
            placed in prop::collection::vec((2.0f64..38.0, -1.5f64..1.5, any::<bool>(), -1.0f64..1.0), 2..14),
        ) {
            let uavs: Vec<(Vec2, Vec2)> = placed
                .iter()
                .map(|&(x, y, east, gy)| (at(x, y), at(if east { 39.0 } else { 1.0 }, gy)))
                .collect();
            let points = follow_points(&uavs);
            for east in [true, false] {
                let along = |x: f64| if east { x } else { -x };
                let front = (0..uavs.len())
                    .filter(|&k| placed[k].2 == east)
                    .max_by(|&a, &b| along(uavs[a].0.x).total_cmp(&along(uavs[b].0.x)).then(b.cmp(&a)));
                if let Some(front) = front {
                    prop_assert_eq!(points[front], None);
                }
            }
            for (k, p) in points.iter().enumerate() {
                if let Some(s) = p {
                    let ahead = uavs.iter().any(|(q, _)| along_dir(placed[k].2, q.x - s) >= 0.3 + KEEP_MARGIN_M - 1e-9);
                    prop_assert!(ahead, "UAV {} follows to {} with nobody that far ahead", k, s);
                }
            }
        }
    }

    fn along_dir(east: bool, dx: f64) -> f64 {
        if east { dx } else { -dx }
    }
}
