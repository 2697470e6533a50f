//! `airroads bench scale`: the fleet engine at scale (BENCHMARKS.md "Fleet engine at scale"). For
//! each `--uavs` size, UAVs fly both ways along a long winding trunk road
//! (`fleet::trunk::trunk_scenario`: 12 m wide, 1.2 km per 1,000 UAVs, goals 60–150 m away) on
//! in-process simulated links; after two warm-up ticks, `--ticks` ticks are timed, each with the
//! metrics a headless run records. Prints tick p50/p99 and the mean time of each stage per tick and
//! per UAV and the process's resident memory, then how the per-UAV cost of each fleet compares with
//! the next smaller one's and the largest's with the smallest's, then the roofline: each stage's
//! time over its floor on this machine ([`crate::roofline`]); `--tick-times FILE` also writes each
//! measured tick's times as CSV. With `--road city` the UAVs fly across a street grid instead
//! (`fleet::city::city_scenario`: B × B blocks, square junctions, two-way streets 6 m wide limited
//! to 3 m/s, about 17 UAVs per block, goals 1.5–4 blocks away).

use flights::say;

use crate::BenchArgs;
use crate::bench_fleet::sim_fleet;
use crate::roofline::{Point, triad_bytes_per_s};
use engine::stats::percentiles;
use fleet::city::city_scenario;
use fleet::trunk::trunk_scenario;
use fleet::{MetricsRecorder, StageTimes};
use std::io::Write;
use std::process::ExitCode;
use std::time::Instant;

/// The stages, in tick order, as printed.
const STAGES: [&str; 8] =
    ["states", "navigation", "neighbours", "policies", "rows", "filter", "send", "metrics"];

/// Each stage's µs in one tick, in [`STAGES`] order.
fn stage_us(s: &StageTimes, metrics_us: f64) -> [f64; 8] {
    [
        s.read_us,
        s.navigation_us,
        s.neighbours_us,
        s.policies_us,
        s.rows_us,
        s.filter_us,
        s.send_us,
        metrics_us,
    ]
}

/// The `--tick-times` CSV file: a header, then a row per measured tick.
struct TickTimes {
    path: std::path::PathBuf,
    out: std::io::BufWriter<std::fs::File>,
}

impl TickTimes {
    /// Creates FILE and writes the header.
    fn create(path: &std::path::Path) -> std::io::Result<Self> {
        let mut out = std::io::BufWriter::new(std::fs::File::create(path)?);
        write!(out, "uavs,tick,tick_us")?;
        for stage in STAGES {
            write!(out, ",{stage}_us")?;
        }
        writeln!(out)?;
        Ok(Self { path: path.to_path_buf(), out })
    }

    /// Reports an error writing the file and gives the command's exit code.
    fn failed(path: &std::path::Path, e: std::io::Error) -> ExitCode {
        eprintln!("error: --tick-times {}: {e}", path.display());
        ExitCode::FAILURE
    }

    /// One tick's row.
    fn row(&mut self, uavs: usize, tick: usize, tick_us: f64, stages: &[f64; 8]) -> std::io::Result<()> {
        write!(self.out, "{uavs},{tick},{tick_us:.1}")?;
        for us in stages {
            write!(self.out, ",{us:.1}")?;
        }
        writeln!(self.out)
    }
}

/// Writes `scenario` as DIR/NAME.json.
fn write_scenario(dir: &std::path::Path, scenario: &fleet::Scenario) -> anyhow::Result<()> {
    use anyhow::Context as _;
    let path = dir.join(format!("{}.json", scenario.name));
    std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    let json = serde_json::to_string(scenario).context("cannot encode the scenario")?;
    std::fs::write(&path, json).with_context(|| format!("cannot write {}", path.display()))
}

/// Runs the subcommand on `--threads` worker threads (default: all cores).
pub fn main(args: &BenchArgs) -> ExitCode {
    let threads = args
        .threads
        .map_or_else(|| std::thread::available_parallelism().map_or(1, usize::from), |n| n as usize);
    match rayon::ThreadPoolBuilder::new().num_threads(threads).build() {
        Ok(pool) => pool.install(|| measure(args, threads)),
        Err(e) => {
            eprintln!("error: cannot start {threads} worker threads: {e}");
            ExitCode::FAILURE
        }
    }
}

