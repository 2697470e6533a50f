//! The per-tick machinery of the fleet, apart from its state (the way rapier keeps its sets apart
//! from `PhysicsPipeline`): the [`Fleet`] holds the road, the UAVs, the policies, the traffic rules'
//! reservations and whether it is paused; the [`TickPipeline`] holds what one tick computes and
//! reuses from tick to tick (positions, the neighbour grid, the rows, the filter's order and
//! solvers, the policy batches) and runs the tick as one method per stage (ARCHITECTURE.md, "One
//! tick"): read → neighbours → navigation → policies → rows → filter → send.

use crate::condition::Condition;
use crate::member::Uav;
use crate::tick::TickState;
use crate::tick::filtering::FilterStage;
use crate::tick::lost::disk_of;
use crate::tick::neighbours::NeighbourSearch;
use crate::tick::rows::{NeighbourLists, RowBuilder};
use crate::tick::{StageTimes, map_into, map_mut_into, parallel};
use crate::traffic::cycles::back_off_target;
use crate::traffic::foreign::{ForeignNear, ForeignViews};
use crate::traffic::passing::{FOREIGN_PASS, pass_point, pass_point_with};
use crate::traffic::yielding::{Flying, YIELD_RADIUS_IN_DC, make_way};
use links::LinkPhase;
use policies::Observation;
use rayon::prelude::*;
use roads::network::Network;
use roads::{Airspace, NavMode, Navigator, NetworkNavigator, Road};
use safety::barrier::Clearance;
use safety::{ReachDisk, activation_radius};
use std::time::Instant;
use uav::Vec2;

/// What a tick computes and keeps for the next one; every buffer is reused.
#[derive(Debug, Default)]
pub(crate) struct TickPipeline {
    /// Each UAV's position and velocity as read this tick (plain copies shared by threads).
    positions: Vec<Vec2>,
    velocities: Vec<Vec2>,
    /// The neighbour grid and each UAV's neighbour list of the last tick.
    pub neighbours: NeighbourSearch,
    /// Where each foreign UAV may be this tick ([`crate::member::ForeignUav::disk`]).
    foreign_disks: Vec<ReachDisk>,
    /// What the traffic rules know of each foreign UAV this tick (on a road with `traffic`
    /// navigation; empty otherwise).
    foreign_views: ForeignViews,
    /// Each UAV's tracked segment this tick.
    segments: Vec<usize>,
    /// Every UAV's rows this tick.
    pub rows: RowBuilder,
    /// The filter's order, workers and solvers.
    filter: FilterStage,
    /// Per UAV this tick: arrived, and its way-making point lacks a path's clearance (it cannot
    /// step aside, so those behind it pass it).
    cannot_step_aside: Vec<bool>,
    /// Per UAV this tick: its target while it flies to its goal (None once arrived or without one),
    /// a plain copy the way-making UAVs read from any thread.
    flying_targets: Vec<Option<Vec2>>,
    /// The registry's policy names, in its order (refreshed when they change).
    policy_names: Vec<String>,
    /// The generation of `policy_names` (`UavPolicy::place_in`): a new one each time they change.
    names_generation: u64,
    /// Each UAV's policy this tick, by its place among the registry's names (None: runs none).
    slots: Vec<Option<usize>>,
    /// One policy's batch: observations, UAV indices, actions.
    observations: Vec<Observation>,
    batch: Vec<usize>,
    actions: Vec<Vec2>,
    /// Per UAV this tick: what its policy gave (None: it ran none; Some(None): no finite action).
    nominal: Vec<Option<Option<Vec2>>>,
    /// How long each stage of the last tick took.
    pub stages: StageTimes,
    /// UAVs arrived at their goals after the last tick.
    pub arrived: usize,
}

impl TickPipeline {
    /// Runs one tick of `fleet`, stage after stage.
    pub fn run(&mut self, fleet: &mut TickState<'_>) {
        let mut clock = Instant::now();
        let mut lap = || {
            let now = Instant::now();
            let us = now.duration_since(clock).as_secs_f64() * 1e6;
            clock = now;
            us
        };
        self.read_states(fleet);
        self.stages.read_us = lap();
        self.find_neighbours(fleet);
        self.stages.neighbours_us = lap();
        match fleet.road {
            Airspace::Road(road) => {
                self.view_foreign(road, fleet);
                self.plan_targets(road, fleet);
                self.make_way(fleet);
                if fleet.config.nav == NavMode::Traffic {
                    self.pass_parked(road, fleet);
                }
            }
            Airspace::Network(net) => {
                self.foreign_views.clear();
                self.plan_ways(net, fleet);
                self.make_way(fleet);
            }
        }
        self.stages.navigation_us = lap();
        self.run_policies(fleet);
        self.stages.policies_us = lap();
        let (params, rule) = (fleet.config.params, fleet.config.road_rule);
        let neighbours = NeighbourLists {
            own: &self.neighbours.lists,
            foreign: &self.neighbours.foreign,
            foreign_disks: &self.foreign_disks,
        };
        let config = fleet.config;
        self.rows.collision_per_uav = config.uav_collision_margins;
        self.rows.build(fleet.road, rule, &params, fleet.uavs, neighbours, |u| disk_of(u, config));
        self.stages.rows_us = lap();
        self.filter.run(fleet, &self.rows);
        self.stages.filter_us = lap();
        self.send(fleet);
        self.stages.send_us = lap();
    }

