//! `airroads bench crazyflie`: N simulated Crazyflies (cfsim, in this process, over UDP on
//! loopback) flown by N relay link tasks from a 20 Hz loop, like the fleet loop does. Per fleet
//! size it prints the setpoint latency (from `Link::send` in the tick to the datagram's arrival at
//! the simulated Crazyflie) and the share of ticks on which a link had a fresh state.

use flights::say;

use crate::BenchArgs;
use cfsim::{SimConfig, SimCrazyflie, SimHandle};
use crazyflie::{CrazyflieLink, RelayConfig};
use engine::stats::percentiles;
use links::{Link, LinkPhase};
use std::net::SocketAddr;
use std::process::ExitCode;
use std::time::{Duration, Instant};
use uav::Vec2;

/// Runs the benchmark.
pub fn main(args: &BenchArgs) -> ExitCode {
    let Some(runtime) = crate::runtime() else { return ExitCode::FAILURE };
    say!("Crazyflie relay over CRTP/UDP (loopback), 20 Hz, {:.0} s per fleet size", args.seconds);
    say!(
        "{:>6} {:>10} {:>10} {:>10} {:>10} {:>12} {:>10}",
        "count",
        "flying",
        "lat p50 ms",
        "lat p99 ms",
        "lat max ms",
        "fresh state",
        "tick p99 ms"
    );
    for &count in &args.crazyflies {
        match measure(&runtime, count, args.seconds.max(1.0)) {
            Ok(row) => say!("{row}"),
            Err(e) => {
                eprintln!("error: {count} Crazyflies: {e:#}");
                return ExitCode::FAILURE;
            }
        }
    }
    ExitCode::SUCCESS
}

fn measure(runtime: &tokio::runtime::Runtime, count: usize, seconds: f64) -> anyhow::Result<String> {
    let _inside = runtime.enter();
    let any: SocketAddr = "127.0.0.1:0".parse()?;
    let sims: Vec<SimHandle> = (0..count)
        .map(|i| {
            let config = SimConfig { initial_position: [i as f64, 0.0, 0.0], ..SimConfig::default() };
            SimCrazyflie::spawn(any, config)
        })
        .collect::<Result<_, _>>()?;
    let relay = RelayConfig { takeoff_s: 1.0, ..RelayConfig::default() };
    let mut links: Vec<CrazyflieLink> =
        sims.iter().map(|s| CrazyflieLink::spawn(runtime.handle(), &s.uri(), relay)).collect();
    let deadline = Instant::now() + Duration::from_secs(30);
    while links.iter().any(|l| l.phase() != LinkPhase::Flying) && Instant::now() < deadline {
        std::thread::sleep(Duration::from_millis(20));
    }
    let flying = links.iter().filter(|l| l.phase() == LinkPhase::Flying).count();

    let period = Duration::from_millis(50);
    let ticks = (seconds / 0.05) as usize;
    // Microseconds, printed in milliseconds.
    let (mut latencies, mut tick_us) = (Vec::new(), Vec::new());
    let (mut fresh, mut reads) = (0usize, 0usize);
    let mut next = Instant::now();
    for tick in 0..ticks {
        next += period;
        let now = Instant::now();
        if next > now {
            std::thread::sleep(next - now);
        }
        let started = Instant::now();
        let before: Vec<u64> = sims.iter().map(|s| s.stats().setpoints).collect();
        // A small circle of accelerations, like a fleet in flight.
        let angle = tick as f64 * 0.1;
        for link in &mut links {
            fresh += usize::from(link.state().is_some());
            reads += 1;
            link.send(Vec2::new(angle.cos(), angle.sin()) * 0.2);
        }
        tick_us.push(started.elapsed().as_secs_f64() * 1e6);
        // Wait (up to the next tick) for each setpoint to reach its simulator.
        let deadline = next + period;
        for (sim, count_before) in sims.iter().zip(before) {
            while sim.stats().setpoints == count_before && Instant::now() < deadline {
                std::hint::spin_loop();
            }
            let stats = sim.stats();
            if let Some(at) = stats.last_setpoint.filter(|_| stats.setpoints > count_before) {
                latencies.push(at.saturating_duration_since(started).as_secs_f64() * 1e6);
            }
        }
    }
    let sent = ticks * count;
    let lat = percentiles(&mut latencies);
    let tick = percentiles(&mut tick_us);
    drop(links);
    runtime.block_on(async {
        tokio::time::sleep(Duration::from_millis(100)).await;
        for sim in sims {
            sim.shutdown().await;
        }
    });
    Ok(format!(
        "{count:>6} {flying:>10} {:>10.2} {:>10.2} {:>10.2} {:>11.1}% {:>10.3}   ({} of {sent} setpoints arrived)",
        lat.p50_us / 1e3,
        lat.p99_us / 1e3,
        lat.max_us / 1e3,
        100.0 * fresh as f64 / reads.max(1) as f64,
        tick.p99_us / 1e3,
        latencies.len(),
    ))
}