fn measure(args: &BenchArgs, threads: usize) -> ExitCode {
    let sizes = args.uavs_or(&[1000, 3000, 10000]);
    let ticks = args.ticks.max(1);
    let city = args.road == "city";
    let road = if city {
        "city grid (two-way streets, about 17 UAVs per block)"
    } else {
        "two-way trunk road (1.2 km per 1,000 UAVs)"
    };
    say!(
        "airroads bench scale: {road}, policy {}, solver {}, {ticks} ticks each, {threads} thread(s)",
        args.policy,
        args.solver
    );
    say!("per stage: mean ms per tick (µs per UAV); tick = every stage, metrics included");
    let mut header = format!("{:>7} {:>9} {:>9}", "uavs", "p50 ms", "p99 ms");
    for name in STAGES {
        header.push_str(&format!(" {name:>17}"));
    }
    header.push_str(&format!(" {:>7}", "rss MB"));
    say!("{header}");
    let mut tick_times = None;
    if let Some(path) = &args.tick_times {
        match TickTimes::create(path) {
            Ok(file) => tick_times = Some(file),
            Err(e) => return TickTimes::failed(path, e),
        }
    }
    let mut per_uav = Vec::new();
    let mut measured = Vec::new();
    for &n in &sizes {
        let scenario = if city {
            city_scenario(n, 1).map_err(|e| format!("city grid for {n} UAVs: {e}"))
        } else {
            trunk_scenario(n, 1).map_err(|e| format!("trunk road for {n} UAVs: {e}"))
        };
        let scenario = match scenario {
            Ok(s) => s,
            Err(e) => {
                eprintln!("error: {e}");
                return ExitCode::FAILURE;
            }
        };
        if let Some(dir) = &args.write_scenarios
            && let Err(e) = write_scenario(dir, &scenario)
        {
            eprintln!("error: {e:#}");
            return ExitCode::FAILURE;
        }
        let mut fleet = match sim_fleet(&scenario, &args.policy, &args.solver) {
            Ok(f) => f,
            Err((message, code)) => {
                eprintln!("error: {} of {n} UAVs: {message}", if city { "city grid" } else { "trunk road" });
                return code;
            }
        };
        let mut recorder = MetricsRecorder::new();
        let dt = scenario.params.dt;
        // Two ticks to warm up (first allocations, the model's first run), then the measured ones.
        for _ in 0..2 {
            fleet.tick();
            recorder.record(&fleet, fleet.ticks() as f64 * dt);
        }
        let (mut sums, mut tick_us) = ([0.0; 8], Vec::with_capacity(ticks));
        for measured_tick in 0..ticks {
            let started = Instant::now();
            fleet.tick();
            let recorded = Instant::now();
            recorder.record(&fleet, fleet.ticks() as f64 * dt);
            let metrics_us = recorded.elapsed().as_secs_f64() * 1e6;
            let this_tick_us = started.elapsed().as_secs_f64() * 1e6;
            tick_us.push(this_tick_us);
            let stages = stage_us(&fleet.stage_times(), metrics_us);
            sums.iter_mut().zip(stages).for_each(|(sum, us)| *sum += us);
            if let Some(file) = &mut tick_times
                && let Err(e) = file.row(n, measured_tick + 1, this_tick_us, &stages)
            {
                return TickTimes::failed(&file.path, e);
            }
        }
        let mean_us = tick_us.iter().sum::<f64>() / ticks as f64;
        let tick = percentiles(&mut tick_us);
        let mut line = format!("{n:>7} {:>9.1} {:>9.1}", tick.p50_us / 1e3, tick.p99_us / 1e3);
        for total in sums {
            let us = total / ticks as f64;
            line.push_str(&format!(" {:>8.2} ({:>6.2})", us / 1e3, us / n as f64));
        }
        line.push_str(&resident_mb().map_or_else(|| format!(" {:>7}", "n/a"), |mb| format!(" {mb:>7.0}")));
        say!("{line}");
        per_uav.push((n, mean_us / n as f64));
        measured.push((n, sums.map(|total| total / ticks as f64 * 1e-6)));
        drop(fleet);
    }
    if let Some(file) = &mut tick_times
        && let Err(e) = file.out.flush()
    {
        return TickTimes::failed(&file.path, e);
    }
    if let Some(line) = per_uav_summary(&per_uav) {
        say!("{line}");
    }
    print_roofline(args, &measured);
    ExitCode::SUCCESS
}