    /// Finds every UAV's neighbours, own and foreign, within the activation radius at twice the top
    /// speed of either (and at least the yielding radius), widened by the farthest reach of a stale
    /// or foreign UAV's disk. Foreign UAVs go into the same grid after the own ones.
    fn find_neighbours(&mut self, fleet: &TickState<'_>) {
        let params = fleet.config.params;
        self.foreign_disks.clear();
        self.foreign_disks.extend(fleet.foreign.iter().map(|f| f.disk(fleet.config)));
        let foreign_reach = fleet
            .foreign
            .iter()
            .zip(&self.foreign_disks)
            .map(|(f, disk)| (disk.centre - f.state.p).norm() + disk.radius)
            .fold(0.0, f64::max);
        // The plain copies of the own UAVs' states (`read_states`), then the foreign UAVs'.
        self.positions.truncate(fleet.uavs.len());
        self.velocities.truncate(fleet.uavs.len());
        self.positions.extend(fleet.foreign.iter().map(|f| f.state.p));
        self.velocities.extend(fleet.foreign.iter().map(|f| f.state.v));
        let v_max = self.velocities.iter().map(|v| v.norm()).fold(0.0, f64::max);
        let pair = Clearance::pair(params.d_c, &params);
        let reach = activation_radius(pair.boundary(), 2.0 * v_max + pair.eta_v, 2.0 * params.delta)
            .max(YIELD_RADIUS_IN_DC * params.kept_d_c())
            + fleet.max_stale_reach().max(foreign_reach);
        self.neighbours.update_with_foreign(&self.positions, fleet.uavs.len(), reach);
    }

    /// What the traffic rules know of each foreign UAV ([`crate::traffic::foreign`]), with `traffic`
    /// navigation: one segment lookup each.
    fn view_foreign(&mut self, road: &Road, fleet: &TickState<'_>) {
        if fleet.config.nav != NavMode::Traffic {
            self.foreign_views.clear();
            return;
        }
        let now = fleet.tick as f64 * fleet.config.params.dt;
        self.foreign_views.update(road, fleet.foreign, &self.foreign_disks, now);
    }

    /// Locates every UAV on its route, tracks its progress, applies the traffic rules (`traffic`
    /// navigation) and chooses its temporary target.
    fn plan_targets(&mut self, road: &Road, fleet: &mut TickState<'_>) {
        let params = fleet.config.params;
        let now = fleet.tick as f64 * params.dt;
        let nav = Navigator::new(road, fleet.config.nav, &params);
        let mut segments = std::mem::take(&mut self.segments);
        let paused = fleet.paused;
        // Per UAV and independent of the others: in parallel, with the same result on any number of
        // threads (each UAV's computation is the same; only where it runs differs).
        let locate = |uav: &mut Uav| {
            let segment = nav.locate(&mut uav.nav, uav.state.p);
            let tracked = !paused && uav.condition.flying() && !uav.nav.arrived;
            uav.traffic.route = uav.nav.position.filter(|_| tracked);
            uav.traffic.waiting = None;
            uav.traffic.progress.update(uav.traffic.route.map(|pos| pos.remaining()), now);
            segment
        };
        map_mut_into(fleet.uavs, locate, &mut segments);
        if fleet.config.nav == NavMode::Traffic {
            let foreign =
                ForeignNear::new(&self.neighbours.foreign, &self.foreign_views.views, fleet.foreign);
            fleet.traffic.plan(&nav, now, fleet.uavs, &self.neighbours.lists, foreign);
        }
        let choose = |(uav, &segment): (&mut Uav, &usize)| {
            let restriction = uav.traffic.restriction;
            uav.last.target = nav.choose(&mut uav.nav, uav.state.p, uav.state.v, segment, &restriction);
            uav.last.stall_s = uav.traffic.progress.stalled_for(now).unwrap_or(0.0);
        };
        if parallel(fleet.uavs.len()) {
            fleet.uavs.par_iter_mut().zip(&segments).for_each(choose);
        } else {
            fleet.uavs.iter_mut().zip(&segments).for_each(choose);
        }
        self.segments = segments;
    }

