//! Flying a scenario through the relay to simulated Crazyflies or to real firmware processes, in
//! real time.

use anyhow::Context as _;
use fleet::{RunOptions, ValidScenario, run_scenario_on, run_scenario_on_truth};
use policies::PolicyRegistry;
use std::path::Path;

/// Flies `scenario` with one simulated Crazyflie per UAV through the CRTP/UDP path, in real time.
pub fn run_on_cfsim(
    scenario: &ValidScenario,
    options: RunOptions,
    policies: PolicyRegistry,
) -> anyhow::Result<fleet::RunOutcome> {
    let runtime = tokio::runtime::Builder::new_multi_thread().enable_all().build()?;
    let mut scenario = scenario.clone();
    let sims = {
        let _inside = runtime.enter();
        let count = scenario.uavs.len();
        crate::cfsim_fleet::spawn(&mut scenario, count, 0)?
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
    let firmware = crate::firmware_fleet::FirmwareFleet::start(&mut scenario, cf2)?;
    say!(
        "flying {} Crazyflie firmware processes ({}) on cfsim's physics (take-off first; consoles in {})",
        scenario.uavs.len(),
        cf2.display(),
        firmware.run_dir.display()
    );
    let started = firmware.motor_packets();
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
        run_scenario_on_truth(&scenario, options, policies, &mut make_link, &mut wait_tick, &mut truth);
    // How the firmware kept up, from the first airborne tick (from its start when it never got
    // there: a firmware the host cannot run in real time is often why).
    let rates = firmware.motor_rates_since(first.as_ref().unwrap_or(&started));
    let (lo, hi) = rates.iter().fold((f64::INFINITY, 0.0_f64), |(lo, hi), r| (lo.min(*r), hi.max(*r)));
    let stats = firmware.physics.loop_stats();
    let slowest = firmware.slowest_second().map_or_else(|| "none yet".to_string(), |n| n.to_string());
    let cuts = firmware.motor_cuts();
    say!(
        "  firmware         motor packets {lo:.0}-{hi:.0}/s per Crazyflie (500 on an idle machine), \
         slowest second {slowest}, {} loop-rate warnings in {} consoles; physics {:.0} Hz, {} resyncs; \
         {cuts} motor cuts (a firmware silent for 100 ms in flight)",
        firmware.rate_warnings(),
        rates.len(),
        stats.physics_rate_hz(),
        stats.resyncs
    );
    let outcome = outcome.context("flying the Crazyflie firmware")?;
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
