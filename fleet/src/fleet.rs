//! One tick of the fleet loop (ARCHITECTURE.md, "One tick"): states → targets → neighbours →
//! policies (batched) → CBF-QP filter → commands.

use crate::condition::Condition;
use crate::filtering::FilterStage;
use crate::neighbours::NeighbourSearch;
use crate::rows::RowBuilder;
use crate::speed::{govern, keep_distance};
use crate::traffic::{TrafficRules, UavTraffic};
use crate::yielding::{Flying, YIELD_RADIUS_IN_DC, make_way};
use links::{Link, LinkPhase};
use policies::{Observation, PolicyRegistry, observation};
use rayon::prelude::*;
use roads::{NavMode, NavState, Navigator, Road};
use safety::{FilterSettings, RoadRule, activation_radius};
use std::time::Instant;
use uav::{Params, UavState, Vec2, braking_input};

/// Fleets at least this large run the per-UAV stages on all worker threads; smaller ones stay on the
/// calling thread (handing a few UAVs to other threads costs more than it saves, and waking them
/// on a busy machine can take milliseconds). Either way the results are the same.
pub const PARALLEL_FROM_UAVS: usize = 256;

/// True when a stage over `n` UAVs runs in parallel ([`PARALLEL_FROM_UAVS`]).
pub(crate) fn parallel(n: usize) -> bool {
    n >= PARALLEL_FROM_UAVS
}
/// How the collision barrier b_kd of a pair is shared between its two UAVs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum CollisionShare {
    /// Each UAV k enforces its share δ_k/(δ_k+δ_d) of every pair row (paper eq. 14, 15;
    /// docs/safety.md §2).
    Split,
    /// UAVs are filtered one after another within a tick. A UAV enforces the whole relative row
    /// `−p̂ᵀ(u_k − u_d) ≤ rhs` against every neighbour d already filtered (its u_d is known) and its
    /// share against the others. Each pair is then enforced exactly by its later UAV, whose row is at
    /// least as loose as its share because the earlier one met its own share; so every QP is at least
    /// as feasible as with `Split`, and a platoon can brake together (with `Split` every member may
    /// only decelerate by about ζb³/2 towards its follower: docs/safety.md §10.3).
    #[default]
    Sequential,
}

impl CollisionShare {
    /// The CLI/JSON name.
    pub fn name(&self) -> &'static str {
        match self {
            CollisionShare::Split => "split",
            CollisionShare::Sequential => "sequential",
        }
    }
}

impl std::str::FromStr for CollisionShare {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "split" => Ok(CollisionShare::Split),
            "sequential" => Ok(CollisionShare::Sequential),
            other => Err(format!("unknown collision share `{other}` (expected split or sequential)")),
        }
    }
}

/// How the fleet navigates and filters.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FleetConfig {
    /// Parameters (dt, δ, r_s, D_s, D_c, ζ, ε).
    pub params: Params,
    /// Which walls each UAV enforces.
    pub road_rule: RoadRule,
    /// How temporary targets are chosen.
    pub nav: NavMode,
    /// QP weights and objective.
    pub filter: FilterSettings,
    /// How pair rows are shared.
    pub share: CollisionShare,
    /// A UAV whose link gives no fresh state for this long (s) is lost ([`crate::lost`]).
    pub stale_after: f64,
    /// How long (s) a lost UAV may keep moving: the Crazyflie's setpoint watchdog cuts its motors
    /// 2 s after the last setpoint, so its reach stops growing after that.
    pub lost_reach_horizon: f64,
}

impl Default for FleetConfig {
    fn default() -> Self {
        Self {
            params: Params::default(),
            road_rule: RoadRule::default(),
            nav: NavMode::default(),
            filter: FilterSettings::default(),
            share: CollisionShare::default(),
            stale_after: 0.3,
            lost_reach_horizon: 2.0,
        }
    }
}

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

/// Wall time (µs) of each stage of the last tick (ARCHITECTURE.md, "One tick").
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct StageTimes {
    /// Reading every link's state.
    pub read_us: f64,
    /// The neighbour search.
    pub neighbours_us: f64,
    /// Navigation and traffic rules: locating each UAV on its route, progress, reservations,
    /// deadlock resolution, targets, arrived UAVs making way.
    pub navigation_us: f64,
    /// The policies (batched).
    pub policies_us: f64,
    /// Building every UAV's rows (road, neighbours, lost UAVs' disks).
    pub rows_us: f64,
    /// The CBF-QP filter of every UAV (without building its rows).
    pub filter_us: f64,
    /// Sending every command.
    pub send_us: f64,
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
    was_airborne: bool,
}

