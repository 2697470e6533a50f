//! Prints [`policies::gemm_roofline`] for a batch: `cargo run --release -p policies --example
//! roofline -- [ROWS] [REPEATS]` (default 10,000 rows, 20 repeats), on the global rayon pool.

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1).map(|a| a.parse::<usize>());
    let rows = args.next().transpose()?.unwrap_or(10_000);
    let repeats = args.next().transpose()?.unwrap_or(20);
    let r = policies::gemm_roofline(rows, repeats)?;
    println!("rows {} threads {} (GFLOP/s, best of {repeats})", r.rows, r.threads);
    println!("ndarray GEMM {rows}x128x128: 1 thread {:.1}, pool {:.1}", r.gemm_one_thread, r.gemm_pool);
    println!("MLP kernel (shipped net):   1 thread {:.1}, pool {:.1}", r.mlp_one_thread, r.mlp_pool);
    println!("tract plan (shipped net):   1 thread {:.1}, pool {:.1}", r.tract_one_thread, r.tract_pool);
    Ok(())
}
