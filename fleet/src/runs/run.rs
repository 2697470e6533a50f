//! Headless scenario runs: simulate until every UAV has arrived or t_max, recording metrics and,
//! optionally, a trajectory CSV.

use crate::fleet::{Fleet, FleetConfig};
use crate::runs::metrics::{MetricsRecorder, RunMetrics, Stall};
use crate::runs::paths::{PathRecorder, UavPath};
use crate::scenario::{UavSpec, ValidScenario};
use links::{Link, LinkPhase, SimLink};
use policies::PolicyRegistry;
use std::io::Write;
use uav::UavState;

/// Options of a headless run.
pub struct RunOptions {
    /// Road rule, navigation and filter settings (params come from the scenario).
    pub config: FleetConfig,
    /// Policy name flown by every UAV.
    pub policy: String,
    /// Where to write the trajectory CSV, if anywhere.
    pub trajectory: Option<Box<dyn Write>>,
    /// Record every UAV's path and waits ([`RunOutcome::paths`]).
    pub paths: bool,
}

/// What a headless run produced.
#[derive(Debug, Clone, PartialEq)]
pub struct RunOutcome {
    /// The METRICS.json document.
    pub metrics: RunMetrics,
    /// UAV-ticks where the policy gave no finite action and the UAV braked instead.
    pub policy_fallbacks: u64,
    /// Every stall, longest first.
    pub stalls: Vec<Stall>,
    /// Every UAV's path and waits, in the scenario's order (empty unless [`RunOptions::paths`]).
    pub paths: Vec<UavPath>,
}

/// Header of the trajectory CSV.
pub const TRAJECTORY_HEADER: &str =
    "t,id,x,y,vx,vy,target_x,target_y,u_ref_x,u_ref_y,u_x,u_y,max_slack,arrived";

/// Runs `scenario` in the in-process simulator. The policy must exist in `policies`.
pub fn run_scenario(
    scenario: &ValidScenario,
    options: RunOptions,
    policies: PolicyRegistry,
) -> std::io::Result<RunOutcome> {
    let dt = scenario.params.dt;
    let mut sim = |_: &UavSpec, state: UavState| -> Box<dyn Link> { Box::new(SimLink::new(state, dt)) };
    run_scenario_on(scenario, options, policies, &mut sim, &mut || {})
}

/// How long the UAVs of a run on real links may take to take off (s).
pub const TAKEOFF_TIMEOUT_S: f64 = 30.0;

/// Runs `scenario` with each UAV on the link `make_link` gives it; `wait_tick` is called before
/// every tick (a real-time run sleeps there until the tick is due). On links that take off, the
/// run starts once every UAV is flying (an error after [`TAKEOFF_TIMEOUT_S`]); the metrics count
/// from there, and every UAV is landed at the end.
pub fn run_scenario_on(
    scenario: &ValidScenario,
    options: RunOptions,
    policies: PolicyRegistry,
    make_link: &mut dyn FnMut(&UavSpec, UavState) -> Box<dyn Link>,
    wait_tick: &mut dyn FnMut(),
) -> std::io::Result<RunOutcome> {
    run_with(scenario, options, policies, make_link, wait_tick, None)
}

/// The UAVs' true states in the scenario's order (`None` for one not in the air), read after
/// every tick; `None` for a tick without them.
pub type TruthSource<'a> = &'a mut dyn FnMut() -> Option<Vec<Option<UavState>>>;

/// Columns the trajectory CSV of a run with ground truth adds: each UAV's true state (empty while
/// it is not in the air).
pub const TRUTH_COLUMNS: &str = ",true_x,true_y,true_vx,true_vy";

/// [`run_scenario_on`] with the margins of METRICS.json measured on `truth` (e.g. a physics
/// simulation's ground truth; a tick without it is measured on the states the fleet read), and
/// the trajectory CSV with [`TRUTH_COLUMNS`].
pub fn run_scenario_on_truth(
    scenario: &ValidScenario,
    options: RunOptions,
    policies: PolicyRegistry,
    make_link: &mut dyn FnMut(&UavSpec, UavState) -> Box<dyn Link>,
    wait_tick: &mut dyn FnMut(),
    truth: TruthSource,
) -> std::io::Result<RunOutcome> {
    run_with(scenario, options, policies, make_link, wait_tick, Some(truth))
}

