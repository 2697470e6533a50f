//! The test of record for Crazyflies: `scenarios/lab3.json` flown by the server through three real
//! firmware processes (bitcraze's crazyflie-firmware 2026.08 built for software-in-the-loop,
//! `cf2`) on cfsim's rigid-body physics of the Crazyflie 2.1, which also stands in for motion
//! capture (the external pose at 200 Hz) and gives the ground truth every check below reads.
//!
//! The server connects to each firmware as it would over a radio, sets the controller, takes off
//! (the firmware confirms it), flies the fleet's filtered commands as full-state setpoints, lands
//! one Crazyflie and stops the others. Checked on the physics: every UAV arrives, the true
//! separation stays ≥ D_c and the true wall distance ≥ D_s while airborne, the landed one is on the
//! floor with its motors off, the stopped ones have their motors off and their firmware locked.
//!
//! Skipped (with a message) unless `AIRROADS_CF_SITL` names the firmware's SITL folder (the one
//! holding `build.sh`); the firmware is built once into
//! `${AIRROADS_CACHE:-$HOME/.cache/airroads}/cf-sitl-build`. The firmware's emulated clock can
//! slip under CPU load; a failed flight is tried once more with fresh processes.

mod support;

use cfsim::sitl::firmware::{self, FirmwareProcesses, StartOptions};
use cfsim::sitl::{SitlConfig, SitlHandle};
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use support::{Running, scenario, shipped, start};
use uav::Vec2;

/// Deadline for each phase that takes seconds on an idle machine (s).
const PATIENCE: f64 = 60.0;

/// Above this height a Crazyflie is airborne for the margins (m).
const AIRBORNE_M: f64 = 0.3;

/// One firmware flight at a time: three firmware processes already take most of two cores.
static ONE_FLIGHT: tokio::sync::Mutex<()> = tokio::sync::Mutex::const_new(());

/// The firmware built from `AIRROADS_CF_SITL` (once, into the cache), or `None` with a message
/// saying how to run the test.
async fn firmware_binary(what: &str) -> Option<PathBuf> {
    let Some(source) = std::env::var_os("AIRROADS_CF_SITL") else {
        eprintln!(
            "skipped: set AIRROADS_CF_SITL to the Crazyflie firmware's SITL folder (the one holding \
             build.sh) to fly {what} through the real firmware"
        );
        return None;
    };
    let cache = std::env::var_os("AIRROADS_CACHE").map(PathBuf::from).unwrap_or_else(|| {
        PathBuf::from(std::env::var_os("HOME").expect("HOME or AIRROADS_CACHE")).join(".cache/airroads")
    });
    let build = cache.join("cf-sitl-build");
    let cf2 = tokio::task::spawn_blocking(move || firmware::build(Path::new(&source), &build))
        .await
        .expect("build task")
        .unwrap_or_else(|e| panic!("{e}"));
    Some(cf2)
}

/// `airroads run --link firmware` writes METRICS.json with exactly the keys of any run, its
/// margins measured on the physics, and exits 0 for a safe run where every UAV arrived.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_run_over_the_firmware_writes_the_same_report() {
    let _alone = ONE_FLIGHT.lock().await;
    let Some(cf2) = firmware_binary("`airroads run scenarios/lab3.json`").await else { return };
    let out = std::env::temp_dir().join(format!("airroads-firmware-metrics-{}.json", std::process::id()));
    let scenario = support::repo().join("scenarios/lab3.json");
    let mut tries = Vec::new();
    // One retry, as for the flight above: the firmware's clock can slip under load.
    for _ in 0..2 {
        let run = std::process::Command::new(env!("CARGO_BIN_EXE_airroads"))
            .args(["run", scenario.to_str().unwrap(), "--link", "firmware", "--cf2", cf2.to_str().unwrap()])
            .args(["--out", out.to_str().unwrap()])
            .output()
            .expect("airroads runs");
        let stdout = String::from_utf8_lossy(&run.stdout).into_owned();
        if run.status.code() == Some(0) {
            assert!(stdout.contains("firmware loop") && stdout.contains("SAFE"), "{stdout}");
            let metrics: Value = serde_json::from_str(&std::fs::read_to_string(&out).unwrap()).unwrap();
            let mut keys: Vec<&str> = metrics.as_object().unwrap().keys().map(String::as_str).collect();
            keys.sort();
            assert_eq!(
                keys,
                [
                    "all_arrived",
                    "arrival_time_s",
                    "max_stall_s",
                    "min_collision_margin_m",
                    "min_road_margin_m",
                    "min_separation_m",
                    "min_wall_distance_m",
                    "qp",
                    "safe",
                    "scenario",
                    "sim_time_s",
                    "stall_s",
                    "steps_outside_road",
                    "ticks"
                ]
            );
            assert!(metrics["min_separation_m"].as_f64().is_some_and(|d| d >= 0.3), "{metrics}");
            assert!(metrics["min_wall_distance_m"].as_f64().is_some_and(|d| d >= 0.1), "{metrics}");
            let _ = std::fs::remove_file(&out);
            return;
        }
        tries.push(format!("{:?}: {stdout}{}", run.status.code(), String::from_utf8_lossy(&run.stderr)));
    }
    panic!("the run over the firmware failed twice:\n{}", tries.join("\n"));
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn lab3_flies_through_three_real_firmware_processes() {
    let _alone = ONE_FLIGHT.lock().await;
    let Some(cf2) = firmware_binary("scenarios/lab3.json with the server").await else { return };
    let run_dir = std::env::temp_dir().join(format!("airroads-lab3-firmware-{}", std::process::id()));
    std::fs::create_dir_all(&run_dir).expect("run folder");
    let report = match fly(&cf2, &run_dir).await {
        Ok(report) => Ok(report),
        Err(first) => {
            eprintln!("first flight failed ({first}); retrying once with fresh processes");
            fly(&cf2, &run_dir).await
        }
    };
    match report {
        Ok(report) => {
            println!("{report}");
            let _ = std::fs::remove_dir_all(&run_dir);
        }
        Err(e) => panic!("{e} (firmware consoles and ground truth in {})", run_dir.display()),
    }
}

