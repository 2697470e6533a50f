//! Helpers shared by the end-to-end tests: a simulator on 127.0.0.1:0 and the official client
//! (crazyflie-lib) connected to it through `crazyflie::udp::UdpConnection`.
#![allow(dead_code)]

use std::time::{Duration, Instant};

use cfsim::{SimConfig, SimCrazyflie, SimHandle};
use crazyflie::udp::{UdpConfig, UdpConnection};
use crazyflie_lib::subsystems::log::{LogPeriod, LogStream};
use crazyflie_lib::{Crazyflie, NoTocCache, TocCache};

/// Deadline for a condition that takes a fraction of a second on an idle machine: a loaded 2-core
/// CI machine may take much longer. Only a test's property is a time window.
pub const PATIENCE: Duration = Duration::from_secs(20);

/// Link timing used by the tests: short timeout so disconnection tests are quick.
pub const LINK: UdpConfig =
    UdpConfig { link_timeout: Duration::from_millis(500), keepalive: Duration::from_millis(50) };

/// A simulator on an ephemeral port, on the ground at `p`.
pub fn sim_at(p: [f64; 3]) -> SimHandle {
    let config = SimConfig { initial_position: p, ..SimConfig::default() };
    SimCrazyflie::spawn("127.0.0.1:0".parse().expect("addr"), config).expect("spawn simulator")
}

/// Open the UDP transport to `sim`.
pub async fn open(sim: &SimHandle) -> UdpConnection {
    UdpConnection::open_with(&sim.uri(), LINK).await.expect("open UDP link")
}

/// Connect the official client to `sim` with a TOC cache.
pub async fn connect_with<T: TocCache>(sim: &SimHandle, cache: T) -> Crazyflie {
    let link = crazyflie_link::Connection::new(Box::new(open(sim).await));
    tokio::time::timeout(Duration::from_secs(10), Crazyflie::connect_from_link(link, cache))
        .await
        .expect("connect_from_link timed out")
        .expect("connect_from_link failed")
}

/// Connect the official client to `sim`.
pub async fn connect(sim: &SimHandle) -> Crazyflie {
    connect_with(sim, NoTocCache).await
}

/// Poll `f` every 5 ms until it holds; the time it took, or `None` after `timeout`.
pub async fn eventually(timeout: Duration, mut f: impl FnMut() -> bool) -> Option<Duration> {
    let start = Instant::now();
    loop {
        if f() {
            return Some(start.elapsed());
        }
        if start.elapsed() > timeout {
            return None;
        }
        tokio::time::sleep(Duration::from_millis(5)).await;
    }
}

/// Start a log block of `vars` at `period_ms`.
pub async fn log_stream(cf: &Crazyflie, vars: &[&str], period_ms: u64) -> LogStream {
    let mut block = cf.log.create_block().await.expect("create block");
    for v in vars {
        block.add_variable(v).await.expect("add variable");
    }
    block.start(LogPeriod::from_millis(period_ms).expect("period")).await.expect("start block")
}

/// Take off with the high-level commander to `height` and wait until there.
pub async fn take_off(cf: &Crazyflie, sim: &SimHandle, height: f32) {
    cf.high_level_commander.take_off(height, None, 1.0, None).await.expect("take off");
    let h = f64::from(height);
    eventually(PATIENCE, || (sim.truth().position[2] - h).abs() < 0.02)
        .await
        .expect("reached take-off height");
}

/// Distance between two points.
pub fn dist(a: [f64; 3], b: [f64; 3]) -> f64 {
    (0..3).map(|k| (a[k] - b[k]).powi(2)).sum::<f64>().sqrt()
}
