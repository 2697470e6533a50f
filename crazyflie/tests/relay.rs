//! The relay against a simulated Crazyflie (cfsim) over real UDP sockets: connect, take off, follow
//! the fleet's commands, land, emergency stop (confirmed by the Crazyflie, resent until it is, and
//! reported when it never is), and survive a link loss.
//!
//! Waits are for a condition with a generous deadline (a loaded 2-core CI machine may be slow);
//! only a test's property is a time window, and then its bound says why.

use cfsim::{Faults, FlightMode, SimConfig, SimCrazyflie, SimHandle};
use crazyflie::{CrazyflieLink, RelayConfig};
use links::{Link, LinkPhase};
use std::time::{Duration, Instant};
use uav::Vec2;

fn sim_at(x: f64, y: f64) -> SimHandle {
    let config = SimConfig { initial_position: [x, y, 0.0], ..SimConfig::default() };
    SimCrazyflie::spawn("127.0.0.1:0".parse().unwrap(), config).unwrap()
}

/// Generous deadline for anything that takes a fraction of a second on an idle machine.
const PATIENCE: f64 = 20.0;

/// Polls `f` every 10 ms until it holds, for at most `seconds`.
async fn until(what: &str, seconds: f64, mut f: impl FnMut() -> bool) {
    let end = Instant::now() + Duration::from_secs_f64(seconds);
    while !f() {
        assert!(Instant::now() < end, "timed out after {seconds} s waiting for {what}");
        tokio::time::sleep(Duration::from_millis(10)).await;
    }
}

/// The link never shows the vehicle down (landed or stopped) while the simulator's motors run.
/// The phase is read first: a Crazyflie confirmed down stays down, so the truth read after it
/// must agree.
fn check_never_down_too_early(link: &CrazyflieLink, sim: &SimHandle) {
    let phase = link.phase();
    let truth = sim.truth();
    if matches!(phase, LinkPhase::Landed | LinkPhase::Stopped) {
        assert!(!truth.motors_on, "{phase:?} shown while the motors are on: {truth:?}");
    }
}

/// Waits (up to [`PATIENCE`]) for `phase`, checking [`check_never_down_too_early`] all along.
async fn until_phase(link: &CrazyflieLink, sim: &SimHandle, phase: LinkPhase) {
    until(&format!("{phase:?}"), PATIENCE, || {
        check_never_down_too_early(link, sim);
        link.phase() == phase
    })
    .await;
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
    airborne_link_with(sim, RelayConfig { takeoff_s: 1.0, ..RelayConfig::default() }).await
}

