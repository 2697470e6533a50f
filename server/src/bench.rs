//! `airroads bench filter`: µs per filtered UAV for 2, 6 and 12 active rows.

use crate::cli::{BenchArgs, BenchTarget};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use safety::{Row, RowKind, SafetyFilter};
use std::process::ExitCode;
use std::time::Instant;
use uav::Vec2;

/// Runs the subcommand.
pub fn main(args: BenchArgs) -> ExitCode {
    match args.target {
        BenchTarget::Filter => bench_filter(args.iterations),
    }
    ExitCode::SUCCESS
}

/// Random instances whose nominal input violates every row, so every call solves a QP.
fn instance(rng: &mut StdRng, rows: usize, out: &mut Vec<Row>) -> Vec2 {
    let angle = rng.random_range(0.0..std::f64::consts::TAU);
    let u_ref = Vec2::new(angle.cos(), angle.sin()) * rng.random_range(1.0..5.0);
    out.clear();
    for k in 0..rows {
        // Rows facing the nominal input within ±60°, each cut 0.1–1 m/s² below it.
        let phi = angle + rng.random_range(-1.0..1.0);
        let a = Vec2::new(phi.cos(), phi.sin());
        let c = a.dot(&u_ref) - rng.random_range(0.1..1.0);
        let kind = if k % 2 == 0 { RowKind::Road(k) } else { RowKind::Collision(k) };
        out.push(Row { a, c, b: 1.0, kind });
    }
    u_ref
}

fn bench_filter(iterations: usize) {
    println!("airroads bench filter: {iterations} filter calls per row count, every call solves a QP");
    println!("{:>6} {:>10} {:>10} {:>10} {:>9}", "rows", "p50_us", "p99_us", "mean_us", "failed");
    let mut filter = SafetyFilter::default();
    let mut rng = StdRng::seed_from_u64(7);
    let mut rows = Vec::new();
    for count in [2, 6, 12] {
        let mut times = Vec::with_capacity(iterations);
        let mut failed = 0;
        for i in 0..iterations + iterations / 10 {
            let u_ref = instance(&mut rng, count, &mut rows);
            let start = Instant::now();
            let out = filter.filter(u_ref, Vec2::zeros(), &rows, 5.0, 0.05);
            let us = start.elapsed().as_secs_f64() * 1e6;
            if i >= iterations / 10 {
                times.push(us);
                failed += usize::from(out.failed);
            }
        }
        times.sort_by(f64::total_cmp);
        let pct = |q: f64| times[((times.len() - 1) as f64 * q).round() as usize];
        let mean = times.iter().sum::<f64>() / times.len() as f64;
        println!("{count:>6} {:>10.1} {:>10.1} {mean:>10.1} {failed:>9}", pct(0.5), pct(0.99));
    }
}
