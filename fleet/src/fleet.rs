//! The fleet's state (road, UAVs, policies, traffic reservations, hold) and its configuration; one
//! [`Fleet::tick`] runs the stages of [`crate::tick::pipeline`] (ARCHITECTURE.md, "One tick"): states →
//! neighbours → targets → policies (batched) → rows → CBF-QP filter → commands.

use crate::condition::Condition;
pub use crate::config::FleetConfig;
use crate::member::{Uav, UavTick, UavTraffic};
use crate::tick::pipeline::TickPipeline;
use crate::tick::{StageTimes, TickState};
use crate::traffic::TrafficRules;
use links::Link;
use policies::PolicyRegistry;
use roads::{Airspace, NavMode, NavState, Road};
use uav::{UavState, Vec2};

/// The fleet: road (or network), UAVs, policies and the reusable filter and scratch buffers.
pub struct Fleet {
    /// Configuration.
    pub config: FleetConfig,
    pub(crate) road: Airspace,
    pub(crate) uavs: Vec<Uav>,
    pub(crate) policies: PolicyRegistry,
    /// Paused: every UAV brakes to a hover instead of flying its policy (the filter still runs).
    pub(crate) paused: bool,
    /// The traffic rules' sections, reservations and speed limits.
    pub(crate) traffic: TrafficRules,
    pub(crate) tick: u64,
    /// UAVs flown by other regions, as last given ([`Fleet::set_foreign`]).
    pub(crate) foreign: Vec<crate::member::ForeignUav>,
    /// The per-tick machinery (its neighbour lists are those of the last tick).
    pub(crate) pipeline: TickPipeline,
}

impl Fleet {
    /// An empty fleet on `road` (a [`Road`] or a network).
    pub fn new(config: FleetConfig, road: impl Into<Airspace>, policies: PolicyRegistry) -> Self {
        Self {
            config,
            road: road.into(),
            uavs: Vec::new(),
            policies,
            paused: false,
            traffic: TrafficRules::default(),
            tick: 0,
            foreign: Vec::new(),
            pipeline: TickPipeline::default(),
        }
    }

    /// What it flies in: a road or a network.
    pub fn airspace(&self) -> &Airspace {
        &self.road
    }

    /// The road, when it flies one (None on a network).
    pub fn road(&self) -> Option<&Road> {
        self.road.road()
    }

    /// The single-file sections of the road and their use as of the last tick (`traffic`
    /// navigation on a road only; none otherwise).
    pub fn section_use(&self) -> impl Iterator<Item = crate::traffic::SectionUse> + '_ {
        let on_road = self.config.nav == NavMode::Traffic && self.road.road().is_some();
        let rules = on_road.then_some(&self.traffic);
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
        nav.set_goal_in(&self.road, goal, state.p);
        let phase = link.phase();
        self.uavs.push(Uav {
            id,
            policy: crate::UavPolicy::new(policy),
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
        let mut state = TickState {
            config: &self.config,
            road: &self.road,
            uavs: &mut self.uavs,
            policies: &mut self.policies,
            paused: self.paused,
            traffic: &mut self.traffic,
            foreign: &self.foreign,
            tick: self.tick,
        };
        self.pipeline.run(&mut state);
        self.tick += 1;
        self.pipeline.arrived
    }
}
