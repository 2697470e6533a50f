//! Simulated Crazyflies (cfsim) flown through the real CRTP/UDP path: by `airroads run --link
//! cfsim`, and by the server (take-off, flight to the goals, land, emergency stop, a link loss, and
//! landing on shutdown). Ground truth comes from the simulators themselves.
//!
//! Waits are for a condition with a generous deadline ([`PATIENCE`]): a loaded 2-core CI machine
//! may take seconds for what takes a fraction of one on an idle one.

mod support;

use cfsim::{Faults, SimConfig, SimCrazyflie, SimHandle};
use serde_json::Value;
use std::process::Command;
use std::time::{Duration, Instant};
use support::{Running, config, repo, shipped, start};

/// Deadline for anything that takes a few seconds on an idle machine (s).
const PATIENCE: f64 = 30.0;

/// Simulated Crazyflies on the ground at each UAV's start; the scenario's UAVs get their links.
fn with_sims(mut scenario: Value) -> (Value, Vec<SimHandle>) {
    let mut sims = Vec::new();
    let delta = scenario["params"]["delta"].as_f64().unwrap_or(5.0);
    for uav in scenario["uavs"].as_array_mut().unwrap() {
        let start = [uav["start"][0].as_f64().unwrap(), uav["start"][1].as_f64().unwrap(), 0.0];
        let sim_config =
            SimConfig { initial_position: start, max_accel: 1.2 * delta, ..SimConfig::default() };
        let sim = SimCrazyflie::spawn("127.0.0.1:0".parse().unwrap(), sim_config).unwrap();
        uav["link"] = Value::String(sim.uri());
        sims.push(sim);
    }
    (scenario, sims)
}

fn uav_field<'a>(state: &'a Value, key: &str) -> Vec<&'a Value> {
    state["uavs"].as_array().unwrap().iter().map(|u| &u[key]).collect()
}

/// The server never reports a UAV `landed` or `stopped` (phase or status) while its simulator's
/// motors run. The state is read before the truth: a Crazyflie confirmed down stays down.
fn check_never_down_too_early(state: &Value, sims: &[SimHandle]) {
    for u in state["uavs"].as_array().unwrap() {
        let down = ["landed", "stopped"].iter().any(|d| u["phase"] == *d || u["status"] == *d);
        if !down {
            continue;
        }
        let sim = sims.iter().find(|s| u["link"] == s.uri().as_str()).expect("a simulator per UAV");
        let truth = sim.truth();
        assert!(!truth.motors_on, "{} reported {} with its motors on: {truth:?}", u["id"], u["phase"]);
    }
}