    /// On a network: follows (or plans) every UAV's way through the cells, tracks its progress,
    /// applies the junction rules (`traffic` navigation, [`crate::traffic::junctions`]) and chooses
    /// its temporary target ([`NetworkNavigator`]).
    fn plan_ways(&mut self, net: &Network, fleet: &mut TickState<'_>) {
        let params = fleet.config.params;
        let now = fleet.tick as f64 * params.dt;
        let nav = NetworkNavigator::new(net, &params);
        let paused = fleet.paused;
        let tracked = |uav: &Uav| !paused && uav.condition.flying() && !uav.nav.arrived;
        // Per UAV and independent of the others (as `plan_targets`).
        let follow = |uav: &mut Uav| {
            nav.follow(&mut uav.nav, uav.state.p);
            uav.traffic.route = None;
            uav.traffic.waiting = None;
            let remaining = nav.remaining(&uav.nav, uav.state.p).filter(|_| tracked(uav));
            uav.traffic.progress.update(remaining, now);
            uav.last.stall_s = uav.traffic.progress.stalled_for(now).unwrap_or(0.0);
        };
        for_each_uav(fleet.uavs, |_, uav| follow(uav));
        if fleet.config.nav == NavMode::Traffic {
            // Congestion-aware route choice (`crate::traffic::congestion`) before the junctions are
            // asked for the movements of the ways chosen, and what they did observed after.
            let reroute = fleet.config.reroute_margin_s;
            if let Some(margin) = reroute {
                fleet.traffic.congestion.choose(&nav, margin, (now, params.dt), fleet.uavs, tracked);
            }
            let rules = &mut fleet.traffic.junctions;
            rules.plan(net, (nav.gates, &params), now, (fleet.uavs, fleet.foreign), tracked);
            if reroute.is_some() {
                fleet.traffic.congestion.observe(net, params.dt, fleet.uavs);
            }
            let waits = (&self.neighbours.lists, rules.waits_for());
            fleet.traffic.cycles.resolve(net, &params, now, fleet.uavs, waits, tracked);
        } else {
            fleet.uavs.iter_mut().for_each(|u| u.traffic.hold = None);
        }
        for_each_uav(fleet.uavs, |_, uav| {
            uav.last.target = nav.choose(&mut uav.nav, uav.state.p, uav.traffic.hold);
            if let Some(aside) = back_off_target(uav) {
                uav.last.target = aside;
            }
        });
    }

    /// Arrived UAVs standing in a flying neighbour's way step aside ([`crate::traffic::yielding`]);
    /// a moving foreign UAV's way is its velocity. Per arrived UAV, reading its flying neighbours'
    /// targets from a plain copy (only arrived UAVs' targets change here): in parallel for large
    /// fleets, the same on any number of threads.
    fn make_way(&mut self, fleet: &mut TickState<'_>) {
        let d_c = fleet.config.params.kept_d_c();
        let foreign = ForeignNear::new(&self.neighbours.foreign, &self.foreign_views.views, fleet.foreign);
        let flying_target = |u: &Uav| (u.nav.goal().is_some() && !u.nav.arrived).then_some(u.last.target);
        map_into(fleet.uavs, flying_target, &mut self.flying_targets);
        let (positions, targets, lists) = (&self.positions, &self.flying_targets, &self.neighbours.lists);
        for_each_uav(fleet.uavs, |k, me| {
            let Some(goal) = me.nav.goal().filter(|_| me.nav.arrived) else { return };
            let flying =
                lists[k].iter().filter_map(|&d| targets[d].map(|target| Flying { p: positions[d], target }));
            let foreign_flying =
                foreign.of(k).filter(|f| f.moving()).map(|f| Flying { p: f.p, target: f.p + f.v });
            me.last.target = make_way(me.state.p, goal, flying.chain(foreign_flying), d_c);
        });
    }

