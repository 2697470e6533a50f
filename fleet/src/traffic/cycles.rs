//! Deadlocks on a network (docs/traffic.md, "Deadlocks"): cycles of waits, found and broken.
//!
//! Every UAV stalled for [`DEADLOCK_AFTER_S`] waits for one other UAV: the one a junction or merge
//! refused it for ([`crate::traffic::junctions::JunctionRules::waits_for`]: a holder, the UAV ahead in
//! its line, an earlier request), or else the nearest UAV in its way (ahead on the straight line to its target, less than D_c off
//! it, within [`BLOCKING_IN_DC`]·D_c), which holds it back in body. Each UAV waits for at most one, so the waits
//! form a functional graph, and a deadlock is a cycle of it (two UAVs facing each other, or a ring of
//! UAVs around a block each held up by the next); a queue behind a leader that moves, or waits for a
//! holder that moves, is a chain, not a cycle, and is left alone. In each cycle one UAV whose
//! predecessor waits for it in body (a cycle always has one: a junction's waits point to holders,
//! which wait in body, or to earlier requests of the same zone) steps [`crate::traffic::yielding`]'s
//! D_c off that predecessor's way for [`BACK_OFF_S`], kept [`KEEP_M`] inside the network: the one with
//! the least priority (the shortest stall, then the larger id), as on a road. Cost per tick: O(UAVs
//! + neighbour pairs).

use crate::member::{Uav, WaitReason};
use crate::ragged::Ragged;
use crate::traffic::yielding::{Flying, make_way};
use crate::traffic::{BACK_OFF_S, BLOCKING_IN_DC, DEADLOCK_AFTER_S};
use roads::Boundary;
use roads::network::Network;
use uav::{Params, Vec2};

/// Kept (m) beyond D_s between a UAV's step-aside point and the network's walls.
pub const KEEP_M: f64 = roads::CLEARANCE_MARGIN_M;

/// Whom a stalled UAV waits for, and how.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Wait {
    /// A junction's rule holds it back (it is refused): stepping aside frees nothing.
    Rule(usize),
    /// That UAV is in front of it, in its way.
    Body(usize),
}

impl Wait {
    fn on(self) -> usize {
        match self {
            Wait::Rule(d) | Wait::Body(d) => d,
        }
    }
}

/// The cycle finder's state and scratch, kept between ticks (no allocation once sized).
#[derive(Debug, Default)]
pub struct WaitCycles {
    /// Per UAV this tick: whom it waits for.
    waits: Vec<Option<Wait>>,
    /// Per UAV: 0 not seen, 1 on the walk being followed, 2 done.
    seen: Vec<u8>,
    /// Scratch: the walk being followed.
    walk: Vec<usize>,
    /// Scratch: one cycle's UAVs that their predecessor waits for in body, with that predecessor.
    candidates: Vec<(usize, usize)>,
}

impl WaitCycles {
    /// Finds this tick's cycles of waits among the UAVs that `tracked` says fly to a goal and
    /// breaks each; keeps the back-offs under way. `refused_for` is the junction rules' waits
    /// (per UAV), `neighbours` each UAV's own neighbours. Sets `traffic.back_off` and
    /// `traffic.waiting` of the UAVs backing off; [`back_off_target`] reads them.
    pub fn resolve(
        &mut self,
        net: &Network,
        params: &Params,
        now: f64,
        uavs: &mut [Uav],
        (neighbours, refused_for): (&Ragged<usize>, &[Option<usize>]),
        tracked: impl Fn(&Uav) -> bool,
    ) {
        let (d_c, blocking) = (params.kept_d_c(), BLOCKING_IN_DC * params.kept_d_c());
        self.waits.clear();
        for (k, u) in uavs.iter().enumerate() {
            let backing = u.traffic.back_off.is_some_and(|(_, until)| now < until);
            let stalled = u.traffic.progress.stalled_for(now).is_some_and(|s| s >= DEADLOCK_AFTER_S);
            let wait = match refused_for.get(k).copied().flatten() {
                _ if backing || !stalled || !tracked(u) => None,
                Some(d) => Some(Wait::Rule(d)),
                None => {
                    let others = neighbours[k].iter().map(|&d| (d, uavs[d].state.p));
                    in_way(u, others, blocking, d_c).map(Wait::Body)
                }
            };
            self.waits.push(wait);
        }
        for u in uavs.iter_mut() {
            match u.traffic.back_off {
                Some((_, until)) if now < until && tracked(u) => {
                    u.traffic.waiting = Some(WaitReason::DeadlockBackoff);
                }
                Some(_) => u.traffic.back_off = None,
                None => {}
            }
        }
        self.seen.clear();
        self.seen.resize(uavs.len(), 0);
        for start in 0..uavs.len() {
            self.walk.clear();
            let mut k = start;
            while self.seen[k] == 0 {
                self.seen[k] = 1;
                self.walk.push(k);
                match self.waits[k] {
                    Some(w) => k = w.on(),
                    None => break,
                }
            }
            let cycle = (self.seen[k] == 1).then(|| self.walk.iter().position(|&w| w == k)).flatten();
            if let Some(from) = cycle {
                self.break_cycle(net, params, now, uavs, from);
            }
            self.walk.iter().for_each(|&w| self.seen[w] = 2);
        }
    }