/// How the mean tick per UAV (µs) grows with the fleet, from (size, µs) in the order measured: each
/// size against the one before it, then (for three or more) the largest against the smallest; None
/// for one size.
fn per_uav_summary(per_uav: &[(usize, f64)]) -> Option<String> {
    let ((small, a), (large, b)) = (per_uav.first()?, per_uav.last()?);
    if per_uav.len() < 2 {
        return None;
    }
    let mut sizes = vec![format!("{a:.2} µs at {small}")];
    for pair in per_uav.windows(2) {
        let ((before, x), (n, y)) = (pair[0], pair[1]);
        sizes.push(format!("{y:.2} µs at {n} (×{:.2} of {before})", y / x));
    }
    let ends =
        if per_uav.len() > 2 { format!("; {large} against {small}: ×{:.2}", b / a) } else { String::new() };
    Some(format!("per-UAV cost: {}{ends}", sizes.join(", ")))
}

/// The process's resident memory now (MB), from `/proc/self/statm` (Linux; `None` elsewhere).
fn resident_mb() -> Option<f64> {
    let statm = std::fs::read_to_string("/proc/self/statm").ok()?;
    let pages: f64 = statm.split_whitespace().nth(1)?.parse().ok()?;
    // Linux pages are 4 KiB on the machines this runs on (x86-64, and aarch64's default).
    Some(pages * 4096.0 / 1e6)
}

/// Prints each stage's place on the roofline ([`crate::roofline`]) for each fleet size, from the
/// mean seconds per tick of each stage in [`STAGES`] order.
fn print_roofline(args: &BenchArgs, measured: &[(usize, [f64; 8])]) {
    let record = std::mem::size_of::<fleet::Uav>() as f64;
    let flops = (args.policy == policies::SHIPPED_MODEL)
        .then(|| policies::flops_per_observation("rl", policies::SHIPPED_MODEL_ONNX).ok())
        .flatten();
    // The GEMM of the policy's shape on this pool (10,000 rows, best of 7): the machine's rate, and
    // the policies' own MLP kernel on the shipped net beside it.
    let roof = flops.and_then(|_| policies::gemm_roofline(10_000, 7).ok());
    let gemm = roof.map(|r| r.gemm_pool * 1e9);
    say!(
        "roofline: each stage's time over its floor; policies{}, the others: each UAV's record ({record:.0} B) streamed once at the triad bandwidth over the fleet's records",
        match (flops, roof) {
            (Some(f), Some(r)) => format!(
                " {f:.0} FLOP per UAV against an f32 GEMM (10000×128×128, ndarray) at {:.1} GFLOP/s (the MLP kernel alone: {:.1})",
                r.gemm_pool, r.mlp_pool
            ),
            _ => " (pd: not floating-point bound) as the others".to_string(),
        }
    );
    let mut header = format!("{:>7} {:>12} {:>12}", "uavs", "triad GB/s", "policy GF/s");
    for name in STAGES {
        header.push_str(&format!(" {name:>10}"));
    }
    say!("{header}");
    for &(n, seconds) in measured {
        let bandwidth = triad_bytes_per_s(n * record as usize);
        let mut line = format!("{n:>7} {:>12.1}", bandwidth / 1e9);
        let policy = flops.zip(gemm).map(|(f, g)| Point::of(f, n, seconds[3], g));
        line.push_str(
            &policy.map_or_else(|| format!(" {:>12}", "-"), |p| format!(" {:>12.1}", p.achieved / 1e9)),
        );
        for (k, &s) in seconds.iter().enumerate() {
            let point = match policy {
                Some(p) if k == 3 => p,
                _ => Point::of(record, n, s, bandwidth),
            };
            line.push_str(&format!(" {:>9.1}x", point.times_floor()));
        }
        say!("{line}");
    }
}

#[cfg(test)]
mod tests {
    use super::per_uav_summary;

    #[test]
    fn the_per_uav_summary_compares_each_size_with_the_one_before_and_the_ends() {
        assert_eq!(per_uav_summary(&[(1000, 0.8)]), None);
        assert_eq!(
            per_uav_summary(&[(1000, 0.5), (10000, 0.6)]).as_deref(),
            Some("per-UAV cost: 0.50 µs at 1000, 0.60 µs at 10000 (×1.20 of 1000)")
        );
        assert_eq!(
            per_uav_summary(&[(1000, 0.5), (10000, 0.4), (100000, 0.6)]).as_deref(),
            Some(
                "per-UAV cost: 0.50 µs at 1000, 0.40 µs at 10000 (×0.80 of 1000), 0.60 µs at 100000 (×1.50 of \
                 10000); 100000 against 1000: ×1.20"
            )
        );
    }
}
