//! `airroads bench fleet`: the wall time of each stage of a tick, per UAV, for dense two-way crowds
//! (`fleet::stress::crowd_scenario`) of 1,000 and 10,000 UAVs on the in-process simulator. The
//! blocks start 30 m apart, so the measured ticks are the approach (every UAV flying, few filter
//! solves): the navigation and traffic rules work for every UAV every tick regardless.

use crate::cli::BenchArgs;
use fleet::stress::crowd_scenario;
use fleet::{Fleet, FleetConfig, StageTimes};
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
    for &n in &args.uavs {
        let scenario = match crowd_scenario(n.max(2)).validate() {
            Ok(s) => s,
            Err(e) => {
                eprintln!("error: crowd of {n}: {e}");
                return ExitCode::FAILURE;
            }
        };
        let policies = match PolicyRegistry::standard(scenario.params.delta) {
            Ok(p) if p.check(&args.policy).is_ok() => p,
            Ok(_) => {
                eprintln!("error: --policy {}: unknown (expected pd or rl)", args.policy);
                return ExitCode::from(2);
            }
            Err(e) => {
                eprintln!("error: {e}");
                return ExitCode::FAILURE;
            }
        };
        let mut config = FleetConfig { params: scenario.params, ..FleetConfig::default() };
        config.filter.solver = args.solver.parse().unwrap_or_default();
        let mut fleet = Fleet::new(config, scenario.road.clone(), policies);
        for u in &scenario.uavs {
            let state = UavState::at_rest(u.start);
            let link = Box::new(SimLink::new(state, scenario.params.dt));
            fleet.add(u.id.clone(), args.policy.clone(), link, state, Some(u.goal));
        }
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
            sum.filter_us += s.filter_us;
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
