//! End to end: flying the simulator with the official client's commanders over UDP.

mod common;

use std::time::{Duration, Instant};

use cfsim::FlightMode;
use common::*;

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn high_level_take_off_and_land() {
    let sim = sim_at([0.5, 0.5, 0.0]);
    let cf = connect(&sim).await;
    assert!(!sim.truth().motors_on);

    let start = Instant::now();
    cf.high_level_commander.take_off(1.0, None, 2.0, None).await.expect("take off");
    let took =
        eventually(PATIENCE, || (sim.truth().position[2] - 1.0).abs() < 0.03).await.expect("reaches 1 m");
    // The take-off lasts its 2 s of simulated (= wall-clock) time: never less; more only by how
    // late a loaded machine runs the simulation, hence the loose upper bound.
    assert!(took < Duration::from_secs(8), "took {took:?}");
    assert!(start.elapsed() > Duration::from_millis(1500), "too fast for a 2 s take-off");
    let t = sim.truth();
    assert_eq!(t.mode, FlightMode::HighLevel);
    assert!(t.motors_on && dist([t.position[0], t.position[1], 0.0], [0.5, 0.5, 0.0]) < 0.01);
    // The log reports the same height.
    let stream = log_stream(&cf, &["stateEstimate.z"], 20).await;
    let z = stream.next().await.expect("log").data["stateEstimate.z"].to_f64_lossy();
    assert!((z - 1.0).abs() < 0.05, "logged z {z}");

    cf.high_level_commander.go_to(1.0, 0.5, 1.0, 0.0, 1.0, false, false, None).await.expect("go to");
    eventually(PATIENCE, || dist(sim.truth().position, [1.0, 0.5, 1.0]) < 0.03)
        .await
        .expect("reaches the go-to target");

    cf.high_level_commander.land(0.0, None, 1.5, None).await.expect("land");
    eventually(PATIENCE, || {
        let t = sim.truth();
        !t.motors_on && t.position[2] == 0.0
    })
    .await
    .expect("lands and stops the motors");
    assert_eq!(sim.truth().mode, FlightMode::Idle);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn full_state_setpoints_track_a_line() {
    let sim = sim_at([0.0, 0.0, 0.0]);
    let cf = connect(&sim).await;
    // The feed-forward needs Mellinger, as on the firmware (PID, the default, holds positions).
    cf.param.set("stabilizer.controller", 2u8).await.expect("controller");
    take_off(&cf, &sim, 1.0).await;

    // x(t) = 0.5 t for 2 s, streamed at 20 Hz.
    let start = Instant::now();
    let mut worst: f64 = 0.0;
    let mut k = 0u32;
    while start.elapsed() < Duration::from_secs(2) {
        let t = f64::from(k) * 0.05;
        let x = 0.5 * t as f32;
        cf.commander
            .setpoint_full_state([x, 0.0, 1.0], [0.5, 0.0, 0.0], [0.0; 3], [0.0, 0.0, 0.0, 1.0], [0.0; 3])
            .await
            .expect("setpoint");
        if k > 10 {
            // Compare with where the reference was one period ago (the truth lags a tick).
            let truth = sim.truth();
            worst = worst.max((truth.position[0] - (t - 0.05) * 0.5).abs());
            assert_eq!(truth.mode, FlightMode::LowLevel);
        }
        k += 1;
        tokio::time::sleep_until((start + Duration::from_millis(50 * u64::from(k))).into()).await;
    }
    assert!(worst < 0.1, "tracking error {worst}");
    let t = sim.truth();
    assert!((t.velocity[0] - 0.5).abs() < 0.1 && (t.position[2] - 1.0).abs() < 0.05, "{t:?}");

    // Hand back to the high-level commander and land. (A loaded machine may run a step of the
    // simulation between the two packets: with no setpoint valid, the motors cut until the land
    // arrives, so wait for down and off, not just off.)
    cf.commander.notify_setpoint_stop(0).await.expect("notify");
    cf.high_level_commander.land(0.0, None, 1.0, None).await.expect("land");
    eventually(PATIENCE, || {
        let t = sim.truth();
        !t.motors_on && t.position[2] < 0.02
    })
    .await
    .expect("landed");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn velocity_world_setpoints() {
    let sim = sim_at([0.0, 0.0, 0.0]);
    let cf = connect(&sim).await;
    take_off(&cf, &sim, 0.8).await;
    let y0 = sim.truth().position[1];
    let start = Instant::now();
    for k in 1..=30u64 {
        cf.commander.setpoint_velocity_world(0.0, 0.4, 0.0, 0.0).await.expect("setpoint");
        tokio::time::sleep_until((start + Duration::from_millis(50 * k)).into()).await;
    }
    let t = sim.truth();
    assert_eq!(t.mode, FlightMode::LowLevel);
    assert!((t.velocity[1] - 0.4).abs() < 0.03, "{t:?}");
    // 1.5 s at 0.4 m/s, minus the ramp-up.
    let moved = t.position[1] - y0;
    assert!((0.45..0.65).contains(&moved), "moved {moved}");
    assert!((t.position[2] - 0.8).abs() < 0.05);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn external_position_is_received() {
    let sim = sim_at([0.0; 3]);
    let cf = connect(&sim).await;
    assert_eq!(sim.last_external_position(), None);
    for k in 0..5 {
        let p = [1.0 + k as f32, -2.5, 0.75];
        cf.localization.external_pose.send_external_position(p).await.expect("send");
    }
    eventually(PATIENCE, || sim.external_position_count() == 5).await.expect("all received");
    assert_eq!(sim.last_external_position(), Some([5.0, -2.5, 0.75]));
    // It is also visible through the log.
    let stream = log_stream(&cf, &["ext_pos.X", "ext_pos.Z"], 10).await;
    let d = stream.next().await.expect("log").data;
    assert_eq!((d["ext_pos.X"].to_f64_lossy(), d["ext_pos.Z"].to_f64_lossy()), (5.0, 0.75));
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn emergency_stop_drops_it_until_reboot() {
    let sim = sim_at([0.0; 3]);
    let cf = connect(&sim).await;
    take_off(&cf, &sim, 1.0).await;
    cf.supervisor.send_emergency_stop().await.expect("emergency stop");
    eventually(PATIENCE, || {
        let t = sim.truth();
        !t.motors_on && t.position[2] == 0.0
    })
    .await
    .expect("falls to the ground");
    assert_eq!(sim.truth().mode, FlightMode::Locked);
    // Setpoints are ignored while locked.
    for _ in 0..5 {
        cf.commander.setpoint_position(0.0, 0.0, 1.0, 0.0).await.expect("setpoint");
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    assert!(!sim.truth().motors_on);
    tokio::time::sleep(Duration::from_millis(150)).await;
    let info = cf.supervisor.read_bitfield().await.expect("bitfield");
    assert!(info.is_locked() && !info.can_fly());

    sim.reboot();
    cf.commander.setpoint_position(0.0, 0.0, 1.0, 0.0).await.expect("setpoint");
    eventually(PATIENCE, || sim.truth().motors_on).await.expect("flies again");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn emergency_stop_watchdog_fires() {
    let sim = sim_at([0.0; 3]);
    let cf = connect(&sim).await;
    take_off(&cf, &sim, 0.5).await;
    cf.supervisor.send_emergency_stop_watchdog().await.expect("arm watchdog");
    let fired =
        eventually(PATIENCE, || sim.truth().mode == FlightMode::Locked).await.expect("watchdog fires");
    // The watchdog's 1 s is the property: never before it; after it only as late as a loaded
    // machine runs the simulation, hence the loose upper bound.
    assert!(fired > Duration::from_millis(900) && fired < Duration::from_secs(5), "{fired:?}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn setpoint_watchdog_levels_out_then_stops() {
    let sim = sim_at([0.0; 3]);
    let cf = connect(&sim).await;
    take_off(&cf, &sim, 1.0).await;
    for _ in 0..10 {
        cf.commander.setpoint_position(0.2, 0.0, 1.0, 0.0).await.expect("setpoint");
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    cf.commander.setpoint_position(0.2, 0.0, 1.0, 0.0).await.expect("setpoint");
    assert_eq!(sim.truth().mode, FlightMode::LowLevel);
    // The watchdog's 0.5 s and 2 s are the properties: never before them (the simulation runs on
    // wall-clock time); after them only as late as a loaded machine runs it, hence the loose upper
    // bounds.
    let leveled =
        eventually(PATIENCE, || sim.truth().mode == FlightMode::Leveling).await.expect("levels out");
    assert!(leveled > Duration::from_millis(400) && leveled < Duration::from_secs(3), "{leveled:?}");
    assert!(sim.truth().motors_on && (sim.truth().position[2] - 1.0).abs() < 0.05);
    let stopped = eventually(PATIENCE, || !sim.truth().motors_on).await.expect("stops");
    assert!(stopped + leveled > Duration::from_millis(1900), "{stopped:?}");
    assert!(stopped + leveled < Duration::from_secs(6), "{stopped:?}");
    eventually(PATIENCE, || sim.truth().position[2] == 0.0).await.expect("falls");
}