/// Waits (up to [`PATIENCE`]) until every UAV's phase is `phase`, sampling the server and the
/// simulators meanwhile ([`check_never_down_too_early`]); returns the last state.
async fn until_every_phase(server: &Running, sims: &[SimHandle], phase: &str) -> Value {
    let deadline = Instant::now() + Duration::from_secs_f64(PATIENCE);
    loop {
        let state = server.get("/api/state").await;
        check_never_down_too_early(&state, sims);
        if uav_field(&state, "phase").iter().all(|p| *p == phase) {
            return state;
        }
        assert!(Instant::now() < deadline, "not every UAV {phase} within {PATIENCE} s: {state}");
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
}

/// Waits (up to [`PATIENCE`]) until every simulator holds `f`.
async fn until_every_sim(what: &str, sims: &[SimHandle], f: impl Fn(&cfsim::Truth) -> bool) {
    let deadline = Instant::now() + Duration::from_secs_f64(PATIENCE);
    while !sims.iter().all(|s| f(&s.truth())) {
        let truths: Vec<_> = sims.iter().map(|s| s.truth()).collect();
        assert!(Instant::now() < deadline, "not every simulator {what} within {PATIENCE} s: {truths:?}");
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
}

/// Smallest horizontal distance between two simulators' true positions.
fn min_true_distance(sims: &[SimHandle]) -> f64 {
    let p: Vec<[f64; 3]> = sims.iter().map(|s| s.truth().position).collect();
    let mut min = f64::INFINITY;
    for i in 0..p.len() {
        for j in i + 1..p.len() {
            min = min.min((p[i][0] - p[j][0]).hypot(p[i][1] - p[j][1]));
        }
    }
    min
}

#[test]
fn run_with_link_cfsim_flies_lab3_safely_like_the_in_process_run() {
    let dir = std::env::temp_dir().join(format!("airroads-cfsim-run-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let scenario = repo().join("scenarios/lab3.json");
    let run = |link: &str| {
        let out = dir.join(format!("{link}.json"));
        let status = Command::new(env!("CARGO_BIN_EXE_airroads"))
            .args(["run", scenario.to_str().unwrap(), "--policy", "pd", "--link", link, "--out"])
            .arg(&out)
            .output()
            .unwrap();
        let metrics: Value = serde_json::from_slice(&std::fs::read(&out).unwrap()).unwrap();
        (status, metrics)
    };
    let (status, over_crtp) = run("cfsim");
    assert!(
        status.status.success(),
        "{}\n{}",
        String::from_utf8_lossy(&status.stdout),
        String::from_utf8_lossy(&status.stderr)
    );
    let (_, in_process) = run("sim");
    // The same METRICS.json keys, and the same properties: safe, all arrived.
    let keys = |m: &Value| m.as_object().unwrap().keys().cloned().collect::<Vec<_>>();
    assert_eq!(keys(&over_crtp), keys(&in_process));
    for m in [&over_crtp, &in_process] {
        assert_eq!(m["safe"], true, "{m}");
        assert_eq!(m["all_arrived"], true, "{m}");
        assert!(m["min_collision_margin_m"].as_f64().unwrap() >= 0.3, "{m}");
    }
    std::fs::remove_dir_all(&dir).ok();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_server_flies_three_crazyflies_to_their_goals_and_lands_them() {
    let (scenario, sims) = with_sims(shipped("lab3.json"));
    let server = start(config(&scenario)).await;
    let state = until_every_phase(&server, &sims, "flying").await;
    assert!(uav_field(&state, "link").iter().all(|l| l.as_str().unwrap().starts_with("udp://")));
    until_every_sim("at 1 m", &sims, |t| (t.position[2] - 1.0).abs() < 0.15).await;
    let deadline = Instant::now() + Duration::from_secs(60);
    let mut min_distance = f64::INFINITY;
    loop {
        min_distance = min_distance.min(min_true_distance(&sims));
        let state = server.get("/api/state").await;
        if uav_field(&state, "arrived").iter().all(|a| **a == Value::Bool(true)) {
            break;
        }
        assert!(Instant::now() < deadline, "not all arrived within 60 s: {state}");
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    assert!(min_distance >= 0.3, "true distance {min_distance} m < D_c");
    // Each Crazyflie's own report: its supervisor flying, its battery, the share of its state log
    // that arrives (every sample, on loopback; the bound allows for a loaded machine).
    for id in ["cf1", "cf2", "cf3"] {
        let f = &server.get(&format!("/api/uavs/{id}")).await["firmware"];
        assert!(f["flying"] == true && f["armed"] == true && f["locked"] == false, "{id}: {f}");
        assert!(f["battery_v"].as_f64().is_some_and(|v| (3.0..4.3).contains(&v)), "{id}: {f}");
        assert!(f["link_quality"].as_f64().is_some_and(|q| q > 0.5), "{id}: {f}");
    }
    let links = &server.get("/api/metrics").await["links"];
    assert_eq!((links["crazyflies"].as_u64(), links["locked"].as_u64()), (Some(3), Some(0)), "{links}");

    let (status, body) = server.call("POST", "/api/fleet/land", None).await;
    assert_eq!(status, 200, "{body}");
    // Landed only once each Crazyflie's log says it is down with its motors off.
    let state = until_every_phase(&server, &sims, "landed").await;
    assert!(uav_field(&state, "status").iter().all(|p| *p == "landed"), "{state}");
    for sim in &sims {
        let t = sim.truth();
        assert!(t.position[2] < 0.05 && !t.motors_on, "not down: {:?}", t.position);
    }
    server.stop().await;
    for sim in sims {
        sim.shutdown().await;
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_lost_crazyflie_is_avoided_and_the_fleet_stays_safe() {
    let (scenario, sims) = with_sims(shipped("lab3.json"));
    let server = start(config(&scenario)).await;
    until_every_phase(&server, &sims, "flying").await;
    // Fly a little first (not a window anything depends on).
    tokio::time::sleep(Duration::from_secs(2)).await;
    // cf1 goes out of range mid-flight, for 1 s and until the server reported it lost: no states,
    // no setpoints reach it. (Out for longer than its commander watchdog's 2 s, it locks and falls,
    // as the firmware does, and is avoided where it fell, reported locked until a reboot.)
    sims[0].set_faults(Faults { disconnected: true, ..Faults::NONE });
    let lost_at = Instant::now();
    let mut seen_lost = false;
    let mut min_distance = f64::INFINITY;
    while lost_at.elapsed() < Duration::from_millis(1000) || !seen_lost {
        assert!(lost_at.elapsed() < Duration::from_secs_f64(PATIENCE), "cf1 never reported lost");
        let state = server.get("/api/uavs/cf1").await;
        seen_lost |= state["status"] == "lost" && state["lost"] == true;
        min_distance = min_distance.min(min_true_distance(&sims));
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    sims[0].set_faults(Faults::NONE);
    let deadline = Instant::now() + Duration::from_secs_f64(PATIENCE);
    while Instant::now() < deadline {
        min_distance = min_distance.min(min_true_distance(&sims));
        let cf1 = server.get("/api/uavs/cf1").await;
        if cf1["phase"] == "flying" && cf1["lost"] == false {
            break;
        }
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    let cf1 = server.get("/api/uavs/cf1").await;
    assert_eq!(cf1["lost"], false, "cf1 did not come back: {cf1}");
    for _ in 0..100 {
        min_distance = min_distance.min(min_true_distance(&sims));
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    assert!(min_distance >= 0.3, "true distance {min_distance} m < D_c");

    let (status, _) = server.call("POST", "/api/fleet/stop", None).await;
    assert_eq!(status, 200);
    // `stopping` until each Crazyflie's log confirms it is locked with its motors off; never
    // `stopped` before.
    let state = until_every_phase(&server, &sims, "stopped").await;
    assert!(uav_field(&state, "status").iter().all(|p| *p == "stopped"), "{state}");
    for sim in &sims {
        let t = sim.truth();
        assert!(!t.motors_on && t.mode == cfsim::FlightMode::Locked, "not stopped: {t:?}");
    }
    // The firmware says locked; so do the UAVs' reports and the metrics.
    let deadline = Instant::now() + Duration::from_secs_f64(PATIENCE);
    while server.get("/api/metrics").await["links"]["locked"] != 3 {
        assert!(Instant::now() < deadline, "{}", server.get("/api/metrics").await["links"]);
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    assert_eq!(server.get("/api/uavs/cf2").await["firmware"]["locked"], true);
    server.stop().await;
    for sim in sims {
        sim.shutdown().await;
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn shutdown_lands_every_crazyflie_before_the_server_exits() {
    let (scenario, sims) = with_sims(shipped("lab3.json"));
    let server = start(config(&scenario)).await;
    until_every_phase(&server, &sims, "flying").await;
    let (status, body) = server.call("POST", "/api/uavs/cf2/land", None).await;
    assert_eq!(status, 200, "{body}");
    let (status, _) = server.call("POST", "/api/uavs/nope/land", None).await;
    assert_eq!(status, 404);
    server.stop().await;
    for sim in &sims {
        let t = sim.truth();
        assert!(t.position[2] < 0.05 && !t.motors_on, "not landed at shutdown: {:?}", t.position);
    }
    for sim in sims {
        sim.shutdown().await;
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn motion_capture_poses_reach_their_crazyflie_as_external_positions() {
    use engine::mocap::ingest;
    use std::sync::atomic::Ordering::Relaxed;
    let (scenario, sims) = with_sims(shipped("lab3.json"));
    let server = airroads_server::serve::Server::start(config(&scenario)).unwrap();
    let socket = tokio::net::UdpSocket::bind("127.0.0.1:0").await.unwrap();
    let mocap_addr = socket.local_addr().unwrap();
    // The server's own counters, as `/api/metrics` shows them (`serve --mocap` passes the same).
    let counters = server.state().mocap.clone();
    tokio::spawn(ingest(socket, server.mocap().clone(), counters.clone(), Vec::new()));
    // The Crazyflie links register once created; wait until cf2 is connected.
    let deadline = Instant::now() + Duration::from_secs_f64(PATIENCE);
    while server
        .state()
        .engine
        .snapshots
        .borrow()
        .uavs
        .iter()
        .any(|u| u.phase == links::LinkPhase::Connecting)
    {
        assert!(Instant::now() < deadline, "the Crazyflies did not connect");
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    let bridge = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
    let mut sent = 0;
    let deadline = Instant::now() + Duration::from_secs_f64(PATIENCE);
    while sims[1].external_position_count() == 0 {
        assert!(Instant::now() < deadline, "no external position reached cf2");
        let pose = serde_json::json!({"id": "cf2", "t": sent as f64 * 0.01, "p": [1.25, -0.5, 0.75]});
        bridge.send_to(pose.to_string().as_bytes(), mocap_addr).unwrap();
        sent += 1;
        tokio::time::sleep(Duration::from_millis(10)).await;
    }
    assert_eq!(sims[1].last_external_position(), Some([1.25, -0.5, 0.75]));
    assert_eq!(sims[0].external_position_count(), 0, "cf1's pose went elsewhere");
    // Unknown ids and garbage are counted, never forwarded, and never stop the ingestion.
    bridge.send_to(br#"{"id": "nobody", "t": 0, "p": [0, 0, 1]}"#, mocap_addr).unwrap();
    bridge.send_to(b"\xff garbage", mocap_addr).unwrap();
    bridge.send_to(br#"{"id": "cf2", "t": 1, "p": [NaN, 0, 1]}"#, mocap_addr).unwrap();
    let deadline = Instant::now() + Duration::from_secs_f64(PATIENCE);
    while counters.unrouted.load(Relaxed) < 1 || counters.invalid.load(Relaxed) < 2 {
        assert!(Instant::now() < deadline, "bad datagrams not counted");
        tokio::time::sleep(Duration::from_millis(10)).await;
    }
    let report = server.state().mocap.report();
    assert!(report.listening, "{report:?}");
    assert!(report.forwarded >= 1, "{report:?}");
    assert!(report.unrouted >= 1 && report.invalid >= 2, "{report:?}");
    server.shutdown().await;
    for sim in sims {
        sim.shutdown().await;
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_radio_uav_without_a_crazyradio_never_takes_the_server_down() {
    // This machine (and CI) has no Crazyradio: opening the radio fails (or panics inside the
    // client library) in the UAV's own task; the server keeps ticking and the UAV stays connecting.
    let server = start(config(&support::small())).await;
    let body = r#"{"id": "cf9", "position": [10.0, 0.0], "link": "radio://0/80/2M/E7E7E7E7E9"}"#;
    let (status, reply) = server.call("POST", "/api/uavs", Some(body)).await;
    assert_eq!(status, 201, "{reply}");
    assert_eq!(reply["link"], "radio://0/80/2M/E7E7E7E7E9");
    let before = server.get("/api/state").await["tick"].as_u64().unwrap();
    // 30 ticks take 1.5 s at 20 Hz. A loop blocked on the radio would wait out the connection
    // timeout (15 s) at least, so 10 s tells the two apart even on a loaded machine.
    let state = server.wait_for(10.0, |s| s["tick"].as_u64().unwrap() >= before + 30).await;
    assert!(state["tick"].as_u64().unwrap() >= before + 30, "the loop stalled: {state}");
    let cf9 = server.get("/api/uavs/cf9").await;
    assert_eq!(cf9["status"], "connecting", "{cf9}");
    assert_eq!(cf9["lost"], false, "never airborne, so not lost");
    // The operator sees why: the radio's error in the UAV's snapshot and in the metrics.
    let deadline = Instant::now() + Duration::from_secs_f64(PATIENCE);
    let cf9 = loop {
        let cf9 = server.get("/api/uavs/cf9").await;
        if cf9["link_error"].is_string() || Instant::now() > deadline {
            break cf9;
        }
        tokio::time::sleep(Duration::from_millis(50)).await;
    };
    let error = cf9["link_error"].as_str().unwrap_or_else(|| panic!("no link error shown: {cf9}"));
    assert!(!error.is_empty());
    let links = &server.get("/api/metrics").await["links"];
    assert_eq!((links["crazyflies"].as_u64(), links["with_error"].as_u64()), (Some(1), Some(1)), "{links}");
    assert_eq!(links["errors"][0]["id"], "cf9", "{links}");
    assert_eq!(links["errors"][0]["error"], error, "{links}");
    let (status, reply) = server
        .call("POST", "/api/uavs", Some(r#"{"id": "x", "position": [12.0, 0.0], "link": "bluetooth://cf"}"#))
        .await;
    assert_eq!((status, reply["error"]["field"].as_str()), (422, Some("link")), "{reply}");
    let (status, _) = server.call("DELETE", "/api/uavs/cf9", None).await;
    assert_eq!(status, 204);
    server.stop().await;
}

/// A policy that takes 5 s per call: it stalls the fleet loop.
struct Stall;

impl policies::Policy for Stall {
    fn act(
        &mut self,
        observations: &[policies::Observation],
        actions: &mut Vec<uav::Vec2>,
    ) -> Result<(), policies::PolicyError> {
        std::thread::sleep(Duration::from_secs(5));
        actions.clear();
        actions.resize(observations.len(), uav::Vec2::zeros());
        Ok(())
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_emergency_stop_reaches_the_crazyflies_while_the_loop_is_stalled() {
    let (scenario, sims) = with_sims(shipped("lab3.json"));
    let mut c = config(&scenario);
    c.policies.insert("stall", Box::new(Stall));
    let server = start(c).await;
    until_every_phase(&server, &sims, "flying").await;
    // Stall the loop: each tick now takes 5 s.
    let (status, body) = server.call("PUT", "/api/uavs/cf1/policy", Some(r#"{"policy": "stall"}"#)).await;
    assert_eq!(status, 200, "{body}");
    tokio::time::sleep(Duration::from_millis(300)).await;
    assert!(
        server.state.engine.clock.tick_age() > Duration::from_millis(250),
        "the loop is inside a slow tick"
    );
    let sent = Instant::now();
    let addr = server.addr;
    // The answer may wait for the stalled loop (503 after 2 s); the Crazyflies must not.
    let answer = tokio::spawn(async move { support::raw(addr, "POST", "/api/fleet/stop", None, &[]).await });
    // The motors are off long before the stalled loop could have applied the stop, and before the
    // Crazyflies' own watchdog (2 s without a setpoint) would have cut them.
    let deadline = Instant::now() + Duration::from_millis(1000);
    while sims.iter().any(|s| s.truth().motors_on) {
        assert!(Instant::now() < deadline, "motors still on {:?} after the stop", sent.elapsed());
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    let (status, body) = answer.await.unwrap();
    assert!(status == 200 || body.contains("sent the stop directly"), "{status}: {body}");
    server.stop().await;
    for sim in sims {
        sim.shutdown().await;
    }
}
