//! `airroads stress`: random valid scenarios, run in parallel, violations reported with their seeds.

use flights::say;

use crate::cli::StressArgs;
use fleet::{RunMetrics, RunOptions, run_scenario};
use std::process::ExitCode;
use std::sync::Mutex;
use std::sync::atomic::{AtomicU64, Ordering};

/// One finished case.
struct CaseResult {
    seed: u64,
    uavs: usize,
    segments: usize,
    metrics: RunMetrics,
}

/// Runs `case` for every seed of `args` (`--seed`, the next `--scenarios` - 1) on `jobs` threads,
/// each taking the next seed; the results in seed order.
pub fn each_seed<T: Send>(args: &StressArgs, jobs: usize, case: impl Fn(u64) -> T + Sync) -> Vec<T> {
    let next = AtomicU64::new(0);
    let results = Mutex::new(Vec::new());
    std::thread::scope(|scope| {
        for _ in 0..jobs.max(1) {
            scope.spawn(|| {
                loop {
                    let i = next.fetch_add(1, Ordering::Relaxed);
                    if i >= args.scenarios {
                        break;
                    }
                    let result = case(args.seed.wrapping_add(i));
                    // A poisoned lock means another worker panicked; the scope re-raises that panic.
                    if let Ok(mut r) = results.lock() {
                        r.push((i, result));
                    }
                }
            });
        }
    });
    let mut results = results.into_inner().unwrap_or_default();
    results.sort_by_key(|r| r.0);
    results.into_iter().map(|r| r.1).collect()
}

/// Runs the subcommand.
pub fn main(args: StressArgs) -> ExitCode {
    if args.link == "firmware" {
        return match args.cf2.as_deref().filter(|p| p.is_file()) {
            Some(cf2) => crate::stress_firmware::main(&args, cf2),
            None => {
                let given = args.cf2.as_ref().map_or("nothing".into(), |p| p.display().to_string());
                eprintln!(
                    "error: --link firmware needs --cf2 PATH, the firmware's SITL build (given: {given})"
                );
                ExitCode::from(2)
            }
        };
    }
    if let Err(msg) = args.flight.policies(5.0) {
        eprintln!("error: {msg}");
        return ExitCode::from(2);
    }
    let jobs =
        args.jobs.unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get())).max(1);
    let results = each_seed(&args, jobs, |seed| run_case(&args, seed));
    report(&args, &results)
}

fn run_case(args: &StressArgs, seed: u64) -> CaseResult {
    // The value parser only lets known families through.
    let family: fleet::families::Family = args.family.parse().unwrap_or_default();
    let scenario = family.scenario(seed);
    // A network's cells: its roads' segments and its junctions.
    let network_cells = scenario.roads.iter().flatten().map(|r| r.segments.len()).sum::<usize>()
        + scenario.junctions.as_ref().map_or(0, Vec::len);
    let (uavs, segments) = (scenario.uavs.len(), scenario.segments.len() + network_cells);
    // The generators only return validated scenarios.
    let valid = scenario.validate().expect("stress scenarios are valid by construction");
    // Checked in `main` before any case runs.
    let policies = args.flight.policies(valid.params.delta).expect("policies were checked at start");
    let options = RunOptions {
        config: args.flight.fleet_config(),
        policy: args.flight.policy.clone(),
        trajectory: None,
        paths: false,
    };
    // Without a trajectory writer the run does no I/O and cannot fail.
    let outcome = run_scenario(&valid, options, policies).expect("no I/O without a trajectory");
    // Unsafe cases keep their historic name; safe cases in which not everyone arrived say so.
    let (dir, name) = if !outcome.metrics.safe {
        (args.save_failing.as_ref(), format!("stress-{seed}.json"))
    } else if !outcome.metrics.all_arrived {
        (
            args.save_unfinished.as_ref().or(args.save_failing.as_ref()),
            format!("stress-{seed}-unfinished.json"),
        )
    } else {
        (None, String::new())
    };
    if let Some(dir) = dir {
        let path = dir.join(name);
        let written = std::fs::create_dir_all(dir).and_then(|()| {
            std::fs::write(&path, serde_json::to_string_pretty(&scenario).unwrap_or_default())
        });
        if let Err(e) = written {
            eprintln!("warning: {}: {e}", path.display());
        }
    }
    CaseResult { seed, uavs, segments, metrics: outcome.metrics }
}