    /// UAVs flying to their goal aim beside an arrived UAV that blocks their way, or a parked foreign
    /// one ([`crate::traffic::passing`]). Per UAV (each changes only its own target, reading its
    /// neighbours' positions from the plain copies): in parallel for large fleets.
    fn pass_parked(&mut self, road: &Road, fleet: &mut TickState<'_>) {
        let params = fleet.config.params;
        let nav = Navigator::new(road, fleet.config.nav, &params);
        let need = nav.clearance_at(0.0);
        let foreign = ForeignNear::new(&self.neighbours.foreign, &self.foreign_views.views, fleet.foreign);
        // One wall query per arrived UAV, not one per flying neighbour of it.
        let cannot_step_aside = |(u, &segment): (&mut Uav, &usize)| {
            u.nav.arrived
                && u.nav.goal().is_some()
                && road.boundary_distance_in(segment, &u.last.target) < need
        };
        let stuck = &mut self.cannot_step_aside;
        if parallel(fleet.uavs.len()) {
            fleet.uavs.par_iter_mut().zip(&self.segments).map(cannot_step_aside).collect_into_vec(stuck);
        } else {
            stuck.clear();
            stuck.extend(fleet.uavs.iter_mut().zip(&self.segments).map(cannot_step_aside));
        }
        let (stuck, segments) = (&self.cannot_step_aside, &self.segments);
        let (positions, lists) = (&self.positions, &self.neighbours.lists);
        for_each_uav(fleet.uavs, |k, me| {
            if me.traffic.route.is_none() || me.traffic.waiting.is_some() || me.traffic.back_off.is_some() {
                return;
            }
            let segment = segments[k];
            let clear = |a: Vec2, b: Vec2| {
                let (seg_a, seg_b) = (road.locate(&a, Some(segment)), road.locate(&b, Some(segment)));
                road.boundary_distance_in(seg_b, &b) >= need && road.path_clear(&a, seg_a, &b, seg_b, need)
            };
            let parked = lists[k].iter().filter(|&&d| stuck[d]).map(|&d| positions[d]);
            let (d_c, foreign_parked) = (params.kept_d_c(), foreign.of(k).filter(|f| f.parked).map(|f| f.p));
            let c = pass_point(me.state.p, me.last.target, parked, d_c, clear).or_else(|| {
                pass_point_with(me.state.p, me.last.target, foreign_parked, d_c, FOREIGN_PASS, clear)
            });
            if let Some(c) = c {
                me.last.target = c;
            }
        });
    }

    /// Reads every link's phase and state, settles each UAV's condition, and copies each UAV's
    /// position and velocity into the plain arrays the other stages read. Per UAV (each reads its
    /// own link and writes its own record): in parallel for large fleets, in one pass.
    fn read_states(&mut self, fleet: &mut TickState<'_>) {
        let (dt, stale_after) = (fleet.config.params.dt, fleet.config.stale_after);
        let read = |uav: &mut Uav| {
            uav.phase = uav.link.phase();
            match uav.link.state() {
                Some(s) if s.is_finite() => {
                    uav.state = s;
                    uav.stale_ticks = 0;
                }
                _ => uav.stale_ticks = uav.stale_ticks.saturating_add(1),
            }
            let silent = f64::from(uav.stale_ticks) * dt >= stale_after;
            uav.condition = Condition::of(uav.phase, uav.was_airborne, uav.stale_ticks, silent);
            if uav.phase.airborne() && !silent {
                uav.was_airborne = true;
            } else if matches!(uav.phase, LinkPhase::Landed | LinkPhase::Stopped) {
                uav.was_airborne = false;
            }
            (uav.state.p, uav.state.v)
        };
        let (positions, velocities) = (&mut self.positions, &mut self.velocities);
        if parallel(fleet.uavs.len()) {
            fleet.uavs.par_iter_mut().map(read).unzip_into_vecs(positions, velocities);
        } else {
            positions.clear();
            velocities.clear();
            for (p, v) in fleet.uavs.iter_mut().map(read) {
                positions.push(p);
                velocities.push(v);
            }
        }
    }

    /// Hands each UAV's filtered input to its link (each link is its own: a real one passes its
    /// setpoint to its own radio task) and counts the arrived UAVs, in one pass: in parallel for
    /// large fleets.
    fn send(&mut self, fleet: &mut TickState<'_>) {
        let send = |uav: &mut Uav| {
            uav.link.send(uav.last.u);
            uav.nav.arrived
        };
        self.arrived = if parallel(fleet.uavs.len()) {
            fleet.uavs.par_iter_mut().map(send).filter(|&arrived| arrived).count()
        } else {
            fleet.uavs.iter_mut().map(send).filter(|&arrived| arrived).count()
        };
    }
}

#[path = "policy_stage.rs"]
mod policy_stage;

/// Calls `f` with each UAV and its index: in parallel for large fleets ([`parallel`]), with the same
/// result on any number of threads (each call reads only its own UAV and shared plain data).
fn for_each_uav(uavs: &mut [Uav], f: impl Fn(usize, &mut Uav) + Sync + Send) {
    if parallel(uavs.len()) {
        uavs.par_iter_mut().enumerate().for_each(|(k, uav)| f(k, uav));
    } else {
        uavs.iter_mut().enumerate().for_each(|(k, uav)| f(k, uav));
    }
}
