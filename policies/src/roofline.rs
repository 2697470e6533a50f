//! The machine's f32 GEMM rate, the roof of the rl policies stage: an independent GEMM of the shipped
//! model's middle-layer shape (ndarray's `general_mat_mul`, i.e. matrixmultiply), beside the rates of
//! the policies' MLP kernel and of tract's plan on the whole shipped net, all on the same batch.

use crate::{LoadError, OnnxPolicy, Policy, shipped_model};
use ndarray::{Array2, Axis, linalg::general_mat_mul};
use rayon::prelude::*;
use std::time::Instant;

/// Width of the shipped model's hidden layers: the GEMM measured is `rows × HIDDEN` by `HIDDEN × HIDDEN`.
pub const HIDDEN: usize = 128;

/// GFLOP/s (10⁹ floating-point operations per second, a multiply-add counted as 2) measured by
/// [`gemm_roofline`]: each figure is the best of its repeats, after one untimed run.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GemmRoofline {
    /// Rows of the batch (observations, or rows of the GEMM's left operand).
    pub rows: usize,
    /// Threads of the rayon pool the `_pool` figures ran on (the caller's current pool).
    pub threads: usize,
    /// `C = A·B`, `A` `rows × 128`, `B` `128 × 128`, f32, ndarray's `general_mat_mul` on one thread:
    /// `2 · rows · 128²` flops per product. The machine's single-core GEMM figure.
    pub gemm_one_thread: f64,
    /// The same product, `A` and `C` split by rows into one share per pool thread.
    pub gemm_pool: f64,
    /// The policies' MLP kernel ([`crate::Mlp`]) on the shipped model (6→128→128→2, tanh, clip) for
    /// `rows` observations on one thread: `2 · rows · 17,152` flops (the products; tanh, clip and
    /// the conversions are not counted but take part of the time).
    pub mlp_one_thread: f64,
    /// The same on the pool (the kernel's blocks spread over it).
    pub mlp_pool: f64,
    /// tract's optimised plan on the same net and batch, one thread (same flop count).
    pub tract_one_thread: f64,
    /// tract's plan on the pool (its multithreaded products, `RayonGlobal` executor).
    pub tract_pool: f64,
}

/// Measures [`GemmRoofline`] for a batch of `rows` (10,000 matches the 10,000-UAV benchmark), each
/// figure the best of `repeats` timed runs. The `_pool` figures use the current rayon pool.
pub fn gemm_roofline(rows: usize, repeats: usize) -> Result<GemmRoofline, LoadError> {
    let mut policy = shipped_model()?;
    let macs_per_row = policy.mlp().map_or(0, |m| m.macs_per_row());
    let net_flops = 2.0 * rows as f64 * macs_per_row as f64;
    let gemm_flops = 2.0 * rows as f64 * (HIDDEN * HIDDEN) as f64;
    // A deterministic spread of observations: offsets up to ±6 m, velocities up to ±2 m/s.
    let observations: Vec<[f64; 6]> = (0..rows)
        .map(|k| std::array::from_fn(|i| ((k * 7 + i * 13) % 97) as f64 / 97.0 * 4.0 - 2.0))
        .collect();
    let a =
        Array2::<f32>::from_shape_fn((rows, HIDDEN), |(i, j)| ((i * 31 + j * 17) % 23) as f32 / 23.0 - 0.5);
    let b =
        Array2::<f32>::from_shape_fn((HIDDEN, HIDDEN), |(i, j)| ((i * 13 + j * 7) % 19) as f32 / 19.0 - 0.5);
    let mut c = Array2::<f32>::zeros((rows, HIDDEN));
    let threads = rayon::current_num_threads();
    let share = rows.div_ceil(threads).max(1);
    let mut gemm_pool = || {
        let shares: Vec<_> =
            a.axis_chunks_iter(Axis(0), share).zip(c.axis_chunks_iter_mut(Axis(0), share)).collect();
        shares.into_par_iter().for_each(|(a, mut c)| general_mat_mul(1.0, &a, &b, 0.0, &mut c));
    };
    let gemm_pool = gflops(gemm_flops, repeats, &mut gemm_pool);
    let (mlp_pool, tract_pool) = net_rates(&mut policy, &observations, net_flops, repeats);
    let one = rayon::ThreadPoolBuilder::new().num_threads(1).build().map_err(|e| LoadError::Model {
        path: "gemm_roofline".into(),
        reason: format!("cannot build a one-thread pool: {e}"),
    })?;
    let (gemm_one_thread, (mlp_one_thread, tract_one_thread)) = one.install(|| {
        let mut c = Array2::<f32>::zeros((rows, HIDDEN));
        let gemm = gflops(gemm_flops, repeats, &mut || general_mat_mul(1.0, &a, &b, 0.0, &mut c));
        (gemm, net_rates(&mut policy, &observations, net_flops, repeats))
    });
    Ok(GemmRoofline {
        rows,
        threads,
        gemm_one_thread,
        gemm_pool,
        mlp_one_thread,
        mlp_pool,
        tract_one_thread,
        tract_pool,
    })
}

/// (MLP kernel, tract plan) GFLOP/s of `policy` on `observations` in the current pool.
fn net_rates(policy: &mut OnnxPolicy, observations: &[[f64; 6]], flops: f64, repeats: usize) -> (f64, f64) {
    let mut actions = Vec::new();
    // `act` runs the MLP kernel (the shipped model is an MLP); tract's plan is run explicitly.
    let mlp = gflops(flops, repeats, &mut || {
        let _ = policy.act(observations, &mut actions);
    });
    let tract = gflops(flops, repeats, &mut || {
        let _ = policy.infer_with_tract(observations);
    });
    (mlp, tract)
}

/// `flops / 10⁹` divided by the best time of `repeats` runs of `run` (after one untimed run).
fn gflops(flops: f64, repeats: usize, run: &mut dyn FnMut()) -> f64 {
    run();
    let best = (0..repeats.max(1))
        .map(|_| {
            let start = Instant::now();
            run();
            start.elapsed().as_secs_f64()
        })
        .fold(f64::INFINITY, f64::min);
    flops / 1e9 / best
}
