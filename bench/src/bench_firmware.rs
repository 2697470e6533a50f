//! `airroads bench firmware --cf2 PATH --uavs N,...`: the largest fleet of real Crazyflie firmware
//! processes this machine flies in real time. Per fleet size, a swap on a straight road (10 m by
//! 3 m; half the UAVs start at each end and fly to the other, head-on through each other) flown
//! like `airroads run --link firmware`: one `cf2` per UAV on cfsim's physics, the fleet loop at
//! 20 Hz with the rl policy. It prints how the firmware kept up (motor packets per second, 500 on
//! an idle machine; the consoles' loop-rate warnings), the physics rate, arrivals and the true
//! margins.

use flights::say;

use crate::BenchArgs;
use std::path::Path;
use std::process::ExitCode;

/// Runs the benchmark.
pub fn main(args: &BenchArgs) -> ExitCode {
    let Some(cf2) = args.cf2.as_deref().filter(|p| p.is_file()) else {
        eprintln!("error: bench firmware needs --cf2 PATH, the Crazyflie firmware's SITL build");
        return ExitCode::from(2);
    };
    let sizes: Vec<u64> = if args.uavs.is_empty() { vec![2, 4, 6] } else { args.uavs.clone() };
    // Every size is tried (a machine's limit shows as the sizes that fail); exit 1 if any did.
    let mut failed = false;
    for n in sizes {
        if let Err(e) = measure(cf2, n as usize, &args.policy) {
            eprintln!("error: {n} firmware processes: {e:#}");
            failed = true;
        }
    }
    if failed { ExitCode::FAILURE } else { ExitCode::SUCCESS }
}

/// The most UAVs of a swap.
pub const MAX_UAVS: usize = 20;

/// The swap scenario of `n` UAVs (2 to [`MAX_UAVS`]).
pub fn swap_scenario(n: usize) -> anyhow::Result<fleet::ValidScenario> {
    anyhow::ensure!((2..=MAX_UAVS).contains(&n), "the swap has 2 to {MAX_UAVS} UAVs, not {n}");
    let per_end = n.div_ceil(2);
    // Lanes across the middle 2.4 m of the road, every other one 0.6 m further in, so that
    // neighbouring lanes start (and end) at least 0.6 m apart.
    let lane = |k: usize| if per_end <= 1 { 0.0 } else { -1.2 + 2.4 * k as f64 / (per_end - 1) as f64 };
    let uavs: Vec<serde_json::Value> = (0..n)
        .map(|i| {
            let k = i / 2;
            let inset = if k % 2 == 1 { 0.6 } else { 0.0 };
            let (from, to) = if i % 2 == 0 { (1.0 + inset, 9.0 - inset) } else { (9.0 - inset, 1.0 + inset) };
            serde_json::json!({"id": format!("cf{}", i + 1), "start": [from, lane(k)], "goal": [to, lane(k)]})
        })
        .collect();
    let json = serde_json::json!({
        "name": format!("swap{n}"),
        "params": {"delta": 2.0, "r_s": 1.0, "t_max": 90},
        "segments": roads::RoadLayout::straight(0.0, 10.0, 3.0, 2).segments,
        "uavs": uavs,
    });
    let scenario = fleet::Scenario::from_json(&json.to_string()).map_err(|e| anyhow::anyhow!("{e}"))?;
    scenario.validate().map_err(|e| anyhow::anyhow!("{e}"))
}

fn measure(cf2: &Path, n: usize, policy: &str) -> anyhow::Result<()> {
    let scenario = swap_scenario(n)?;
    let policies =
        policies::PolicyRegistry::standard(scenario.params.delta).map_err(|e| anyhow::anyhow!("{e}"))?;
    let options = fleet::RunOptions {
        config: fleet::FleetConfig::default(),
        policy: policy.to_string(),
        trajectory: None,
        paths: false,
    };
    say!("== {n} Crazyflie firmware processes, {} ({policy})", scenario.name);
    let outcome = flights::run_on_firmware(&scenario, options, policies, cf2)?;
    flights::print_summary(&outcome.metrics, outcome.policy_fallbacks, &outcome.stalls);
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every size the benchmark may fly is a valid scenario: starts and goals inside the road,
    /// D_s from the walls, D_c apart.
    #[test]
    fn swap_scenarios_are_valid_up_to_the_largest() {
        for n in 2..=MAX_UAVS {
            let s = swap_scenario(n).unwrap_or_else(|e| panic!("{n} UAVs: {e}"));
            assert_eq!(s.uavs.len(), n);
            assert!(s.uavs.iter().all(|u| (u.start - u.goal).norm() > 6.5), "every UAV crosses the road");
        }
    }
}
