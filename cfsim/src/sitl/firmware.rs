//! The real firmware processes of a [`SitlHandle`]: one `cf2 PORT` (the Crazyflie firmware's
//! SITL build) per drone, built from its source folder with the folder's own `build.sh`.
//!
//! The firmware's FreeRTOS POSIX port sometimes stalls at start (the hello completes but the
//! stabilizer never runs, or stops soon after): a drone counts as started once half a second of
//! motor commands arrived since its hello, and a stalled start is killed and started again. Every process is killed when the
//! [`FirmwareProcesses`] is dropped, so none outlives its user.

use super::SitlHandle;
use std::fs::File;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// Motor commands since its hello after which a firmware counts as started: half a second of its
/// 500 per second (one alone also came from firmware that stalled right after).
const STARTED_AFTER: u64 = 250;

/// Errors building or starting the firmware.
#[derive(Debug, thiserror::Error)]
pub enum FirmwareError {
    /// `build.sh` could not run or failed.
    #[error("building the firmware from {source_dir} into {build_dir} failed: {reason}")]
    Build {
        /// The firmware's source folder.
        source_dir: PathBuf,
        /// Where it was built.
        build_dir: PathBuf,
        /// What went wrong.
        reason: String,
    },
    /// A process could not be started, or a log file opened.
    #[error("drone {drone}: {reason}")]
    Start {
        /// The drone.
        drone: usize,
        /// What went wrong.
        reason: String,
    },
    /// The firmware never ran its stabilizer.
    #[error("drone {drone}: the firmware did not start in {tries} tries of {wait:?}")]
    Stalled {
        /// The drone.
        drone: usize,
        /// Starts attempted.
        tries: usize,
        /// Wait per start.
        wait: Duration,
    },
}

/// Builds `cf2` from the firmware folder `source_dir` (the one holding `build.sh`) into
/// `build_dir`, unless a `cf2` is there already; returns its path.
pub fn build(source_dir: &Path, build_dir: &Path) -> Result<PathBuf, FirmwareError> {
    let cf2 = build_dir.join("cf2");
    if cf2.is_file() {
        return Ok(cf2);
    }
    let fail = |reason: String| FirmwareError::Build {
        source_dir: source_dir.to_path_buf(),
        build_dir: build_dir.to_path_buf(),
        reason,
    };
    let output = Command::new("bash")
        .arg(source_dir.join("build.sh"))
        .arg(build_dir)
        .stdin(Stdio::null())
        .output()
        .map_err(|e| fail(format!("cannot run build.sh: {e}")))?;
    if !output.status.success() {
        let stderr = String::from_utf8_lossy(&output.stderr);
        return Err(fail(format!("{}: {}", output.status, stderr.trim())));
    }
    if !cf2.is_file() {
        return Err(fail("build.sh succeeded but left no cf2".into()));
    }
    Ok(cf2)
}

/// How the firmware processes are started.
#[derive(Debug, Clone)]
pub struct StartOptions {
    /// Folder for each drone's console (`fwN.out`) and errors (`fwN.err`); also their working
    /// directory.
    pub run_dir: PathBuf,
    /// How long a start may take before it counts as stalled.
    pub wait: Duration,
    /// Starts tried per drone.
    pub tries: usize,
}

impl StartOptions {
    /// Logs in `run_dir`, 5 s per start, 6 tries (as the SITL's own start script).
    pub fn in_dir(run_dir: impl Into<PathBuf>) -> Self {
        Self { run_dir: run_dir.into(), wait: Duration::from_secs(5), tries: 6 }
    }
}

/// The running firmware processes, one per drone of a [`SitlHandle`], killed when dropped.
#[derive(Debug)]
pub struct FirmwareProcesses {
    children: Vec<Option<Child>>,
}

impl FirmwareProcesses {
    /// Starts `cf2` for every drone of `sitl`, one after another, each until its stabilizer runs.
    pub fn start(cf2: &Path, sitl: &SitlHandle, options: &StartOptions) -> Result<Self, FirmwareError> {
        let mut processes = Self { children: Vec::with_capacity(sitl.len()) };
        for drone in 0..sitl.len() {
            let child = start_one(cf2, sitl, drone, options)?;
            processes.children.push(Some(child));
        }
        Ok(processes)
    }

    /// The process id of drone `drone`'s firmware, while it runs.
    pub fn pid(&self, drone: usize) -> Option<u32> {
        self.children.get(drone)?.as_ref().map(Child::id)
    }

    /// Kills drone `drone`'s firmware (a firmware that dies in flight).
    pub fn kill(&mut self, drone: usize) {
        if let Some(mut child) = self.children.get_mut(drone).and_then(Option::take) {
            let _ = child.kill();
            let _ = child.wait();
        }
    }
}

impl Drop for FirmwareProcesses {
    fn drop(&mut self) {
        for drone in 0..self.children.len() {
            self.kill(drone);
        }
    }
}

/// Starts drone `drone`'s firmware and waits for its first motor packet since its hello,
/// restarting a stalled start.
fn start_one(
    cf2: &Path,
    sitl: &SitlHandle,
    drone: usize,
    options: &StartOptions,
) -> Result<Child, FirmwareError> {
    let fail = |reason: String| FirmwareError::Start { drone, reason };
    let port = sitl.firmware_addr(drone).ok_or_else(|| fail("no such drone".into()))?.port();
    let log = |kind: &str| {
        let path = options.run_dir.join(format!("fw{drone}.{kind}"));
        File::options()
            .create(true)
            .append(true)
            .open(&path)
            .map_err(|e| fail(format!("{}: {e}", path.display())))
    };
    for _ in 0..options.tries {
        let hellos = sitl.stats(drone).map_or(0, |s| s.hellos);
        // The console is the firmware's stdout: line-buffered, so a killed process keeps its log.
        let mut command = match which("stdbuf") {
            Some(stdbuf) => {
                let mut c = Command::new(stdbuf);
                c.arg("-oL").arg(cf2);
                c
            }
            None => Command::new(cf2),
        };
        let mut child = command
            .arg(port.to_string())
            .current_dir(&options.run_dir)
            .stdin(Stdio::null())
            .stdout(log("out")?)
            .stderr(log("err")?)
            .spawn()
            .map_err(|e| fail(format!("cannot start {}: {e}", cf2.display())))?;
        let started = Instant::now();
        while started.elapsed() < options.wait {
            if sitl
                .stats(drone)
                .is_some_and(|s| s.hellos > hellos && s.motor_packets_since_hello >= STARTED_AFTER)
            {
                return Ok(child);
            }
            std::thread::sleep(Duration::from_millis(50));
        }
        let _ = child.kill();
        let _ = child.wait();
    }
    Err(FirmwareError::Stalled { drone, tries: options.tries, wait: options.wait })
}

/// `program`'s path if it is on `PATH`.
fn which(program: &str) -> Option<PathBuf> {
    std::env::split_paths(&std::env::var_os("PATH")?).map(|d| d.join(program)).find(|p| p.is_file())
}
