//! `airroads bench fleet`: the wall time of each stage of a tick, per UAV, for dense two-way crowds
//! (`fleet::stress::crowd_scenario`) of 1,000 and 10,000 UAVs on the in-process simulator. The
//! blocks start 30 m apart, so the measured ticks are the approach (every UAV flying, few filter
//! solves): the navigation and traffic rules work for every UAV every tick regardless.

use flights::say;

use crate::BenchArgs;
use fleet::stress::crowd_scenario;
use fleet::{Fleet, FleetConfig, Scenario, StageTimes};
use links::SimLink;
use policies::PolicyRegistry;
use std::process::ExitCode;
use uav::UavState;

/// Runs the subcommand.
pub fn main(args: &BenchArgs) -> ExitCode {
    say!(
        "airroads bench fleet: crowd of N UAVs, policy {}, {} ticks each; mean µs per tick (and per UAV)",
        args.policy,
        args.ticks
    );
    say!(
        "{:>7} {:>18} {:>18} {:>18} {:>18} {:>18} {:>18} {:>18}",
        "uavs",
        "read",
        "neighbours",
        "navigation",
        "policies",
        "filter",
        "send",
        "tick"
    );
    for &n in &args.uavs_or(&[1000, 10000]) {
        let mut fleet = match sim_fleet(&crowd_scenario(n.max(2)), &args.policy, &args.solver) {
            Ok(f) => f,
            Err((message, code)) => {
                eprintln!("error: crowd of {n}: {message}");
                return code;
            }
        };
        // Two ticks to warm up (first allocations, the model's first run), then the measured ones.
        fleet.tick();
        fleet.tick();
        let mut sum = StageTimes::default();
        let ticks = args.ticks.max(1);
        for _ in 0..ticks {
            fleet.tick();
            let s = fleet.stage_times();
            sum.read_us += s.read_us;
            sum.neighbours_us += s.neighbours_us;
            sum.navigation_us += s.navigation_us;
            sum.policies_us += s.policies_us;
            sum.filter_us += s.rows_us + s.filter_us;
            sum.send_us += s.send_us;
        }
        let per = |total: f64| {
            let tick = total / ticks as f64;
            format!("{tick:>10.0} ({:>5.2})", tick / n as f64)
        };
        let total = sum.read_us
            + sum.neighbours_us
            + sum.navigation_us
            + sum.policies_us
            + sum.filter_us
            + sum.send_us;
        say!(
            "{n:>7} {:>18} {:>18} {:>18} {:>18} {:>18} {:>18} {:>18}",
            per(sum.read_us),
            per(sum.neighbours_us),
            per(sum.navigation_us),
            per(sum.policies_us),
            per(sum.filter_us),
            per(sum.send_us),
            per(total)
        );
    }
    ExitCode::SUCCESS
}

/// A fleet flying `scenario` on in-process simulated links with `policy` for every UAV and QP
/// `solver` (`exact` or `clarabel`), or the error message and exit code (2 for an unknown policy).
pub fn sim_fleet(scenario: &Scenario, policy: &str, solver: &str) -> Result<Fleet, (String, ExitCode)> {
    let scenario = scenario.validate().map_err(|e| (e.to_string(), ExitCode::FAILURE))?;
    let policies = match PolicyRegistry::standard(scenario.params.delta) {
        Ok(p) if p.check(policy).is_ok() => p,
        Ok(_) => return Err((format!("--policy {policy}: unknown (expected pd or rl)"), ExitCode::from(2))),
        Err(e) => return Err((e.to_string(), ExitCode::FAILURE)),
    };
    let mut config = FleetConfig { params: scenario.params, ..FleetConfig::default() };
    // The value parser of `--solver` only admits valid names.
    config.filter.solver = solver.parse().unwrap_or_default();
    let mut fleet = Fleet::new(config, scenario.road.clone(), policies);
    for u in &scenario.uavs {
        let state = UavState::at_rest(u.start);
        let link = Box::new(SimLink::new(state, scenario.params.dt));
        fleet.add(u.id.clone(), policy.to_string(), link, state, Some(u.goal));
    }
    Ok(fleet)
}
