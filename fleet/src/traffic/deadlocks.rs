//! Deadlock resolution ([`crate::traffic`]): a UAV stalled for [`DEADLOCK_AFTER_S`] next to a
//! stalled neighbour with priority (stalled longer, then the smaller id; a foreign UAV that has
//! hovered as long, by id alone: [`crate::traffic::foreign::stalled_ahead`]) backs off for
//! [`BACK_OFF_S`] off that neighbour's way, kept inside the road.

use crate::member::{Uav, WaitReason};
use crate::ragged::Ragged;
use crate::traffic::foreign::{ForeignNear, stalled_ahead};
use crate::traffic::yielding::{Flying, make_way};
use crate::traffic::{BACK_OFF_S, BLOCKING_IN_DC, DEADLOCK_AFTER_S, TrafficRules};
use roads::{Navigator, RoutePosition};
use uav::Vec2;

impl TrafficRules {
    /// Sets the back-off of every UAV stalled next to a stalled neighbour with priority (own, or
    /// foreign from `foreign`), and keeps the back-offs still running.
    pub(crate) fn resolve_deadlocks(
        &mut self,
        nav: &Navigator,
        now: f64,
        uavs: &mut [Uav],
        neighbours: &Ragged<usize>,
        foreign: ForeignNear<'_>,
    ) {
        let blocking = BLOCKING_IN_DC * nav.d_c;
        // Only a UAV with a back-off running or stalled long enough does anything below, and what
        // decides that is its own record, which only its own turn changes: found in parallel for
        // large fleets (one pass over the records on all cores), then visited in index order.
        let may = |u: &Uav| {
            u.traffic.back_off.is_some()
                || (u.traffic.route.is_some()
                    && u.traffic.progress.stalled_for(now).is_some_and(|s| s >= DEADLOCK_AFTER_S))
        };
        crate::tick::map_into(uavs, may, &mut self.may_back_off);
        for k in (0..uavs.len()).filter(|&k| self.may_back_off[k]) {
            if let Some((target, until)) = uavs[k].traffic.back_off {
                if now < until && uavs[k].traffic.route.is_some() {
                    uavs[k].traffic.restriction.back_off = Some(target);
                    uavs[k].traffic.waiting = Some(WaitReason::DeadlockBackoff);
                    continue;
                }
                uavs[k].traffic.back_off = None;
            }
            let (Some(pos), Some(mine)) = (uavs[k].traffic.route, uavs[k].traffic.progress.stalled_for(now))
            else {
                continue;
            };
            if mine < DEADLOCK_AFTER_S {
                continue;
            }
            // The stalled neighbours with priority (the longer stall to a tick, then the smaller id):
            // step off their way, as an arrived UAV does ([`crate::traffic::yielding`]). A UAV held by a rule
            // gives way to every stalled neighbour that is not held and heads towards it (one
            // leaving a single-file section, say), whatever their stalls.
            let (me, my_target) = (uavs[k].state.p, uavs[k].last.target);
            let held = uavs[k].traffic.restriction.hold_at.is_some();
            let winners = neighbours[k].iter().filter_map(|&d| {
                let other = &uavs[d];
                let (p, target) = (other.state.p, other.last.target);
                let theirs = other.traffic.progress.stalled_for(now)?;
                let first = if (theirs - mine).abs() > 1e-6 { theirs > mine } else { other.id < uavs[k].id };
                let near = (p - me).norm() <= blocking;
                // In each other's way: each heads towards the other (a queue behind a leader is not).
                let towards_me = (target - p).dot(&(me - p)) > 0.0;
                let facing = towards_me && (my_target - me).dot(&(p - me)) > 0.0;
                let going = other.traffic.restriction.hold_at.is_none();
                let gives_way = if held { towards_me } else { facing && first };
                (near && going && gives_way && other.traffic.back_off.is_none())
                    .then_some(Flying { p, target })
            });
            let foreign_winners = foreign
                .with_ids(k)
                .filter(|(f, id)| stalled_ahead(f, id, (me, my_target, &uavs[k].id), blocking))
                .map(|(f, _)| Flying { p: f.p, target: me });
            let aside = make_way(me, me, winners.chain(foreign_winners), nav.d_c);
            if aside != me {
                let target = inside_lane(nav, &pos, aside);
                uavs[k].traffic.back_off = Some((target, now + BACK_OFF_S));
                uavs[k].traffic.restriction.back_off = Some(target);
                uavs[k].traffic.waiting = Some(WaitReason::DeadlockBackoff);
            }
        }
    }
}

/// `x` moved across the road, if needed, so that it keeps D_s plus a margin from both sides (at the
/// arc length of `pos`).
fn inside_lane(nav: &Navigator, pos: &RoutePosition, x: Vec2) -> Vec2 {
    let line = nav.road.centerline();
    let (right, left) = nav.road.profile().at(pos.s);
    let keep = nav.d_s + roads::CLEARANCE_MARGIN_M;
    let n = line.normal_at(pos.s);
    let base = line.point_at(pos.s);
    let along = x - base;
    let lateral = n.dot(&along);
    let clamped = if right + left < 2.0 * keep {
        (left - right) / 2.0
    } else {
        lateral.clamp(keep - right, left - keep)
    };
    x + n * (clamped - lateral)
}