async fn airborne_link_with(sim: &SimHandle, config: RelayConfig) -> CrazyflieLink {
    let mut link = CrazyflieLink::spawn(&tokio::runtime::Handle::current(), &sim.uri(), config);
    assert_eq!(link.phase(), LinkPhase::Connecting);
    until("take-off to start", PATIENCE, || link.phase() == LinkPhase::TakingOff).await;
    until("flying", PATIENCE, || link.phase() == LinkPhase::Flying).await;
    until("1 m up", PATIENCE, || (sim.truth().position[2] - 1.0).abs() < 0.1).await;
    until("a fresh state", PATIENCE, || link.state().is_some()).await;
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
    until("a fresh state", PATIENCE, || {
        link.state().is_some_and(|s| (s.p.x - sim.truth().position[0]).abs() < 0.1)
    })
    .await;

    link.land();
    until_phase(&link, &sim, LinkPhase::Landing).await;
    // Landed only once the Crazyflie's log says it is down with its motors off.
    until_phase(&link, &sim, LinkPhase::Landed).await;
    let truth = sim.truth();
    assert!(truth.position[2] < 0.05 && !truth.motors_on, "landed: {:?}", truth.position);
    assert_eq!((link.unconfirmed_commands(), link.error()), (0, None));
    sim.shutdown().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn emergency_stop_cuts_the_motors() {
    let sim = sim_at(0.0, 0.0);
    let mut link = airborne_link(&sim).await;
    link.emergency_stop();
    until_phase(&link, &sim, LinkPhase::Stopped).await;
    assert!(!sim.truth().motors_on, "stopped, so the motors are off");
    assert_eq!(sim.truth().mode, FlightMode::Locked);
    until("on the ground", PATIENCE, || sim.truth().position[2] < 0.05).await;
    assert_eq!((link.unconfirmed_commands(), link.error()), (0, None));
    sim.shutdown().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_ignored_stop_is_resent_and_shown_stopping_until_the_crazyflie_confirms() {
    let sim = sim_at(0.0, 0.0);
    // A long bound: this test is about the resending, not about giving up.
    let config = RelayConfig { takeoff_s: 1.0, stop_confirm_s: 60.0, ..RelayConfig::default() };
    let mut link = airborne_link_with(&sim, config).await;
    sim.set_faults(Faults { ignore_stop: true, ..Faults::NONE });
    link.emergency_stop();
    until_phase(&link, &sim, LinkPhase::Stopping).await;
    // Each send is two packets (supervisor and localization ports): wait for three sends.
    until("the stop to be resent", PATIENCE, || {
        check_never_down_too_early(&link, &sim);
        sim.stats().stops_ignored >= 6
    })
    .await;
    assert_eq!(link.phase(), LinkPhase::Stopping, "not confirmed, so not stopped");
    assert!(sim.truth().motors_on, "the simulator ignored the stop");
    assert!(link.phase().airborne(), "a stopping Crazyflie is still an obstacle");
    // The Crazyflie obeys again: the next copy locks it and its log confirms.
    sim.set_faults(Faults::NONE);
    until_phase(&link, &sim, LinkPhase::Stopped).await;
    let truth = sim.truth();
    assert!(!truth.motors_on && truth.mode == FlightMode::Locked, "{truth:?}");
    assert!(sim.stats().emergency_stops > sim.stats().stops_ignored, "a stop got through");
    assert_eq!((link.unconfirmed_commands(), link.error()), (0, None));
    sim.shutdown().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_crazyflie_that_never_confirms_the_stop_is_reported_and_never_shown_stopped() {
    let sim = sim_at(0.0, 0.0);
    let mut link = airborne_link(&sim).await;
    sim.set_faults(Faults { ignore_stop: true, ..Faults::NONE });
    link.emergency_stop();
    // Given up after the default 3 s: reported, still shown stopping.
    until("the stop to be given up", PATIENCE, || {
        check_never_down_too_early(&link, &sim);
        link.unconfirmed_commands() > 0
    })
    .await;
    assert_eq!(link.unconfirmed_commands(), 1);
    assert_eq!(link.error().as_deref(), Some("emergency stop not confirmed after 3 s"));
    assert_eq!(link.phase(), LinkPhase::Stopping);
    assert!(sim.stats().stops_ignored >= 4, "resent before giving up: {:?}", sim.stats());
    for _ in 0..50 {
        assert_eq!(link.phase(), LinkPhase::Stopping, "never shown stopped without a confirmation");
        assert!(sim.truth().motors_on);
        tokio::time::sleep(Duration::from_millis(10)).await;
    }
    // A land request does not override the stop.
    link.land();
    tokio::time::sleep(Duration::from_millis(100)).await;
    assert_eq!(link.phase(), LinkPhase::Stopping);
    // Asked again once the Crazyflie obeys: confirmed, and the count of unconfirmed stops stays.
    sim.set_faults(Faults::NONE);
    link.emergency_stop();
    until_phase(&link, &sim, LinkPhase::Stopped).await;
    assert!(!sim.truth().motors_on);
    assert_eq!(link.unconfirmed_commands(), 1);
    sim.shutdown().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_lost_link_gives_no_state_then_reconnects_in_the_air() {
    let sim = sim_at(0.0, 0.0);
    // It hovers under the high-level commander, which (unlike low-level setpoints) has no
    // watchdog: it is still in the air however long the reconnection takes on a loaded machine.
    let mut link = airborne_link(&sim).await;
    sim.set_faults(Faults { disconnected: true, ..Faults::NONE });
    let lost_at = Instant::now();
    // The fleet reads no fresh state once the newest one is older than stale_after (0.3 s). None
    // also means "nothing new since the last call" (a late sample may still follow): wait for a
    // silence that lasts.
    let mut silent_since: Option<Instant> = None;
    while silent_since.is_none_or(|t| t.elapsed() < Duration::from_millis(500)) {
        assert!(lost_at.elapsed() < Duration::from_secs_f64(PATIENCE), "states kept coming");
        match link.state() {
            Some(_) => silent_since = None,
            None => {
                silent_since.get_or_insert_with(Instant::now);
            }
        }
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    let silent = silent_since.expect("set above") - lost_at;
    // The property is stale_after (0.3 s); the bound allows for a slow test thread.
    assert!(silent < Duration::from_secs(2), "stale after {silent:?}");
    until("the link to reconnect", PATIENCE, || link.phase() == LinkPhase::Connecting).await;
    sim.set_faults(Faults::NONE);
    // Found in the air: the session resumes flying without a take-off.
    until("flying again", PATIENCE, || link.phase() == LinkPhase::Flying).await;
    assert!(sim.truth().position[2] > 0.5, "still airborne: {:?}", sim.truth().position);
    until("a fresh state", PATIENCE, || link.state().is_some()).await;
    link.land();
    until_phase(&link, &sim, LinkPhase::Landed).await;
    sim.shutdown().await;
}

/// A gap in the state stream shorter than `relog_after` (1 s) and the link's own silence timeout:
/// the fleet reads no state meanwhile, but the session is kept (no error, no reconnection, which a
/// lossy link might not get through) and flies on when the state comes back.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_gap_in_the_state_keeps_the_session_and_it_flies_on() {
    let sim = sim_at(0.0, 0.0);
    let mut link = airborne_link(&sim).await;
    sim.set_faults(Faults { loss_down: 1.0, ..Faults::NONE });
    let gap_from = Instant::now();
    let mut stale_seen = false;
    while gap_from.elapsed() < Duration::from_millis(550) {
        stale_seen |= gap_from.elapsed() > Duration::from_millis(350) && link.state().is_none();
        assert_eq!(link.error(), None, "the session was ended during the gap");
        tokio::time::sleep(Duration::from_millis(10)).await;
    }
    sim.set_faults(Faults::NONE);
    assert!(stale_seen, "no state reached the fleet during the gap");
    until("a fresh state after the gap", PATIENCE, || link.state().is_some()).await;
    assert_eq!(link.phase(), LinkPhase::Flying, "the session flew on");
    assert_eq!(link.error(), None, "the session was not ended");
    sim.shutdown().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn dropping_the_link_lands_the_crazyflie() {
    let sim = sim_at(0.0, 0.0);
    let link = airborne_link(&sim).await;
    drop(link);
    until("landed after the link is dropped", PATIENCE, || {
        let t = sim.truth();
        t.position[2] < 0.05 && !t.motors_on
    })
    .await;
    sim.shutdown().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_detached_link_closes_without_landing_and_another_link_flies_on() {
    // A handover between two regions: the old owner detaches, the new owner opens its own link.
    let sim = sim_at(0.0, 0.0);
    let mut old = airborne_link(&sim).await;
    assert!(!old.detached(), "a flying link is not detached");
    old.detach();
    until("the connection closed", PATIENCE, || old.detached()).await;
    drop(old);
    // Closed for good: no reconnection, no landing; the firmware holds its last setpoint.
    tokio::time::sleep(Duration::from_millis(300)).await;
    let held = sim.truth();
    assert!(held.motors_on && held.position[2] > 0.8, "still in the air after the detach: {held:?}");
    let config = RelayConfig { takeoff_s: 1.0, ..RelayConfig::default() };
    let mut new = CrazyflieLink::spawn(&tokio::runtime::Handle::current(), &sim.uri(), config);
    // Found in the air: flying without a take-off, and its commands move it.
    until("the new link flying", PATIENCE, || {
        assert_ne!(new.phase(), LinkPhase::TakingOff, "the new owner took off again");
        new.phase() == LinkPhase::Flying
    })
    .await;
    let start = sim.truth().position;
    fly(&mut new, 1.0, |_| Vec2::new(1.0, 0.0)).await;
    fly(&mut new, 1.0, |s| s.map_or(Vec2::zeros(), |s| -s.v * 2.0)).await;
    let moved = sim.truth().position[0] - start[0];
    assert!(moved > 0.3, "the new owner's commands moved it {moved} m");
    assert!(sim.truth().motors_on, "never came down");
    new.land();
    until_phase(&new, &sim, LinkPhase::Landed).await;
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
