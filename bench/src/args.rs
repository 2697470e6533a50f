//! `airroads bench`'s arguments (a public contract: flags relied on by BENCHMARKS.md's commands).

use clap::{Args, ValueEnum};
use std::path::PathBuf;

/// `airroads bench`.
#[derive(Debug, Args)]
pub struct BenchArgs {
    /// What to measure.
    #[arg(value_enum)]
    pub target: BenchTarget,
    /// Filter calls per row count (`filter`).
    #[arg(long, default_value_t = 20000)]
    pub iterations: usize,
    /// Seconds per phase (`server`).
    #[arg(long, default_value_t = 10.0)]
    pub seconds: f64,
    /// WebSocket clients of the loaded phases (`server`); a tenth of them never read.
    #[arg(long, default_value_t = 200)]
    pub clients: usize,
    /// Scenario the server flies (`server`; default: the embedded demo).
    #[arg(long, conflicts_with = "crowd")]
    pub scenario: Option<PathBuf>,
    /// Fly the dense two-way crowd of N UAVs instead (`server`; the crowd of `fleet`).
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u64).range(2..=100_000))]
    pub crowd: Option<u64>,
    /// Fleet sizes to measure (`crazyflie`), comma-separated.
    #[arg(long, value_delimiter = ',', default_values_t = [1, 10, 25, 50, 100])]
    pub crazyflies: Vec<usize>,
    /// Fleet sizes to measure, comma-separated (`fleet`: default 1000,10000; `scale`: default
    /// 1000,3000,10000).
    #[arg(long, value_delimiter = ',', value_parser = clap::value_parser!(u64).range(2..=200_000))]
    pub uavs: Vec<u64>,
    /// Ticks measured per fleet size (`fleet`, `scale`).
    #[arg(long, default_value_t = 40)]
    pub ticks: usize,
    /// Policy flown (`fleet`, `scale`): `pd` or `rl`.
    #[arg(long, default_value = "rl")]
    pub policy: String,
    /// Worker threads of the tick's parallel stages (`scale`; default: all cores).
    #[arg(long, value_parser = clap::value_parser!(u64).range(1..=256))]
    pub threads: Option<u64>,
    /// Also write each fleet size's scenario as DIR/trunkN.json (`scale`; DIR/cityN.json with `--road
    /// city`), for `airroads run` and for other simulators (scripts/rvo2-bench).
    #[arg(long, value_name = "DIR")]
    pub write_scenarios: Option<PathBuf>,
    /// Also write every measured tick's time and stage times (µs) as CSV rows to FILE (`scale`):
    /// `uavs,tick,tick_us,` then each stage as printed, `states_us` to `metrics_us`.
    #[arg(long, value_name = "FILE")]
    pub tick_times: Option<PathBuf>,
    /// What `scale` flies: `trunk`, the winding two-way trunk road, or `city`, a street grid of
    /// square junctions and two-way streets sized from the fleet (`fleet::city`).
    #[arg(long, default_value = "trunk", value_parser = ["trunk", "city"])]
    pub road: String,
    /// QP solver of the filter (`filter`, `fleet`, `scale`): `exact` or `clarabel`.
    #[arg(long, default_value = "exact", value_parser = ["exact", "clarabel"])]
    pub solver: String,
    /// Random instances (`solver`).
    #[arg(long, default_value_t = 100_000)]
    pub instances: u64,
    /// Seed of the random instances (`solver`).
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Region servers of the deployment (`regions`).
    #[arg(long, default_value_t = 4, value_parser = clap::value_parser!(u64).range(2..=16))]
    pub regions: u64,
    /// Join the regions over plain TCP instead of TLS with certificates (`regions`; loopback).
    #[arg(long = "zenoh-insecure")]
    pub zenoh_insecure: bool,
    /// The Crazyflie firmware's SITL build (`firmware`): one process per UAV.
    #[arg(long, value_name = "PATH")]
    pub cf2: Option<PathBuf>,
}

/// Benchmarks.
#[derive(Debug, Clone, Copy, ValueEnum)]
pub enum BenchTarget {
    /// µs per filtered UAV for 2, 6 and 12 active rows.
    Filter,
    /// The server under load: tick p99 with 0 and with 200 WebSocket clients (20 stalled), REST p99.
    Server,
    /// Crazyflie relay: setpoint latency from tick to the simulated Crazyflie, and how many
    /// Crazyflies one server's link tasks keep at 20 Hz.
    Crazyflie,
    /// Changes per second the server acknowledges on disk (fsync, group commit) and in memory.
    Durability,
    /// The exact QP solver against Clarabel on `--instances` random and degenerate instances from
    /// `--seed`: max ‖u − u_clarabel‖, max KKT residual; exits 1 beyond 1e-6 / 1e-9.
    Solver,
    /// Per-stage time of one tick (navigation and traffic rules, policies, filter, ...) per UAV, for
    /// dense two-way crowds of each `--uavs` size.
    Fleet,
    /// `--regions` region servers in one process over Zenoh (loopback TCP) flying the trunk road's
    /// `--uavs` UAVs: bytes per second each publishes, the age of the foreign states used, ticks.
    Regions,
    /// Real Crazyflie firmware processes (`--cf2`) on cfsim's physics flying a swap of `--uavs`
    /// UAVs in real time: how the firmware kept up, arrivals, true margins.
    Firmware,
    /// Tick p50/p99 and each stage's time for UAVs flying both ways along a long winding trunk road
    /// (1.2 km per 1,000 UAVs; `--road city`: across a street grid), for each `--uavs` size (up to
    /// 200,000), resident memory, how the per-UAV cost grows, and each stage's roofline (its time over
    /// its floor at this machine's measured GEMM rate or memory bandwidth).
    Scale,
}

impl BenchArgs {
    /// The `--uavs` sizes, or `default` when none were given.
    pub fn uavs_or(&self, default: &[usize]) -> Vec<usize> {
        if self.uavs.is_empty() { default.to_vec() } else { self.uavs.iter().map(|&n| n as usize).collect() }
    }
}