/// Per case, when its last UAV arrived (s), infinite where not all arrived; sorted.
fn all_arrived_times(results: &[CaseResult]) -> Vec<f64> {
    let mut times: Vec<f64> = results
        .iter()
        .map(|r| {
            let m = &r.metrics;
            let last = m.arrival_time_s.values().try_fold(0.0, |last: f64, t| t.map(|t| last.max(t)));
            last.filter(|_| m.all_arrived).unwrap_or(f64::INFINITY)
        })
        .collect();
    times.sort_by(f64::total_cmp);
    times
}

/// The nearest-rank percentile `q` of sorted values (NaN when there are none).
fn percentile(sorted: &[f64], q: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    let rank = ((q * sorted.len() as f64).ceil() as usize).clamp(1, sorted.len());
    sorted[rank - 1]
}

/// A time for the summary: seconds, or "never" when not everyone arrived.
fn seconds(t: f64) -> String {
    if t.is_finite() {
        format!("{t:.1} s")
    } else if t.is_nan() {
        "-".into()
    } else {
        "never".into()
    }
}

fn report(args: &StressArgs, results: &[CaseResult]) -> ExitCode {
    let violations: Vec<&CaseResult> = results.iter().filter(|r| !r.metrics.safe).collect();
    let arrived = results.iter().filter(|r| r.metrics.all_arrived).count();
    let min = |f: fn(&RunMetrics) -> f64| results.iter().map(|r| f(&r.metrics)).fold(f64::INFINITY, f64::min);
    say!(
        "stress: {} {} scenarios (seeds {}..{}), road rule {}, nav {}, policy {}, share {}, slack weights {}",
        results.len(),
        args.family,
        args.seed,
        args.seed.wrapping_add(args.scenarios),
        args.flight.road_rule,
        args.flight.nav,
        args.flight.policy,
        args.flight.share,
        args.flight.slack_weights
    );
    say!("  all arrived in   {arrived}/{}", results.len());
    say!(
        "  min collision margin {:.3} m, min road margin {:.3} m",
        min(|m| m.min_collision_margin_m.unwrap_or(f64::INFINITY)),
        min(|m| m.min_road_margin_m)
    );
    say!(
        "  qp failures {}, max slack {:.3e}",
        results.iter().map(|r| r.metrics.qp.failures).sum::<u64>(),
        results.iter().map(|r| r.metrics.qp.max_slack).fold(0.0, f64::max)
    );
    let done = all_arrived_times(results);
    say!(
        "  time until all arrived: p50 {}, p99 {} (over all cases; unfinished count as never)",
        seconds(percentile(&done, 0.50)),
        seconds(percentile(&done, 0.99))
    );
    let stalls: f64 = results.iter().map(|r| r.metrics.stall_s).sum();
    let longest = results.iter().map(|r| r.metrics.max_stall_s).fold(0.0, f64::max);
    say!("  stalls {stalls:.1} UAV-s in total, longest {longest:.1} s");
    let wait = results.iter().map(|r| r.metrics.max_wait_s).fold(0.0, f64::max);
    say!("  longest wait for a turn at a conflict zone {wait:.1} s");
    let unfinished: Vec<&CaseResult> = results.iter().filter(|r| !r.metrics.all_arrived).collect();
    if !unfinished.is_empty() {
        say!("  not all arrived (replay with: airroads stress --family FAMILY --scenarios 1 --seed SEED):");
        say!("  {:>20} {:>5} {:>5} {:>8} {:>12}", "seed", "uavs", "segs", "arrived", "longest_s");
        for r in &unfinished {
            let m = &r.metrics;
            let arrived = m.arrival_time_s.values().filter(|t| t.is_some()).count();
            say!("  {:>20} {:>5} {:>5} {:>8} {:>12.1}", r.seed, r.uavs, r.segments, arrived, m.max_stall_s);
        }
    }
    if violations.is_empty() {
        say!("  violations 0");
        return ExitCode::SUCCESS;
    }
    say!(
        "  violations {} (replay with: airroads stress --family FAMILY --scenarios 1 --seed SEED)",
        violations.len()
    );
    say!(
        "  {:>20} {:>5} {:>5} {:>12} {:>12} {:>8} {:>8}",
        "seed",
        "uavs",
        "segs",
        "coll_m",
        "road_m",
        "outside",
        "failed"
    );
    for r in violations {
        let m = &r.metrics;
        say!(
            "  {:>20} {:>5} {:>5} {:>12.4} {:>12.4} {:>8} {:>8}",
            r.seed,
            r.uavs,
            r.segments,
            m.min_collision_margin_m.unwrap_or(f64::NAN),
            m.min_road_margin_m,
            m.steps_outside_road,
            m.qp.failures
        );
    }
    ExitCode::from(1)
}