/// The fleet: road, UAVs, policies and the reusable filter and scratch buffers.
pub struct Fleet {
    /// Configuration.
    pub config: FleetConfig,
    pub(crate) road: Road,
    pub(crate) uavs: Vec<Uav>,
    pub(crate) policies: PolicyRegistry,
    /// Hold: every UAV brakes to a hover instead of flying its policy (the filter still runs).
    pub(crate) hold: bool,
    filter_stage: FilterStage,
    pub(crate) neighbours: NeighbourSearch,
    traffic: TrafficRules,
    positions: Vec<Vec2>,
    velocities: Vec<Vec2>,
    segments: Vec<usize>,
    pub(crate) row_builder: RowBuilder,
    observations: Vec<Observation>,
    batch: Vec<usize>,
    actions: Vec<Vec2>,
    tick: u64,
    stages: StageTimes,
}

impl Fleet {
    /// An empty fleet on `road`.
    pub fn new(config: FleetConfig, road: Road, policies: PolicyRegistry) -> Self {
        Self {
            filter_stage: FilterStage::default(),
            config,
            road,
            uavs: Vec::new(),
            policies,
            hold: false,
            neighbours: NeighbourSearch::default(),
            traffic: TrafficRules::default(),
            positions: Vec::new(),
            velocities: Vec::new(),
            segments: Vec::new(),
            row_builder: RowBuilder::default(),
            observations: Vec::new(),
            batch: Vec::new(),
            actions: Vec::new(),
            tick: 0,
            stages: StageTimes::default(),
        }
    }

    /// The road.
    pub fn road(&self) -> &Road {
        &self.road
    }