fn run_with(
    scenario: &ValidScenario,
    mut options: RunOptions,
    policies: PolicyRegistry,
    make_link: &mut dyn FnMut(&UavSpec, UavState) -> Box<dyn Link>,
    wait_tick: &mut dyn FnMut(),
    mut truth: Option<TruthSource>,
) -> std::io::Result<RunOutcome> {
    let mut config = options.config;
    config.params = scenario.params;
    let params = config.params;
    let mut fleet = Fleet::new(config, scenario.road.clone(), policies);
    for u in &scenario.uavs {
        let state = UavState::at_rest(u.start);
        fleet.add(u.id.clone(), options.policy.clone(), make_link(u, state), state, Some(u.goal));
    }
    // Take-off: the fleet is paused (every UAV brakes) until all links fly.
    let mut preflight = 0.0;
    fleet.set_paused(true);
    while fleet.uavs().iter().any(|u| u.link.phase() != LinkPhase::Flying) {
        if preflight > TAKEOFF_TIMEOUT_S {
            let waiting: Vec<String> = fleet
                .uavs()
                .iter()
                .filter(|u| u.link.phase() != LinkPhase::Flying)
                .map(|u| match u.link.error() {
                    Some(e) => format!("{} ({}: {e})", u.id, u.link.phase().name()),
                    None => format!("{} ({})", u.id, u.link.phase().name()),
                })
                .collect();
            return Err(std::io::Error::other(format!(
                "not flying after {TAKEOFF_TIMEOUT_S} s: {}",
                waiting.join(", ")
            )));
        }
        wait_tick();
        fleet.tick();
        preflight += params.dt;
    }
    fleet.set_paused(false);
    if let Some(w) = options.trajectory.as_mut() {
        let extra = if truth.is_some() { TRUTH_COLUMNS } else { "" };
        writeln!(w, "{TRAJECTORY_HEADER}{extra}")?;
    }
    let mut recorder = MetricsRecorder::new();
    let mut paths = options.paths.then(|| PathRecorder::new(&fleet));
    let n = scenario.uavs.len();
    for tick in 0..params.max_ticks() {
        let t = tick as f64 * params.dt;
        wait_tick();
        let arrived = fleet.tick();
        let true_states = truth.as_mut().and_then(|truth| truth());
        match &true_states {
            Some(states) => recorder.record_truth(&fleet, t, states),
            None => recorder.record(&fleet, t),
        }
        if let Some(p) = paths.as_mut() {
            p.record(&fleet, t + params.dt);
        }
        if let Some(w) = options.trajectory.as_mut() {
            for (k, u) in fleet.uavs().iter().enumerate() {
                let (s, l) = (&u.state, &u.last);
                write!(
                    w,
                    "{t:.3},{},{},{},{},{},{},{},{},{},{},{},{:e},{}",
                    u.id,
                    s.p.x,
                    s.p.y,
                    s.v.x,
                    s.v.y,
                    l.target.x,
                    l.target.y,
                    l.u_ref.x,
                    l.u_ref.y,
                    l.u.x,
                    l.u.y,
                    l.max_slack,
                    u.nav.arrived
                )?;
                match true_states.as_ref().and_then(|states| states.get(k).copied().flatten()) {
                    Some(s) => writeln!(w, ",{},{},{},{}", s.p.x, s.p.y, s.v.x, s.v.y)?,
                    None if truth.is_some() => writeln!(w, ",,,,")?,
                    None => writeln!(w)?,
                }
            }
        }
        if arrived == n {
            break;
        }
    }
    if let Some(w) = options.trajectory.as_mut() {
        w.flush()?;
    }
    land(&mut fleet, wait_tick, params.dt);
    let (policy_fallbacks, stalls) = (recorder.policy_fallbacks(), recorder.stalls(&fleet));
    let paths = paths.map(PathRecorder::finish).unwrap_or_default();
    Ok(RunOutcome { metrics: recorder.finish(&fleet, &scenario.name), policy_fallbacks, stalls, paths })
}

/// Lands every UAV whose link takes off and ticks until they are down (at most 10 s).
fn land(fleet: &mut Fleet, wait_tick: &mut dyn FnMut(), dt: f64) {
    if fleet.uavs().iter().all(|u| u.link.describe() == links::SIM_LINK) {
        return;
    }
    fleet.land_all();
    let mut waited = 0.0;
    while waited < 10.0 && fleet.uavs().iter().any(|u| u.link.phase().airborne()) {
        wait_tick();
        fleet.tick();
        waited += dt;
    }
}
