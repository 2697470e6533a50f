//! `airroads run SCENARIO.json`: headless run, human summary, METRICS.json, exit status.

use crate::cli::RunArgs;
use anyhow::Context;
use fleet::{RunMetrics, RunOptions, ValidScenario, run_scenario};
use flights::{load_scenario, print_summary, run_on_cfsim, run_on_firmware};
use policies::PolicyRegistry;
use std::path::Path;
use std::process::ExitCode;

/// Exit status for invalid input.
pub const EXIT_INVALID: u8 = 2;

/// Runs the subcommand.
pub fn main(args: RunArgs) -> ExitCode {
    let scenario = match load_scenario(&args.scenario) {
        Ok(s) => s,
        Err(msg) => {
            eprintln!("error: {msg}");
            return ExitCode::from(EXIT_INVALID);
        }
    };
    if args.link == "firmware" && !args.cf2.as_deref().is_some_and(Path::is_file) {
        let given = args.cf2.as_ref().map_or("none".into(), |p| p.display().to_string());
        eprintln!("error: --link firmware needs --cf2 PATH, the firmware's SITL build (given: {given})");
        return ExitCode::from(EXIT_INVALID);
    }
    let policies = match args.flight.policies(scenario.params.delta) {
        Ok(p) => p,
        Err(msg) => {
            eprintln!("error: {msg}");
            return ExitCode::from(EXIT_INVALID);
        }
    };
    match execute(&args, &scenario, policies) {
        Ok(m) if m.safe && m.all_arrived => ExitCode::SUCCESS,
        Ok(_) => ExitCode::from(1),
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::from(1)
        }
    }
}

fn execute(args: &RunArgs, scenario: &ValidScenario, policies: PolicyRegistry) -> anyhow::Result<RunMetrics> {
    let trajectory: Option<Box<dyn std::io::Write>> = match &args.trajectory {
        Some(path) => {
            let file =
                std::fs::File::create(path).with_context(|| format!("{}: cannot create", path.display()))?;
            Some(Box::new(std::io::BufWriter::new(file)))
        }
        None => None,
    };
    let options = RunOptions {
        config: args.flight.fleet_config(),
        policy: args.flight.policy.clone(),
        trajectory,
        paths: args.plot.is_some(),
    };
    let outcome = if args.link == "cfsim" {
        run_on_cfsim(scenario, options, policies)?
    } else if args.link == "firmware" {
        // Checked in `main` before anything runs.
        let cf2 = args.cf2.as_deref().context("--link firmware needs --cf2 PATH")?;
        run_on_firmware(scenario, options, policies, cf2)?
    } else {
        run_scenario(scenario, options, policies).context("writing the trajectory")?
    };
    print_summary(&outcome.metrics, outcome.policy_fallbacks, &outcome.stalls);
    if let Some(path) = &args.plot {
        let m = &outcome.metrics;
        let arrived = m.arrival_time_s.values().filter(|t| t.is_some()).count();
        let title = format!(
            "{}: {arrived}/{} arrived in {:.1} s, policy {}, nav {}; longest stall {:.1} s",
            m.scenario,
            m.arrival_time_s.len(),
            m.sim_time_s,
            args.flight.policy,
            args.flight.nav,
            m.max_stall_s
        );
        crate::plot::draw(path, &scenario.road, &outcome.paths, &outcome.stalls, &title)
            .with_context(|| format!("{}: cannot draw the plot", path.display()))?;
    }
    if let Some(path) = &args.out {
        let json = serde_json::to_string_pretty(&outcome.metrics)?;
        std::fs::write(path, json + "\n").with_context(|| format!("{}: cannot write", path.display()))?;
    }
    Ok(outcome.metrics)
}
