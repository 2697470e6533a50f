//! The relay against what a real firmware keeps across client sessions, imitated by cfsim: the
//! default PID controller (which follows a full-state setpoint's position only), a previous
//! session's low-level setpoint that still outranks the high-level commander (the take-off would
//! be ignored), and a lock that only a reboot clears.
//!
//! Waits are for a condition with a generous deadline (a loaded 2-core CI machine may be slow).

use cfsim::{SimConfig, SimCrazyflie, SimHandle};
use crazyflie::{CrazyflieLink, RelayConfig};
use crazyflie_lib::{Crazyflie, NoTocCache};
use links::{Link, LinkPhase};
use std::time::{Duration, Instant};
use uav::Vec2;

/// Generous deadline for anything that takes a fraction of a second on an idle machine.
const PATIENCE: f64 = 20.0;

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

/// A client session of another program (crazyflie-lib directly), as a previous user left it.
async fn other_session(sim: &SimHandle) -> Crazyflie {
    let link = crazyflie::udp::connect(&sim.uri()).await.expect("udp link");
    Crazyflie::connect_from_link(link, NoTocCache).await.expect("connect")
}

/// Takes off with `config` and pushes along +x at 1 m/s² for 1 s, then brakes; returns how far
/// the Crazyflie moved along x.
async fn push_along_x(sim: &SimHandle, config: RelayConfig) -> f64 {
    let mut link = CrazyflieLink::spawn(&tokio::runtime::Handle::current(), &sim.uri(), config);
    until("flying", PATIENCE, || link.phase() == LinkPhase::Flying).await;
    until("a fresh state", PATIENCE, || link.state().is_some()).await;
    let start = sim.truth().position[0];
    let t0 = Instant::now();
    while t0.elapsed() < Duration::from_millis(2500) {
        let v = link.state().map_or(0.0, |s| s.v.x);
        let u = if t0.elapsed() < Duration::from_secs(1) { 1.0 } else { (-2.0 * v).clamp(-1.0, 1.0) };
        link.send(Vec2::new(u, 0.0));
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    let moved = sim.truth().position[0] - start;
    link.land();
    until("landed", PATIENCE, || link.phase() == LinkPhase::Landed).await;
    moved
}

/// The relay sets the controller its setpoints need; a Crazyflie left on its default PID creeps.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_relay_sets_the_controller_its_setpoints_need() {
    let sim = sim_at(0.0, 0.0);
    let kept =
        push_along_x(&sim, RelayConfig { takeoff_s: 1.0, controller: None, ..RelayConfig::default() }).await;
    assert!(kept.abs() < 0.3, "on PID the feed-forward is ignored: moved {kept} m");
    let set = push_along_x(&sim, RelayConfig { takeoff_s: 1.0, ..RelayConfig::default() }).await;
    assert!((0.6..1.6).contains(&set), "on Mellinger it follows: moved {set} m");
    sim.shutdown().await;
}

/// A previous session that ended on low-level setpoints without a notify-stop would have the
/// take-off ignored; the relay clears it first and the firmware confirms the take-off.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_previous_sessions_setpoint_does_not_block_the_take_off() {
    let sim = sim_at(0.0, 0.0);
    let previous = other_session(&sim).await;
    previous.commander.setpoint_stop().await.expect("stop setpoint");
    previous.disconnect().await;
    let config = RelayConfig { takeoff_s: 1.0, ..RelayConfig::default() };
    let link = CrazyflieLink::spawn(&tokio::runtime::Handle::current(), &sim.uri(), config);
    until("flying", PATIENCE, || link.phase() == LinkPhase::Flying).await;
    let truth = sim.truth();
    assert!(truth.motors_on && (truth.position[2] - 1.0).abs() < 0.15, "confirmed in the air: {truth:?}");
    assert_eq!(link.error(), None);
    drop(link);
    sim.shutdown().await;
}

/// A locked Crazyflie (an earlier emergency stop) is reported with the reason and never shown
/// taking off.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_locked_crazyflie_is_reported_and_not_flown() {
    let sim = sim_at(0.0, 0.0);
    let previous = other_session(&sim).await;
    previous.supervisor.send_emergency_stop().await.expect("stop");
    previous.disconnect().await;
    let link = CrazyflieLink::spawn(&tokio::runtime::Handle::current(), &sim.uri(), RelayConfig::default());
    until("the lock reported", PATIENCE, || {
        assert!(!matches!(link.phase(), LinkPhase::TakingOff | LinkPhase::Flying), "{:?}", link.phase());
        link.error().is_some_and(|e| e.contains("locked") && e.contains("reboot"))
    })
    .await;
    assert!(!sim.truth().motors_on);
    sim.reboot();
    until("flying after the reboot", PATIENCE, || link.phase() == LinkPhase::Flying).await;
    drop(link);
    sim.shutdown().await;
}

/// The firmware's own report reaches the fleet's side: supervisor bits, battery, link quality.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_firmware_report_reaches_the_fleet() {
    let sim = sim_at(0.0, 0.0);
    let config = RelayConfig { takeoff_s: 1.0, ..RelayConfig::default() };
    let link = CrazyflieLink::spawn(&tokio::runtime::Handle::current(), &sim.uri(), config);
    until("flying", PATIENCE, || link.phase() == LinkPhase::Flying).await;
    until("a link quality", PATIENCE, || link.vehicle().is_some_and(|r| r.link_quality.is_some())).await;
    let report = link.vehicle().expect("a Crazyflie has a firmware");
    let info = report.supervisor_info.expect("supervisor.info logged");
    let bits = cfsim::firmware::supervisor::IS_ARMED | cfsim::firmware::supervisor::IS_FLYING;
    assert_eq!(info & bits, bits, "armed and flying: {info:#06x}");
    assert!(report.battery_v.is_some_and(|v| (3.0..4.3).contains(&v)), "{report:?}");
    // Every 10 ms sample arrives on loopback; the bound allows for a loaded machine.
    assert!(report.link_quality.is_some_and(|q| q > 0.5 && q <= 1.0), "{report:?}");
    drop(link);
    sim.shutdown().await;
}

/// A firmware built to need arming (`CONFIG_MOTORS_REQUIRE_ARMING`, the Crazyflie 2.1 Brushless)
/// is armed through the supervisor before the take-off.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_crazyflie_that_needs_arming_is_armed_then_flown() {
    let config =
        SimConfig { initial_position: [0.0, 0.0, 0.0], require_arming: true, ..SimConfig::default() };
    let sim = SimCrazyflie::spawn("127.0.0.1:0".parse().unwrap(), config).unwrap();
    let relay = RelayConfig { takeoff_s: 1.0, ..RelayConfig::default() };
    let link = CrazyflieLink::spawn(&tokio::runtime::Handle::current(), &sim.uri(), relay);
    until("flying", PATIENCE, || link.phase() == LinkPhase::Flying).await;
    let info = link.vehicle().and_then(|r| r.supervisor_info).expect("supervisor.info");
    assert_ne!(info & cfsim::firmware::supervisor::IS_ARMED, 0, "armed: {info:#06x}");
    assert!((sim.truth().position[2] - 1.0).abs() < 0.15, "{:?}", sim.truth());
    drop(link);
    sim.shutdown().await;
}
