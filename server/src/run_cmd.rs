//! `airroads run SCENARIO.json`: headless run, human summary, METRICS.json, exit status.

use crate::cli::RunArgs;
use anyhow::Context;
use fleet::{
    RunMetrics, RunOptions, Scenario, ScenarioError, ValidScenario, run_scenario, run_scenario_on,
    run_scenario_on_truth,
};
use policies::PolicyRegistry;
use std::path::Path;
use std::process::ExitCode;

/// Exit status for invalid input.
pub const EXIT_INVALID: u8 = 2;

/// Reads and validates a scenario file; the error names the file, the field (or line) and the reason.
pub fn load_scenario(path: &Path) -> Result<ValidScenario, String> {
    load_scenario_with(path, &links::LinkRules::default())
}

/// [`load_scenario`] with the links `rules` allow (e.g. the server's `--allow-link-host`).
pub fn load_scenario_with(path: &Path, rules: &links::LinkRules) -> Result<ValidScenario, String> {
    let text = std::fs::read_to_string(path).map_err(|e| format!("{}: cannot read: {e}", path.display()))?;
    let located = |e: ScenarioError| match e {
        ScenarioError::Parse { line, column, message } => {
            format!("{}:{line}:{column}: {message}", path.display())
        }
        ScenarioError::Invalid { field, reason } => format!("{}: {field}: {reason}", path.display()),
    };
    Scenario::from_json(&text).and_then(|s| s.validate_with(rules)).map_err(located)
}

/// Prints the short human summary of a run.
pub fn print_summary(m: &RunMetrics, policy_fallbacks: u64, stalls: &[fleet::Stall]) {
    let arrived = m.arrival_time_s.values().filter(|t| t.is_some()).count();
    let fmt = |x: Option<f64>| x.map_or("n/a".to_string(), |v| format!("{v:.3} m"));
    say!("scenario {}: {} ticks, {:.2} s simulated", m.scenario, m.ticks, m.sim_time_s);
    say!("  arrived          {arrived}/{}", m.arrival_time_s.len());
    say!("  stalls           {:.1} UAV-s in total, longest {:.1} s", m.stall_s, m.max_stall_s);
    for s in stalls.iter().filter(|s| s.duration_s > 2.0).take(5) {
        say!(
            "                   {} {:.1} s from t = {:.1} s at [{:.2}, {:.2}]",
            s.id,
            s.duration_s,
            s.start_s,
            s.at[0],
            s.at[1]
        );
    }
    say!(
        "  collision margin {} (min S_kd), separation {}",
        fmt(m.min_collision_margin_m),
        fmt(m.min_separation_m)
    );
    say!(
        "  road margin      {:.3} m (min S_kij), wall distance {:.3} m",
        m.min_road_margin_m,
        m.min_wall_distance_m
    );
    say!("  outside road     {} UAV-ticks", m.steps_outside_road);
    say!(
        "  qp               {} solves, {} with slack, max slack {:.3e}, {} failures, p50 {:.1} µs, p99 {:.1} µs",
        m.qp.solves,
        m.qp.slack_used,
        m.qp.max_slack,
        m.qp.failures,
        m.qp.p50_us,
        m.qp.p99_us
    );
    if policy_fallbacks > 0 {
        say!("  policy fallbacks {policy_fallbacks} UAV-ticks braked on a non-finite policy output");
    }
    say!("  {}", if m.safe { "SAFE" } else { "UNSAFE" });
}

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

/// Flies `scenario` with one simulated Crazyflie per UAV through the CRTP/UDP path, in real time.
fn run_on_cfsim(
    scenario: &ValidScenario,
    options: RunOptions,
    policies: PolicyRegistry,
) -> anyhow::Result<fleet::RunOutcome> {
    let runtime = tokio::runtime::Builder::new_multi_thread().enable_all().build()?;
    let mut scenario = scenario.clone();
    let sims = {
        let _inside = runtime.enter();
        let count = scenario.uavs.len();
        airroads::cfsim_fleet::spawn(&mut scenario, count, 0)?
    };
    say!("flying {} simulated Crazyflies over CRTP/UDP (take-off first)", sims.len());
    let dt = scenario.params.dt;
    let mut make_link = crazyflie_links(runtime.handle(), dt);
    // Ticks at 1/dt of wall time, like the server's loop.
    let mut wait_tick = real_time_ticks(dt);
    let outcome = run_scenario_on(&scenario, options, policies, &mut make_link, &mut wait_tick)
        .context("flying the simulated Crazyflies")?;
    runtime.block_on(async {
        for sim in sims {
            sim.shutdown().await;
        }
    });
    Ok(outcome)
}