/// What the physics saw while the fleet flew: the closest true pair and the closest true wall
/// among airborne Crazyflies.
#[derive(Debug, Clone, Copy)]
struct Margins {
    separation_m: f64,
    wall_m: f64,
}

/// One flight of lab3 through fresh firmware processes and a fresh server.
async fn fly(cf2: &Path, run_dir: &Path) -> Result<String, String> {
    let mut json = shipped("lab3.json");
    let starts: Vec<[f64; 3]> = json["uavs"]
        .as_array()
        .expect("uavs")
        .iter()
        .map(|u| [u["start"][0].as_f64().unwrap(), u["start"][1].as_f64().unwrap(), 0.0])
        .collect();
    let config = SitlConfig {
        positions: starts.clone(),
        firmware_base_port: 0,
        client_base_port: 0,
        truth_dir: Some(run_dir.to_path_buf()),
        noise: true,
        ..SitlConfig::default()
    };
    let sitl = Arc::new(SitlHandle::spawn(config).map_err(|e| e.to_string())?);
    let (cf2, options, physics) = (cf2.to_path_buf(), StartOptions::in_dir(run_dir), sitl.clone());
    let processes = tokio::task::spawn_blocking(move || FirmwareProcesses::start(&cf2, &physics, &options))
        .await
        .map_err(|e| e.to_string())?
        .map_err(|e| e.to_string())?;
    for (i, uav) in json["uavs"].as_array_mut().expect("uavs").iter_mut().enumerate() {
        uav["link"] = Value::String(sitl.uri(i).expect("drone"));
    }
    let road = scenario(&json).road;
    let policies = policies::PolicyRegistry::standard(5.0).map_err(|e| e.to_string())?;
    let config = airroads::serve::ServeConfig::new(
        fleet::FleetConfig::default(),
        policies,
        "rl".into(),
        scenario(&json),
    );
    let server = start(config).await;
    let result = flight(&server, &sitl, &road).await;
    server.stop().await;
    drop(processes);
    result
}

