//! The relay against a simulated Crazyflie (cfsim) over real UDP sockets: connect, take off, follow
//! the fleet's commands, land, emergency stop, and survive a link loss.

use cfsim::{Faults, SimConfig, SimCrazyflie, SimHandle};
use crazyflie::{CrazyflieLink, RelayConfig};
use links::{Link, LinkPhase};
use std::time::{Duration, Instant};
use uav::Vec2;

fn sim_at(x: f64, y: f64) -> SimHandle {
    let config = SimConfig { initial_position: [x, y, 0.0], ..SimConfig::default() };
    SimCrazyflie::spawn("127.0.0.1:0".parse().unwrap(), config).unwrap()
}

/// Polls `f` every 10 ms until it holds, for at most `seconds`.
async fn until(what: &str, seconds: f64, mut f: impl FnMut() -> bool) {
    let end = Instant::now() + Duration::from_secs_f64(seconds);
    while !f() {
        assert!(Instant::now() < end, "timed out after {seconds} s waiting for {what}");
        tokio::time::sleep(Duration::from_millis(10)).await;
    }
}

/// Runs the fleet's side for `seconds`: every 50 ms read the state and send `u` (like the loop).
async fn fly(link: &mut CrazyflieLink, seconds: f64, mut u: impl FnMut(Option<uav::UavState>) -> Vec2) {
    let end = Instant::now() + Duration::from_secs_f64(seconds);
    while Instant::now() < end {
        let state = link.state();
        link.send(u(state));
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
}

async fn airborne_link(sim: &SimHandle) -> CrazyflieLink {
    let config = RelayConfig { takeoff_s: 1.0, ..RelayConfig::default() };
    let mut link = CrazyflieLink::spawn(&tokio::runtime::Handle::current(), &sim.uri(), config);
    assert_eq!(link.phase(), LinkPhase::Connecting);
    until("take-off to start", 5.0, || link.phase() == LinkPhase::TakingOff).await;
    until("flying", 5.0, || link.phase() == LinkPhase::Flying).await;
    let z = sim.truth().position[2];
    assert!((z - 1.0).abs() < 0.1, "took off to {z} m, not 1 m");
    assert!(link.state().is_some(), "a flying link has a fresh state");
    link
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn takes_off_follows_commands_and_lands() {
    let sim = sim_at(1.0, 2.0);
    let mut link = airborne_link(&sim).await;
    // Accelerate along +x at 1 m/s² for 1 s, then brake: it moves about 1 m along x.
    let start = sim.truth().position;
    let t0 = Instant::now();
    fly(&mut link, 2.5, |s| {
        let v = s.map_or(0.0, |s| s.v.x);
        if t0.elapsed() < Duration::from_secs(1) {
            Vec2::new(1.0, 0.0)
        } else {
            Vec2::new((-2.0 * v).clamp(-1.0, 1.0), 0.0)
        }
    })
    .await;
    let end = sim.truth();
    let moved = end.position[0] - start[0];
    assert!((0.6..1.6).contains(&moved), "moved {moved} m along x");
    assert!((end.position[1] - start[1]).abs() < 0.1, "drifted along y: {:?}", end.position);
    assert!((end.position[2] - 1.0).abs() < 0.1, "left the altitude: {:?}", end.position);
    until("a fresh state", 1.0, || {
        link.state().is_some_and(|s| (s.p.x - sim.truth().position[0]).abs() < 0.1)
    })
    .await;

    link.land();
    until("landing", 2.0, || link.phase() == LinkPhase::Landing).await;
    until("landed", 5.0, || link.phase() == LinkPhase::Landed).await;
    let truth = sim.truth();
    assert!(truth.position[2] < 0.05 && !truth.motors_on, "landed: {:?}", truth.position);
    sim.shutdown().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn emergency_stop_cuts_the_motors() {
    let sim = sim_at(0.0, 0.0);
    let mut link = airborne_link(&sim).await;
    link.emergency_stop();
    until("stopped", 2.0, || link.phase() == LinkPhase::Stopped).await;
    until("motors off", 2.0, || !sim.truth().motors_on).await;
    until("on the ground", 3.0, || sim.truth().position[2] < 0.05).await;
    sim.shutdown().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_lost_link_gives_no_state_then_reconnects_in_the_air() {
    let sim = sim_at(0.0, 0.0);
    let mut link = airborne_link(&sim).await;
    fly(&mut link, 0.3, |_| Vec2::zeros()).await;
    sim.set_faults(Faults { disconnected: true, ..Faults::NONE });
    let lost_at = Instant::now();
    // The fleet reads no fresh state once the newest one is older than stale_after (0.3 s).
    let mut silent_since = None;
    while lost_at.elapsed() < Duration::from_millis(600) {
        match link.state() {
            Some(_) => silent_since = None,
            None => {
                silent_since.get_or_insert(Instant::now());
            }
        }
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    let silent = silent_since.expect("no state while disconnected");
    assert!(
        silent.duration_since(lost_at) < Duration::from_millis(400),
        "stale after {:?}",
        silent - lost_at
    );
    until("the link to reconnect", 1.0, || link.phase() == LinkPhase::Connecting).await;
    // Back within the watchdog's 2 s: still in the air, so the session resumes flying without a
    // take-off.
    sim.set_faults(Faults::NONE);
    until("flying again", 2.0 - lost_at.elapsed().as_secs_f64(), || link.phase() == LinkPhase::Flying).await;
    assert!(sim.truth().position[2] > 0.5, "still airborne: {:?}", sim.truth().position);
    until("a fresh state", 1.0, || link.state().is_some()).await;
    link.land();
    until("landed", 6.0, || link.phase() == LinkPhase::Landed).await;
    sim.shutdown().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn dropping_the_link_lands_the_crazyflie() {
    let sim = sim_at(0.0, 0.0);
    let link = airborne_link(&sim).await;
    drop(link);
    until("landed after the link is dropped", 6.0, || {
        let t = sim.truth();
        t.position[2] < 0.05 && !t.motors_on
    })
    .await;
    sim.shutdown().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_unreachable_crazyflie_stays_connecting_and_never_blocks() {
    // Nothing listens on this port: the session keeps retrying; the fleet side never waits.
    let socket = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
    let uri = format!("udp://{}", socket.local_addr().unwrap());
    drop(socket);
    let mut link = CrazyflieLink::spawn(&tokio::runtime::Handle::current(), &uri, RelayConfig::default());
    let t0 = Instant::now();
    for _ in 0..100 {
        assert!(link.state().is_none());
        link.send(Vec2::new(1.0, 0.0));
        link.land();
    }
    // A call that waited on the connection would take at least the UDP answer timeout (0.5 s).
    let limit = crazyflie::transport::UDP_ANSWER_TIMEOUT;
    assert!(t0.elapsed() < limit, "the fleet side blocked: {:?} for 300 calls", t0.elapsed());
    tokio::time::sleep(Duration::from_millis(500)).await;
    assert_eq!(link.phase(), LinkPhase::Connecting);
    assert_eq!(link.describe(), uri);
}
