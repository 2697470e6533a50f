//! The fleet's state (road, UAVs, policies, traffic reservations, hold) and its configuration; one
//! [`Fleet::tick`] runs the stages of [`crate::pipeline`] (ARCHITECTURE.md, "One tick"): states →
//! neighbours → targets → policies (batched) → rows → CBF-QP filter → commands.

use crate::condition::Condition;
use crate::pipeline::TickPipeline;
use crate::traffic::{TrafficRules, UavTraffic};
use links::{Link, LinkPhase};
use policies::PolicyRegistry;
use roads::{NavMode, NavState, Road};
use safety::{FilterSettings, RoadRule};
use uav::{Params, UavState, Vec2};

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

/// The fleet: road, UAVs, policies and the reusable filter and scratch buffers.
pub struct Fleet {
    /// Configuration.
    pub config: FleetConfig,
    pub(crate) road: Road,
    pub(crate) uavs: Vec<Uav>,
    pub(crate) policies: PolicyRegistry,
    /// Paused: every UAV brakes to a hover instead of flying its policy (the filter still runs).
    pub(crate) paused: bool,
    /// The traffic rules' sections, reservations and speed limits.
    pub(crate) traffic: TrafficRules,
    pub(crate) tick: u64,
    /// UAVs flown by other regions, as last given ([`Fleet::set_foreign`]).
    pub(crate) foreign: Vec<crate::ForeignUav>,
    /// The per-tick machinery (its neighbour lists are those of the last tick).
    pub(crate) pipeline: TickPipeline,
}

impl Fleet {
    /// An empty fleet on `road`.
    pub fn new(config: FleetConfig, road: Road, policies: PolicyRegistry) -> Self {
        Self {
            config,
            road,
            uavs: Vec::new(),
            policies,
            paused: false,
            traffic: TrafficRules::default(),
            tick: 0,
            foreign: Vec::new(),
            pipeline: TickPipeline::default(),
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
        self.pipeline.stages
    }

    /// Adds a UAV at `state` flying policy `policy` towards `goal` (None: hover where it is), and
    /// returns it.
    pub fn add(
        &mut self,
        id: String,
        policy: String,
        link: Box<dyn Link>,
        state: UavState,
        goal: Option<Vec2>,
    ) -> &mut Uav {
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
        let last = self.uavs.len() - 1; // just pushed
        &mut self.uavs[last]
    }

    /// Runs one tick ([`TickPipeline`]) and returns the number of UAVs that have arrived.
    pub fn tick(&mut self) -> usize {
        let mut pipeline = std::mem::take(&mut self.pipeline);
        pipeline.run(self);
        self.pipeline = pipeline;
        self.tick += 1;
        self.uavs.iter().filter(|u| u.nav.arrived).count()
    }
}
