//! The benchmarks of `airroads bench` (BENCHMARKS.md holds their figures), one module each; this
//! file dispatches them and is `airroads bench filter` itself: µs per filtered UAV for 2, 6 and 12
//! rows, through the whole filter (as flown with `--solver`), and per QP through the exact solver
//! and through Clarabel alone.

use flights::say;

mod args;
mod bench_crazyflie;
mod bench_durability;
mod bench_firmware;
mod bench_fleet;
mod bench_regions;
mod bench_scale;
mod bench_server;
mod bench_solver;
mod roofline;

pub use args::{BenchArgs, BenchTarget};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use safety::{ExactSolver, FilterSettings, QpSolver, Row, RowKind, SafetyFilter, Solver};
use std::process::ExitCode;
use std::time::Instant;
use uav::Vec2;

/// Runs the subcommand.
pub fn main(args: BenchArgs) -> ExitCode {
    match args.target {
        BenchTarget::Filter => bench_filter(args.iterations, args.solver.parse().unwrap_or_default()),
        BenchTarget::Server => return crate::bench_server::main(&args),
        BenchTarget::Crazyflie => return crate::bench_crazyflie::main(&args),
        BenchTarget::Durability => return crate::bench_durability::main(&args),
        BenchTarget::Fleet => return crate::bench_fleet::main(&args),
        BenchTarget::Scale => return crate::bench_scale::main(&args),
        BenchTarget::Regions => return crate::bench_regions::main(&args),
        BenchTarget::Firmware => return crate::bench_firmware::main(&args),
        BenchTarget::Solver => return crate::bench_solver::main(args.instances, args.seed),
    }
    ExitCode::SUCCESS
}

/// Runs an async benchmark to its end on [`runtime`]; its error is printed and exits 1.
pub fn block_on(bench: impl std::future::Future<Output = anyhow::Result<()>>) -> ExitCode {
    let Some(runtime) = runtime() else { return ExitCode::FAILURE };
    match runtime.block_on(bench) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}

/// A multi-thread tokio runtime for the benchmarks; None (the error printed) if it cannot start.
pub fn runtime() -> Option<tokio::runtime::Runtime> {
    match tokio::runtime::Builder::new_multi_thread().enable_all().build() {
        Ok(r) => Some(r),
        Err(e) => {
            eprintln!("error: cannot start the async runtime: {e}");
            None
        }
    }
}

/// A random instance whose nominal input violates every row (rows facing it within ±60°, each cut
/// 0.1–1 m/s² below it), so no call can return the nominal input unchanged.
fn instance(rng: &mut StdRng, rows: usize, out: &mut Vec<Row>) -> Vec2 {
    let angle = rng.random_range(0.0..std::f64::consts::TAU);
    let u_ref = Vec2::new(angle.cos(), angle.sin()) * rng.random_range(1.0..5.0);
    out.clear();
    for k in 0..rows {
        let phi = angle + rng.random_range(-1.0..1.0);
        let a = Vec2::new(phi.cos(), phi.sin());
        let c = a.dot(&u_ref) - rng.random_range(0.1..1.0);
        let kind = if k % 2 == 0 { RowKind::Road(k) } else { RowKind::Collision(k) };
        out.push(Row { a, c, b: rng.random_range(0.05..5.0), kind });
    }
    u_ref
}

/// p50, p99 and mean of a sample (sorted in place).
fn stats(times: &mut [f64]) -> (f64, f64, f64) {
    times.sort_by(f64::total_cmp);
    let pct = |q: f64| times[((times.len() - 1) as f64 * q).round() as usize];
    (pct(0.5), pct(0.99), times.iter().sum::<f64>() / times.len() as f64)
}

fn bench_filter(iterations: usize, solver: Solver) {
    let iterations = iterations.max(1);
    say!(
        "airroads bench filter: {iterations} random instances per row count, nominal input violating every row"
    );
    say!("  filter   = SafetyFilter::filter as flown with --solver {}", solver.name());
    say!("  exact    = ExactSolver::solve on the same rows (active set in R², KKT-certified)");
    say!("  clarabel = QpSolver::solve on the same rows (cached solver, data updated in place)");
    say!(
        "{:>6} {:>11} {:>11} {:>10} {:>10} {:>13} {:>13} {:>12} {:>7}",
        "rows",
        "filter_p50",
        "filter_p99",
        "exact_p50",
        "exact_p99",
        "clarabel_p50",
        "clarabel_p99",
        "closed_form",
        "failed"
    );
    let settings = FilterSettings { solver, ..FilterSettings::default() };
    let mut filter = SafetyFilter::new(settings);
    let (mut clarabel, mut exact) = (QpSolver::new(), ExactSolver::new());
    let mut rng = StdRng::seed_from_u64(7);
    let (mut rows, mut constraints) = (Vec::new(), Vec::new());
    for count in [2, 6, 12] {
        let mut times =
            [Vec::with_capacity(iterations), Vec::with_capacity(iterations), Vec::with_capacity(iterations)];
        let (mut closed, mut failed) = (0, 0);
        let warmup = iterations / 10;
        for i in 0..iterations + warmup {
            let u_ref = instance(&mut rng, count, &mut rows);
            constraints.clear();
            constraints.extend(settings.constraint_rows(&rows, 5.0));
            let start = Instant::now();
            let out = filter.filter(u_ref, Vec2::zeros(), &rows, 5.0, 0.05);
            let filter_us = start.elapsed().as_secs_f64() * 1e6;
            let start = Instant::now();
            let ours = exact.solve(u_ref, &constraints, 5.0);
            let exact_us = start.elapsed().as_secs_f64() * 1e6;
            let start = Instant::now();
            let sol = clarabel.solve(u_ref, &constraints, 5.0);
            let clarabel_us = start.elapsed().as_secs_f64() * 1e6;
            if i >= warmup {
                for (sample, t) in times.iter_mut().zip([filter_us, exact_us, clarabel_us]) {
                    sample.push(t);
                }
                failed += usize::from(
                    out.failed || ours.is_err() || sol.status != clarabel::solver::SolverStatus::Solved,
                );
                closed += usize::from(out.closed_form);
            }
        }
        let [(f50, f99, _), (e50, e99, _), (c50, c99, _)] = times.map(|mut t| stats(&mut t));
        let share = format!("{:.0}%", 100.0 * closed as f64 / iterations as f64);
        say!(
            "{count:>6} {f50:>11.2} {f99:>11.2} {e50:>10.2} {e99:>10.2} {c50:>13.1} {c99:>13.1} {share:>12} {failed:>7}"
        );
    }
}
