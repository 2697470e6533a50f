//! The roofline of `airroads bench scale`: each stage's achieved rate against a figure measured on
//! this machine. The policy stage does floating-point work (tract's count of the model's FLOPs per
//! observation, `policies::flops_per_observation`), held against the rate of an f32 GEMM of the
//! policy's middle layer on the pool (`policies::gemm_roofline`: matrixmultiply through ndarray, 10,000
//! rows); every other stage is held against the time to stream each UAV's record
//! (`fleet::Uav`, as laid out) once at the memory bandwidth measured for the fleet's working set (a
//! triad over as many bytes as the fleet's records: cache for small fleets, memory for large ones).
//! Hardware counters (instructions, cycles) are not readable here (`perf stat` says "not
//! supported" in this VM), so instructions per UAV are not reported.

use rayon::prelude::*;
use std::time::Instant;

/// Repetitions of each machine measurement; the best is kept (the machine's capability).
const REPEATS: usize = 7;

/// Bytes per second of a STREAM triad `a = b + s·c` over three f64 arrays that together hold about
/// `bytes` bytes (at least 3 × 4,096 elements), split by chunks over the current rayon pool; the best of
/// [`REPEATS`] passes. Counts 24 bytes per element (two reads, one write), as STREAM does.
pub fn triad_bytes_per_s(bytes: usize) -> f64 {
    let n = (bytes / 24).max(4096);
    let (b, c) = (vec![1.0f64; n], vec![2.0f64; n]);
    let mut a = vec![0.0f64; n];
    let chunk = n.div_ceil(rayon::current_num_threads() * 4).max(1024);
    let mut best = f64::INFINITY;
    for _ in 0..REPEATS {
        let started = Instant::now();
        a.par_chunks_mut(chunk).zip(b.par_chunks(chunk)).zip(c.par_chunks(chunk)).for_each(|((a, b), c)| {
            for ((a, b), c) in a.iter_mut().zip(b).zip(c) {
                *a = b + 3.0 * c;
            }
        });
        best = best.min(started.elapsed().as_secs_f64());
    }
    // The result is read so the passes cannot be optimised away.
    std::hint::black_box(a[n / 2]);
    24.0 * n as f64 / best
}

/// One stage's place on the roofline: its achieved rate, the machine's, and how many times its
/// floor (work at the machine's rate) it takes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Point {
    /// Achieved rate: FLOP/s or bytes/s.
    pub achieved: f64,
    /// The machine's rate for that kind of work.
    pub machine: f64,
}

impl Point {
    /// `work` units per UAV done by `uavs` UAVs in `seconds`, against the machine's `rate`.
    pub fn of(work: f64, uavs: usize, seconds: f64, rate: f64) -> Self {
        let achieved = if seconds > 0.0 { work * uavs as f64 / seconds } else { f64::INFINITY };
        Self { achieved, machine: rate }
    }

    /// Stage time over its floor (1 = at the machine's rate).
    pub fn times_floor(&self) -> f64 {
        self.machine / self.achieved
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_stage_at_the_machines_rate_is_at_its_floor() {
        let at = Point::of(1000.0, 10, 1e-6, 1e10);
        assert!((at.times_floor() - 1.0).abs() < 1e-12);
        assert!((Point::of(1000.0, 10, 4e-6, 1e10).times_floor() - 4.0).abs() < 1e-12);
    }

    #[test]
    fn the_triad_measures_a_finite_positive_bandwidth() {
        let rate = triad_bytes_per_s(1 << 20);
        assert!(rate.is_finite() && rate > 1e8, "{rate} B/s");
    }
}