    /// Breaks the cycle `walk[from..]`: the UAV of least priority among those their predecessor
    /// waits for in body that can step off its predecessor's way inside the network backs off (none
    /// when none can: the cycle is tried again next tick, as the UAVs may have moved).
    fn break_cycle(&mut self, net: &Network, params: &Params, now: f64, uavs: &mut [Uav], from: usize) {
        let cycle = &self.walk[from..];
        let (d_c, keep) = (params.kept_d_c(), params.kept_d_s() + KEEP_M);
        let candidates = &mut self.candidates;
        candidates.clear();
        for (i, &pred) in cycle.iter().enumerate() {
            let victim = cycle[(i + 1) % cycle.len()];
            if self.waits[pred] == Some(Wait::Body(victim)) {
                candidates.push((victim, pred));
            }
        }
        // Least priority first: the shortest stall, then the larger id.
        let stall = |u: &Uav| u.traffic.progress.stalled_for(now).unwrap_or(0.0);
        candidates.sort_by(|a, b| {
            let (ua, ub) = (&uavs[a.0], &uavs[b.0]);
            stall(ua).total_cmp(&stall(ub)).then_with(|| ub.id.cmp(&ua.id))
        });
        for &(victim, pred) in candidates.iter() {
            let (me, them) = (uavs[victim].state.p, &uavs[pred]);
            let flying = Flying { p: them.state.p, target: them.last.target };
            let aside = make_way(me, me, std::iter::once(flying), d_c);
            let mirrored = me * 2.0 - aside;
            let inside = |x: &Vec2| net.locate(x).is_some_and(|c| net.signed_distance_in(c, x) >= keep);
            if let Some(target) = [aside, mirrored].into_iter().find(|x| *x != me && inside(x)) {
                let u = &mut uavs[victim];
                u.traffic.back_off = Some((target, now + BACK_OFF_S));
                u.traffic.waiting = Some(WaitReason::DeadlockBackoff);
                return;
            }
        }
    }
}

/// The nearest of `others` (index, position) in `u`'s way: ahead of it towards its last target,
/// within `blocking` (m), and less than `d_c` (m) off the straight line to that target (one beside
/// its way does not hold it back); ties go to the smaller index.
fn in_way(u: &Uav, others: impl Iterator<Item = (usize, Vec2)>, blocking: f64, d_c: f64) -> Option<usize> {
    let p = u.state.p;
    let to_target = u.last.target - p;
    let heading = to_target.try_normalize(1e-9)?;
    others
        .filter(|(_, q)| {
            let x = q - p;
            let (along, off) = (x.dot(&heading), (heading.x * x.y - heading.y * x.x).abs());
            along > 0.0 && off < d_c && x.norm() <= blocking
        })
        .min_by(|a, b| (a.1 - p).norm().total_cmp(&(b.1 - p).norm()).then(a.0.cmp(&b.0)))
        .map(|(d, _)| d)
}

/// The target of a UAV backing off this tick (where it steps aside to), as [`WaitCycles::resolve`]
/// left it.
pub fn back_off_target(u: &Uav) -> Option<Vec2> {
    u.traffic.back_off.filter(|_| u.traffic.waiting == Some(WaitReason::DeadlockBackoff)).map(|(x, _)| x)
}
