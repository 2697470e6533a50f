//! The real Crazyflie firmware under the server, for the firmware tests: its build from
//! `AIRROADS_CF_SITL`, a rig of firmware processes on cfsim's physics with a server flying
//! `scenarios/lab3.json` through them, and ground-truth margins read from the physics.

use super::{Running, scenario, shipped, start};
use cfsim::sitl::firmware::{self, FirmwareProcesses, StartOptions};
use cfsim::sitl::pace::Tries;
use cfsim::sitl::{SitlConfig, SitlHandle};
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use uav::Vec2;

/// Deadline for each phase that takes seconds on an idle machine (s).
pub const PATIENCE: f64 = 90.0;

/// Above this height a Crazyflie is airborne for the margins (m).
pub const AIRBORNE_M: f64 = 0.3;

/// One firmware flight at a time: three firmware processes already take most of two cores.
pub static ONE_FLIGHT: tokio::sync::Mutex<()> = tokio::sync::Mutex::const_new(());

/// The firmware built from `AIRROADS_CF_SITL` (once, into the cache), or `None` with a message
/// saying how to run the test.
pub async fn firmware_binary(what: &str) -> Option<PathBuf> {
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

/// lab3's three firmware processes on the physics, and a server flying them (rl policy).
pub struct Rig {
    /// The physics: ground truth, faults.
    pub sitl: Arc<SitlHandle>,
    /// The firmware processes (kill one to stage a fault).
    pub processes: FirmwareProcesses,
    /// The server.
    pub server: Running,
    /// lab3's road, for the true wall distance.
    pub road: roads::Road,
    /// The firmware the flight stopped on purpose (killed, cut off), left out of the pace check
    /// and of the true wall distance.
    silenced: Arc<Mutex<Vec<usize>>>,
}

impl Rig {
    /// Starts the physics (ground truth to `run_dir`), the firmware and the server.
    pub async fn start(cf2: &Path, run_dir: &Path) -> Result<Self, String> {
        let mut json = shipped("lab3.json");
        let starts: Vec<[f64; 3]> = json["uavs"]
            .as_array()
            .expect("uavs")
            .iter()
            .map(|u| [u["start"][0].as_f64().unwrap(), u["start"][1].as_f64().unwrap(), 0.0])
            .collect();
        let config = SitlConfig {
            positions: starts,
            firmware_base_port: 0,
            client_base_port: 0,
            truth_dir: Some(run_dir.to_path_buf()),
            noise: true,
            ..SitlConfig::default()
        };
        let sitl = Arc::new(SitlHandle::spawn(config).map_err(|e| e.to_string())?);
        let (cf2, options, physics) = (cf2.to_path_buf(), StartOptions::in_dir(run_dir), sitl.clone());
        let processes =
            tokio::task::spawn_blocking(move || FirmwareProcesses::start(&cf2, &physics, &options))
                .await
                .map_err(|e| e.to_string())?
                .map_err(|e| e.to_string())?;
        for (i, uav) in json["uavs"].as_array_mut().expect("uavs").iter_mut().enumerate() {
            uav["link"] = Value::String(sitl.uri(i).expect("drone"));
        }
        let road = scenario(&json).road.road().expect("lab3 is one road").clone();
        let policies = policies::PolicyRegistry::standard(5.0).map_err(|e| e.to_string())?;
        let config = airroads_server::serve::ServeConfig::new(
            fleet::FleetConfig::default(),
            policies,
            "rl".into(),
            scenario(&json),
        );
        let server = start(config).await;
        Ok(Self { sitl, processes, server, road, silenced: Arc::default() })
    }

    /// Stops the server, then the firmware.
    pub async fn stop(self) {
        self.server.stop().await;
        drop(self.processes);
    }

    /// Leaves drone `i`'s firmware out of [`Self::fell_behind`] and its Crazyflie out of the true
    /// wall distance from now on (the flight is about to kill it or cut it off: the server can no
    /// longer steer it; the others still keep their distance from it).
    pub fn silence(&self, i: usize) {
        self.silenced.lock().unwrap_or_else(std::sync::PoisonError::into_inner).push(i);
    }

    /// Why the flight says nothing about the server, if a firmware (not silenced) fell behind
    /// real time ([`SitlHandle::fell_behind`]).
    pub fn fell_behind(&self) -> Option<String> {
        let silenced = self.silenced.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
        (0..self.sitl.len()).filter(|i| !silenced.contains(i)).find_map(|i| self.sitl.fell_behind(i))
    }

    /// Starts reading the true margins of the airborne Crazyflies; read them with
    /// [`Watch::margins`].
    pub fn watch(&self) -> Watch {
        let margins = Arc::new(Mutex::new(Margins { separation_m: f64::INFINITY, wall_m: f64::INFINITY }));
        let (sitl, road, silenced) = (self.sitl.clone(), self.road.clone(), self.silenced.clone());
        let task = tokio::spawn(watch_margins(sitl, road, silenced, margins.clone()));
        Watch { margins, task }
    }
}

/// Flies `flight` on a fresh rig until it passes, as [`Tries`] allows (a failed flight is tried
/// once more; one whose firmware fell behind real time, [`Rig::fell_behind`], does not count).
/// Panics with every reason and where the consoles are; when no try's firmware kept up, returns
/// the skip message (the firmware never ran in real time, which says nothing about the server).
pub async fn with_retries<F, Fut>(cf2: &Path, name: &str, flight: F) -> String
where
    F: Fn(Rig) -> Fut,
    Fut: std::future::Future<Output = (Rig, Result<String, String>)>,
{
    let run_dir = std::env::temp_dir().join(format!("airroads-{name}-{}", std::process::id()));
    std::fs::create_dir_all(&run_dir).expect("run folder");
    let mut tries = Tries::default();
    loop {
        let (outcome, behind, gaps) = match Rig::start(cf2, &run_dir).await {
            Ok(rig) => {
                let (rig, outcome) = flight(rig).await;
                let behind = rig.fell_behind();
                let gaps: Vec<u64> = (0..rig.sitl.len())
                    .filter_map(|i| rig.sitl.stats(i))
                    .map(|s| s.longest_motor_gap)
                    .collect();
                rig.stop().await;
                (outcome, behind, gaps)
            }
            Err(e) => (Err(format!("the rig did not start: {e}")), None, Vec::new()),
        };
        match outcome {
            Ok(report) => {
                let _ = std::fs::remove_dir_all(&run_dir);
                return report;
            }
            Err(e) => {
                eprintln!("{name}: flight failed ({e}); {behind:?}; longest motor gaps {gaps:?} ms");
                if !tries.failed(e, behind) {
                    break;
                }
            }
        }
    }
    match tries.verdict() {
        Ok(skipped) => {
            let message = format!("{name}: {skipped}");
            tell(&message);
            message
        }
        Err(failures) => {
            panic!("{name} failed: {failures} (firmware consoles and ground truth in {})", run_dir.display())
        }
    }
}

/// Writes `message` to the test's stderr past the harness's capture (which only takes the print
/// macros), so that a passing run's log shows it: a firmware test skipped for a slow host must not
/// pass unseen.
pub fn tell(message: &str) {
    use std::io::Write as _;
    let _ = writeln!(std::io::stderr(), "{message}");
}

/// The margins being read from the physics (stopped when dropped).
pub struct Watch {
    margins: Arc<Mutex<Margins>>,
    task: tokio::task::JoinHandle<()>,
}

impl Watch {
    /// The smallest true margins so far.
    pub fn margins(&self) -> Margins {
        *self.margins.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
    }
}

impl Drop for Watch {
    fn drop(&mut self) {
        self.task.abort();
    }
}

/// What the physics saw while the fleet flew: the closest true pair and the closest true wall
/// among airborne Crazyflies.
#[derive(Debug, Clone, Copy)]
pub struct Margins {
    /// Closest true pair (m).
    pub separation_m: f64,
    /// Closest true wall (m).
    pub wall_m: f64,
}

/// Reads the physics every 5 ms and keeps the smallest true separation among airborne Crazyflies
/// and their smallest true wall distance, of those the server still steers (not silenced), in the
/// horizontal plane the fleet flies in.
async fn watch_margins(
    sitl: Arc<SitlHandle>,
    road: roads::Road,
    silenced: Arc<Mutex<Vec<usize>>>,
    margins: Arc<Mutex<Margins>>,
) {
    loop {
        let up: Vec<(usize, Vec2)> = (0..sitl.len())
            .filter_map(|i| Some((i, sitl.truth(i)?)))
            .filter(|(_, t)| t.position[2] > AIRBORNE_M)
            .map(|(i, t)| (i, Vec2::new(t.position[0], t.position[1])))
            .collect();
        let silenced = silenced.lock().unwrap_or_else(std::sync::PoisonError::into_inner).clone();
        {
            let mut m = margins.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
            for (k, (i, a)) in up.iter().enumerate() {
                if !silenced.contains(i) {
                    m.wall_m = m.wall_m.min(road.boundary_distance(a));
                }
                for (_, b) in &up[k + 1..] {
                    m.separation_m = m.separation_m.min((a - b).norm());
                }
            }
        }
        tokio::time::sleep(Duration::from_millis(5)).await;
    }
}

/// The UAVs of a snapshot.
pub fn uavs(state: &Value) -> &Vec<Value> {
    state["uavs"].as_array().expect("uavs")
}

/// Polls the snapshot every 20 ms until `done` holds, for at most [`PATIENCE`] s; gives up at
/// once when a firmware fell behind real time ([`Rig::fell_behind`]).
pub async fn until(rig: &Rig, what: &str, done: impl Fn(&Value) -> bool) -> Result<(), String> {
    let deadline = Instant::now() + Duration::from_secs_f64(PATIENCE);
    loop {
        let state = rig.server.get("/api/state").await;
        if done(&state) {
            return Ok(());
        }
        if rig.fell_behind().is_some() {
            return Err(format!("gave up waiting for {what}: a firmware fell behind real time"));
        }
        if Instant::now() > deadline {
            return Err(format!("not {what} within {PATIENCE} s: {state}"));
        }
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
}
