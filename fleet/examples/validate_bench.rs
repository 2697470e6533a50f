//! Times `Scenario::validate` on a 2,000-segment road with 50,000 UAVs, valid and invalid in its
//! last UAV (median of a few runs), and prints a table:
//!
//! ```sh
//! cargo run --release -p fleet --example validate_bench
//! ```

#[path = "support/big_scenario.rs"]
mod big_scenario;

use std::time::{Duration, Instant};

const RUNS: usize = 5;

fn median(mut times: Vec<Duration>) -> Duration {
    times.sort();
    times[times.len() / 2]
}

fn main() {
    // Wall-clock figures on a shared machine: the load average says how much else was running.
    let load = std::fs::read_to_string("/proc/loadavg").unwrap_or_default();
    let load = load.split_whitespace().next().unwrap_or("?");
    println!(
        "Scenario::validate, {} segments, median of {RUNS} runs (load average {load})",
        big_scenario::SEGMENTS
    );
    println!("| case | UAVs | median (ms) | result |");
    println!("|---|---:|---:|---|");
    for (case, scenario) in [
        ("valid", big_scenario::scenario(big_scenario::UAVS)),
        ("invalid last UAV", big_scenario::invalid_last(big_scenario::UAVS)),
    ] {
        let mut times = Vec::with_capacity(RUNS);
        let mut result = String::new();
        for _ in 0..RUNS {
            let start = Instant::now();
            let outcome = scenario.validate();
            times.push(start.elapsed());
            result = match outcome {
                Ok(v) => format!("ok, {} UAVs", v.uavs.len()),
                Err(e) => e.to_string(),
            };
        }
        let ms = median(times).as_secs_f64() * 1e3;
        println!("| {case} | {} | {ms:.1} | {result} |", scenario.uavs.len());
    }
}