    /// The single-file sections of the road and their use as of the last tick (`traffic`
    /// navigation only; none otherwise).
    pub fn section_use(&self) -> impl Iterator<Item = crate::traffic::SectionUse> + '_ {
        let rules = (self.config.nav == NavMode::Traffic).then_some(&self.traffic);
        rules.into_iter().flat_map(|r| r.section_use(&self.uavs))
    }

    /// The UAVs.
    pub fn uavs(&self) -> &[Uav] {
        &self.uavs
    }

    /// Ticks run so far.
    pub fn ticks(&self) -> u64 {
        self.tick
    }

    /// How long each stage of the last tick took.
    pub fn stage_times(&self) -> StageTimes {
        self.stages
    }

    /// Adds a UAV at `state` flying policy `policy` towards `goal` (None: hover where it is).
    pub fn add(
        &mut self,
        id: String,
        policy: String,
        link: Box<dyn Link>,
        state: UavState,
        goal: Option<Vec2>,
    ) {
        let mut nav = NavState::new(state.p);
        nav.set_goal(&self.road, goal, state.p);
        let phase = link.phase();
        self.uavs.push(Uav {
            id,
            policy,
            link,
            nav,
            state,
            last: UavTick::default(),
            phase,
            stale_ticks: 0,
            traffic: UavTraffic::default(),
            condition: Condition::of(phase, phase.airborne(), 0, false),
            was_airborne: phase.airborne(),
        });
    }

    /// Runs one tick and returns the number of UAVs that have arrived.
    pub fn tick(&mut self) -> usize {
        let params = self.config.params;
        let mut clock = Instant::now();
        let mut lap = || {
            let now = Instant::now();
            let us = now.duration_since(clock).as_secs_f64() * 1e6;
            clock = now;
            us
        };
        self.read_states();
        self.stages.read_us = lap();
        self.positions.clear();
        self.positions.extend(self.uavs.iter().map(|u| u.state.p));
        let v_max = self.uavs.iter().map(|u| u.state.v.norm()).fold(0.0, f64::max);
        let reach = activation_radius(params.d_c, 2.0 * v_max, 2.0 * params.delta)
            .max(YIELD_RADIUS_IN_DC * params.d_c)
            + self.max_stale_reach();
        self.neighbours.update(&self.positions, reach);
        self.stages.neighbours_us = lap();
        self.plan_targets();
        self.make_way();
        self.stages.navigation_us = lap();
        self.run_policies();
        self.stages.policies_us = lap();
        let mut builder = std::mem::take(&mut self.row_builder);
        let (rule, lists) = (self.config.road_rule, &self.neighbours.lists);
        builder.build(&self.road, rule, &params, &self.uavs, lists, |d| self.disk_of(d));
        self.row_builder = builder;
        self.stages.rows_us = lap();
        let mut stage = std::mem::take(&mut self.filter_stage);
        stage.run(self, self.config.filter);
        self.filter_stage = stage;
        self.stages.filter_us = lap();
        for uav in &mut self.uavs {
            uav.link.send(uav.last.u);
        }
        self.stages.send_us = lap();
        self.tick += 1;
        self.uavs.iter().filter(|u| u.nav.arrived).count()
    }

    /// Locates every UAV on its route, tracks its progress, applies the traffic rules (`traffic`
    /// navigation) and chooses its temporary target.
    fn plan_targets(&mut self) {
        let params = self.config.params;
        let now = self.tick as f64 * params.dt;
        let nav = Navigator::new(&self.road, self.config.nav, &params);
        let mut segments = std::mem::take(&mut self.segments);
        segments.clear();
        let hold = self.hold;
        // Per UAV and independent of the others: in parallel, with the same result on any number of
        // threads (each UAV's computation is the same; only where it runs differs).
        let locate = |uav: &mut Uav| {
            let segment = nav.locate(&mut uav.nav, uav.state.p);
            let tracked = !hold && uav.condition.flying() && !uav.nav.arrived;
            uav.traffic.route = uav.nav.position.filter(|_| tracked);
            uav.traffic.waiting = None;
            uav.traffic.progress.update(uav.traffic.route.map(|pos| pos.remaining()), now);
            segment
        };
        if parallel(self.uavs.len()) {
            self.uavs.par_iter_mut().map(locate).collect_into_vec(&mut segments);
        } else {
            segments.extend(self.uavs.iter_mut().map(locate));
        }
        if self.config.nav == NavMode::Traffic {
            self.traffic.plan(&nav, now, &mut self.uavs, &self.neighbours.lists);
        }
        let choose = |(uav, &segment): (&mut Uav, &usize)| {
            let restriction = uav.traffic.restriction;
            uav.last.target = nav.choose(&mut uav.nav, uav.state.p, uav.state.v, segment, &restriction);
            uav.last.stall_s = uav.traffic.progress.stalled_for(now).unwrap_or(0.0);
        };
        if parallel(self.uavs.len()) {
            self.uavs.par_iter_mut().zip(&segments).for_each(choose);
        } else {
            self.uavs.iter_mut().zip(&segments).for_each(choose);
        }
        self.segments = segments;
    }

    /// Arrived UAVs standing in a flying neighbour's way step aside ([`crate::yielding`]).
    fn make_way(&mut self) {
        let d_c = self.config.params.d_c;
        for k in 0..self.uavs.len() {
            let me = &self.uavs[k];
            let Some(goal) = me.nav.goal().filter(|_| me.nav.arrived) else { continue };
            let flying = self.neighbours.lists[k].iter().map(|&d| &self.uavs[d]).filter_map(|u| {
                let goal = u.nav.goal().filter(|_| !u.nav.arrived)?;
                Some(Flying { p: u.state.p, goal })
            });
            self.uavs[k].last.target = make_way(me.state.p, goal, flying, d_c);
        }
    }

    fn read_states(&mut self) {
        let (dt, stale_after) = (self.config.params.dt, self.config.stale_after);
        for uav in &mut self.uavs {
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
        }
    }

    /// Evaluates each policy once on the batch of UAVs that use it.
    fn run_policies(&mut self) {
        let (delta, dt) = (self.config.params.delta, self.config.params.dt);
        for uav in &mut self.uavs {
            uav.last.u_ref = braking_input(uav.state.v, delta, dt);
            uav.last.policy_fallback = !self.hold;
        }
        if self.hold {
            return;
        }
        for (name, policy) in self.policies.iter_mut() {
            self.batch.clear();
            self.observations.clear();
            for (k, uav) in
                self.uavs.iter().enumerate().filter(|(_, u)| u.policy == name && u.condition.flying())
            {
                self.batch.push(k);
                self.observations.push(observation(&uav.state, uav.last.target, Vec2::zeros()));
            }
            if self.batch.is_empty() || policy.act(&self.observations, &mut self.actions).is_err() {
                continue;
            }
            for (&k, u) in self.batch.iter().zip(&self.actions) {
                if uav::is_finite(u) {
                    self.uavs[k].last.u_ref = uav::saturate(*u, delta);
                    self.uavs[k].last.policy_fallback = false;
                }
            }
        }
        if self.config.nav == NavMode::Traffic {
            self.limit_speeds();
        }
    }

    /// The traffic rules' speed limit (narrower road, slower flight) and the distance kept to every
    /// neighbour (`fleet::speed`), applied to each flying UAV's nominal input. Per UAV, reading its
    /// neighbours' states from plain copies (a link is not shared across threads): in parallel for
    /// large fleets, with the same result on any number of threads.
    fn limit_speeds(&mut self) {
        let (d_c, delta, dt) = (self.config.params.d_c, self.config.params.delta, self.config.params.dt);
        self.velocities.clear();
        self.velocities.extend(self.uavs.iter().map(|u| u.state.v));
        let (positions, velocities) = (&self.positions, &self.velocities);
        let (traffic, lists) = (&self.traffic, &self.neighbours.lists);
        let limit = |(k, me): (usize, &mut Uav)| {
            let Some(pos) = me.nav.position.filter(|_| !me.nav.arrived && me.condition.flying()) else {
                return;
            };
            let (p, v) = (me.state.p, me.state.v);
            let limit = traffic.speed_limit(pos.s, pos.direction());
            let mut u = govern(v, me.last.u_ref, limit, delta, dt);
            for &d in &lists[k] {
                u = keep_distance(v, u, positions[d] - p, velocities[d], d_c, delta, dt);
            }
            me.last.u_ref = u;
        };
        if parallel(self.uavs.len()) {
            self.uavs.par_iter_mut().enumerate().for_each(limit);
        } else {
            self.uavs.iter_mut().enumerate().for_each(limit);
        }
    }
}