/// The flight itself, once the server and the firmware run.
async fn flight(server: &Running, sitl: &Arc<SitlHandle>, road: &roads::Road) -> Result<String, String> {
    let t0 = Instant::now();
    until(server, "every UAV flying (take-off confirmed by the firmware)", |s| {
        uavs(s).iter().all(|u| u["phase"] == "flying")
    })
    .await?;
    let airborne_after = t0.elapsed();
    let state = server.get("/api/state").await;
    let (d_c, d_s) = (state["d_c"].as_f64().expect("d_c"), state["d_s"].as_f64().expect("d_s"));
    for i in 0..sitl.len() {
        let z = sitl.truth(i).expect("drone").position[2];
        if (z - 1.0).abs() > 0.15 {
            return Err(format!("drone {i} reported flying at a true height of {z:.3} m"));
        }
    }
    let margins = Arc::new(Mutex::new(Margins { separation_m: f64::INFINITY, wall_m: f64::INFINITY }));
    let watcher = tokio::spawn(watch_margins(sitl.clone(), road.clone(), margins.clone()));
    let arrived = until(server, "every UAV arrived", |s| uavs(s).iter().all(|u| u["arrived"] == true)).await;
    watcher.abort();
    let seen = *margins.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
    arrived?;
    let flown = t0.elapsed();
    if seen.separation_m < d_c || seen.wall_m < d_s {
        return Err(format!("true margins {seen:?} below D_c = {d_c} m / D_s = {d_s} m"));
    }
    for (i, u) in uavs(&server.get("/api/state").await).iter().enumerate() {
        let goal = Vec2::new(u["goal"][0].as_f64().unwrap(), u["goal"][1].as_f64().unwrap());
        let p = sitl.truth(i).expect("drone").position;
        let off = (Vec2::new(p[0], p[1]) - goal).norm();
        if off > 0.2 {
            return Err(format!(
                "{} arrived by its estimate but is {off:.3} m from its goal in truth",
                u["id"]
            ));
        }
    }

    // cf1 lands: confirmed by its firmware's log, and on the floor with its motors off in truth.
    let (status, body) = server.call("POST", "/api/uavs/cf1/land", None).await;
    if status != 200 {
        return Err(format!("land cf1: {status} {body}"));
    }
    until(server, "cf1 landed", |s| uavs(s)[0]["phase"] == "landed").await?;
    let truth = sitl.truth(0).expect("drone");
    if !truth.on_floor || truth.pwm != [0; 4] {
        return Err(format!("cf1 shown landed but its truth is {truth:?}"));
    }
    // The emergency stop: cf2 and cf3 stopped, their firmware locked, their motors off.
    let (status, body) = server.call("POST", "/api/fleet/stop", None).await;
    if status != 200 {
        return Err(format!("stop: {status} {body}"));
    }
    until(server, "cf2 and cf3 stopped", |s| uavs(s)[1..].iter().all(|u| u["phase"] == "stopped")).await?;
    for (i, u) in uavs(&server.get("/api/state").await).iter().enumerate().skip(1) {
        let pwm = sitl.truth(i).expect("drone").pwm;
        if pwm != [0; 4] || u["firmware"]["locked"] != true {
            return Err(format!(
                "{} shown stopped with motors {pwm:?} and firmware {}",
                u["id"], u["firmware"]
            ));
        }
    }
    let stats = sitl.loop_stats();
    Ok(format!(
        "lab3 through the real firmware: airborne after {:.1} s, all arrived after {:.1} s; true \
         separation ≥ {:.3} m (D_c {d_c}), true wall distance ≥ {:.3} m (D_s {d_s}); physics {:.0} Hz, \
         {} resyncs",
        airborne_after.as_secs_f64(),
        flown.as_secs_f64(),
        seen.separation_m,
        seen.wall_m,
        stats.physics_rate_hz(),
        stats.resyncs
    ))
}

/// Reads the physics every 5 ms and keeps the smallest true separation and wall distance among
/// airborne Crazyflies (horizontal, the plane the fleet flies in).
async fn watch_margins(sitl: Arc<SitlHandle>, road: roads::Road, margins: Arc<Mutex<Margins>>) {
    loop {
        let up: Vec<Vec2> = (0..sitl.len())
            .filter_map(|i| sitl.truth(i))
            .filter(|t| t.position[2] > AIRBORNE_M)
            .map(|t| Vec2::new(t.position[0], t.position[1]))
            .collect();
        {
            let mut m = margins.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
            for (k, a) in up.iter().enumerate() {
                m.wall_m = m.wall_m.min(road.boundary_distance(a));
                for b in &up[k + 1..] {
                    m.separation_m = m.separation_m.min((a - b).norm());
                }
            }
        }
        tokio::time::sleep(Duration::from_millis(5)).await;
    }
}

/// The UAVs of a snapshot.
fn uavs(state: &Value) -> &Vec<Value> {
    state["uavs"].as_array().expect("uavs")
}

/// Polls the snapshot every 20 ms until `done` holds, for at most [`PATIENCE`] s.
async fn until(server: &Running, what: &str, done: impl Fn(&Value) -> bool) -> Result<(), String> {
    let deadline = Instant::now() + Duration::from_secs_f64(PATIENCE);
    loop {
        let state = server.get("/api/state").await;
        if done(&state) {
            return Ok(());
        }
        if Instant::now() > deadline {
            return Err(format!("not {what} within {PATIENCE} s: {state}"));
        }
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
}