/// Above this height every Crazyflie is airborne and the margins are measured on the physics (m).
const AIRBORNE_M: f64 = 0.3;

/// Flies `scenario` with one real firmware process per UAV on cfsim's physics, in real time; the
/// margins are measured on the physics' ground truth.
pub fn run_on_firmware(
    scenario: &ValidScenario,
    options: RunOptions,
    policies: PolicyRegistry,
    cf2: &Path,
) -> anyhow::Result<fleet::RunOutcome> {
    let runtime = tokio::runtime::Builder::new_multi_thread().enable_all().build()?;
    let mut scenario = scenario.clone();
    let firmware = airroads::firmware_fleet::FirmwareFleet::start(&mut scenario, cf2)?;
    say!(
        "flying {} Crazyflie firmware processes ({}) on cfsim's physics (take-off first; consoles in {})",
        scenario.uavs.len(),
        cf2.display(),
        firmware.run_dir.display()
    );
    let dt = scenario.params.dt;
    let mut make_link = crazyflie_links(runtime.handle(), dt);
    // Setpoint latency: from the start of a tick to its setpoint's arrival at the firmware's
    // socket, read before the next tick (by then every setpoint of the tick has arrived).
    let mut latencies_us = Vec::new();
    let mut sleep = real_time_ticks(dt);
    let mut tick_start: Option<(std::time::Instant, Vec<u64>)> = None;
    let mut wait_tick = || {
        sleep();
        let setpoints = firmware.setpoints();
        if let Some((start, before)) = &tick_start {
            for ((count, at), before) in setpoints.iter().zip(before) {
                if let Some(at) = at.filter(|_| count > before) {
                    latencies_us.push(at.saturating_duration_since(*start).as_secs_f64() * 1e6);
                }
            }
        }
        tick_start = Some((std::time::Instant::now(), setpoints.iter().map(|s| s.0).collect()));
    };
    let mut first: Option<(std::time::Instant, Vec<u64>)> = None;
    let mut truth = || {
        let states = firmware.truth(AIRBORNE_M);
        if states.is_some() && first.is_none() {
            first = Some(firmware.motor_packets());
        }
        states
    };
    let outcome =
        run_scenario_on_truth(&scenario, options, policies, &mut make_link, &mut wait_tick, &mut truth)
            .context("flying the Crazyflie firmware")?;
    if let Some(first) = first {
        let rates = firmware.motor_rates_since(&first);
        let (lo, hi) = rates.iter().fold((f64::INFINITY, 0.0_f64), |(lo, hi), r| (lo.min(*r), hi.max(*r)));
        let stats = firmware.physics.loop_stats();
        say!(
            "  firmware         motor packets {lo:.0}-{hi:.0}/s per Crazyflie (500 on an idle machine), {} \
             loop-rate warnings in {} consoles; physics {:.0} Hz, {} resyncs",
            firmware.rate_warnings(),
            rates.len(),
            stats.physics_rate_hz(),
            stats.resyncs
        );
    }
    let latency = engine::stats::percentiles(&mut latencies_us);
    say!(
        "  setpoints        {} arrived, latency from the tick p50 {:.1} ms, p99 {:.1} ms, max {:.1} ms",
        latencies_us.len(),
        latency.p50_us / 1e3,
        latency.p99_us / 1e3,
        latency.max_us / 1e3
    );
    drop(firmware);
    Ok(outcome)
}

/// A `make_link` that flies each UAV through the relay to the Crazyflie its `link` names.
pub fn crazyflie_links(
    runtime: &tokio::runtime::Handle,
    dt: f64,
) -> impl FnMut(&fleet::UavSpec, uav::UavState) -> Box<dyn links::Link> + use<> {
    let relay = crazyflie::RelayConfig { dt, ..Default::default() };
    let handle = runtime.clone();
    move |u, _| {
        Box::new(crazyflie::CrazyflieLink::spawn(&handle, u.link.as_deref().unwrap_or_default(), relay))
    }
}

/// A `wait_tick` for real time: sleeps until the next multiple of `dt` (late ticks are not made up).
pub fn real_time_ticks(dt: f64) -> impl FnMut() {
    let period = std::time::Duration::from_secs_f64(dt);
    let mut next = std::time::Instant::now();
    move || {
        next += period;
        let now = std::time::Instant::now();
        if next > now {
            std::thread::sleep(next - now);
        } else {
            next = now;
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
