//! Headless scenario runs: simulate until every UAV has arrived or t_max, recording metrics and,
//! optionally, a trajectory CSV.

use crate::fleet::{Fleet, FleetConfig};
use crate::metrics::{MetricsRecorder, RunMetrics};
use crate::scenario::ValidScenario;
use links::SimLink;
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
}

/// What a headless run produced.
#[derive(Debug, Clone, PartialEq)]
pub struct RunOutcome {
    /// The METRICS.json document.
    pub metrics: RunMetrics,
    /// UAV-ticks where the policy gave no finite action and the UAV braked instead.
    pub policy_fallbacks: u64,
}

/// Header of the trajectory CSV.
pub const TRAJECTORY_HEADER: &str =
    "t,id,x,y,vx,vy,target_x,target_y,u_ref_x,u_ref_y,u_x,u_y,max_slack,arrived";

/// Runs `scenario` in the in-process simulator. The policy must exist in `policies`.
pub fn run_scenario(
    scenario: &ValidScenario,
    mut options: RunOptions,
    policies: PolicyRegistry,
) -> std::io::Result<RunOutcome> {
    let mut config = options.config;
    config.params = scenario.params;
    let params = config.params;
    let mut fleet = Fleet::new(config, scenario.road.clone(), policies);
    for u in &scenario.uavs {
        let state = UavState::at_rest(u.start);
        let link = Box::new(SimLink::new(state, params.dt));
        fleet.add(u.id.clone(), options.policy.clone(), link, state, Some(u.goal));
    }
    if let Some(w) = options.trajectory.as_mut() {
        writeln!(w, "{TRAJECTORY_HEADER}")?;
    }
    let mut recorder = MetricsRecorder::new();
    let n = scenario.uavs.len();
    for tick in 0..params.max_ticks() {
        let t = tick as f64 * params.dt;
        let arrived = fleet.tick();
        recorder.record(&fleet, t);
        if let Some(w) = options.trajectory.as_mut() {
            for u in fleet.uavs() {
                let (s, l) = (&u.state, &u.last);
                writeln!(
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
            }
        }
        if arrived == n {
            break;
        }
    }
    if let Some(w) = options.trajectory.as_mut() {
        w.flush()?;
    }
    let policy_fallbacks = recorder.policy_fallbacks;
    Ok(RunOutcome { metrics: recorder.finish(&fleet, &scenario.name), policy_fallbacks })
}
