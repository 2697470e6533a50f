//! What a session does on connect before it flies a Crazyflie that is on the ground: the state a
//! real firmware keeps across client sessions is put right, and what the firmware reports decides
//! whether it may take off.
//!
//! * **The controller** (`stabilizer.controller`): the full-state setpoints carry velocity and
//!   acceleration feed-forward, which Mellinger follows and the default PID does not (PID tracks
//!   only their position, one tick ahead: the Crazyflie creeps). It is set when it differs and
//!   read back; a firmware that keeps another value is refused with both values named.
//! * **Stale commander state**: over UDP (and after a radio session that ended without a landing)
//!   the firmware never saw the previous client leave, and its low-level setpoint may still
//!   outrank the high-level commander, which then ignores the take-off. A "notify setpoint stop"
//!   hands control to the high-level commander first.
//! * **The supervisor**: a locked Crazyflie (emergency stop, or the free-fall lock) flies only after
//!   a reboot, which is reported instead of a take-off the firmware would ignore; one that needs
//!   arming (firmware built with `CONFIG_MOTORS_REQUIRE_ARMING`, e.g. the Crazyflie 2.1 Brushless)
//!   is armed through the supervisor and must say so.

use crate::relay::Controller;
use crazyflie_lib::subsystems::supervisor::SupervisorInfo;
use crazyflie_lib::{Crazyflie, TocCache};
use std::collections::HashMap;
use std::sync::{Arc, Mutex, OnceLock, PoisonError};
use std::time::Duration;
use tokio::time::{Instant, sleep, timeout};

/// The firmware parameter that selects the controller.
pub const CONTROLLER_PARAM: &str = "stabilizer.controller";

/// Longest wait for the supervisor's answer to one request.
const SUPERVISOR_WAIT: Duration = Duration::from_millis(500);

/// Longest wait for the armed bit after an arming request.
const ARM_WAIT: Duration = Duration::from_secs(1);

/// Longest wait for the supervisor to let the motors run (a firmware that has just booted passes
/// its pre-flight checks within a second or two).
const READY_WAIT: Duration = Duration::from_secs(5);

/// Sets `controller` if the firmware has the parameter and another value, then reads it back.
/// Returns the value read back (`None`: the firmware has no such parameter, e.g. very old).
pub async fn set_controller(cf: &Crazyflie, controller: Controller) -> Result<Option<u8>, String> {
    if !cf.param.names().iter().any(|n| n == CONTROLLER_PARAM) {
        return Ok(None);
    }
    let read = || async {
        cf.param.get::<u8>(CONTROLLER_PARAM).await.map_err(|e| format!("read {CONTROLLER_PARAM}: {e}"))
    };
    let want = controller.value();
    if read().await? != want {
        cf.param.set(CONTROLLER_PARAM, want).await.map_err(|e| format!("set {CONTROLLER_PARAM}: {e}"))?;
        let got = read().await?;
        if got != want {
            return Err(format!("{CONTROLLER_PARAM} is {got} after setting it to {want} ({controller:?})"));
        }
    }
    Ok(Some(want))
}

/// The supervisor's state, or `None` from a firmware without the supervisor port (before 2023).
async fn supervisor(cf: &Crazyflie) -> Option<SupervisorInfo> {
    timeout(SUPERVISOR_WAIT, cf.supervisor.read_bitfield()).await.ok()?.ok()
}

/// Clears the previous session's low-level setpoint, checks (and if needed arms) the supervisor
/// and waits until it lets the motors run ("can fly": its pre-flight checks passed, armed; a
/// take-off before that is refused by the high-level commander, which the supervisor keeps
/// blocked). Returns the supervisor bits last read, if the firmware has a supervisor.
pub async fn ready_for_take_off(cf: &Crazyflie) -> Result<Option<u16>, String> {
    cf.commander.notify_setpoint_stop(0).await.map_err(|e| format!("setpoint stop: {e}"))?;
    let Some(mut info) = supervisor(cf).await else { return Ok(None) };
    check_not_locked(&info)?;
    if !info.is_armed() && !info.is_auto_armed() {
        cf.supervisor.send_arming_request(true).await.map_err(|e| format!("arming request: {e}"))?;
        info = until_supervisor(cf, info, ARM_WAIT, SupervisorInfo::is_armed).await.map_err(|last| {
            format!(
                "not armed {} ms after the arming request (supervisor.info {last:#06x})",
                ARM_WAIT.as_millis()
            )
        })?;
    }
    let ready = until_supervisor(cf, info, READY_WAIT, SupervisorInfo::can_fly).await.map_err(|last| {
        format!(
            "the supervisor does not let the motors run after {} s (supervisor.info {last:#06x})",
            READY_WAIT.as_secs()
        )
    })?;
    Ok(Some(ready.raw))
}

/// Reads the supervisor every 50 ms until `done` holds (at once if it holds for `info`), for at
/// most `wait`; the error is the last bitfield read (a lock ends the wait at once).
async fn until_supervisor(
    cf: &Crazyflie,
    mut info: SupervisorInfo,
    wait: Duration,
    done: fn(&SupervisorInfo) -> bool,
) -> Result<SupervisorInfo, u16> {
    let deadline = Instant::now() + wait;
    loop {
        if done(&info) {
            return Ok(info);
        }
        if Instant::now() >= deadline || check_not_locked(&info).is_err() {
            return Err(info.raw);
        }
        sleep(Duration::from_millis(50)).await;
        if let Some(read) = supervisor(cf).await {
            info = read;
        }
    }
}

/// A locked or crashed Crazyflie cannot take off until it is rebooted (or recovered).
fn check_not_locked(info: &SupervisorInfo) -> Result<(), String> {
    if info.is_locked() {
        return Err(format!(
            "the Crazyflie is locked (supervisor.info {:#06x}: emergency stop or free fall): reboot it",
            info.raw
        ));
    }
    if info.is_crashed() || info.is_tumbled() {
        return Err(format!(
            "the Crazyflie reports it is {} (supervisor.info {:#06x}): put it upright and reboot it",
            if info.is_crashed() { "crashed" } else { "tumbled" },
            info.raw
        ));
    }
    Ok(())
}

/// The tables of contents of every Crazyflie this process has connected to, by the key
/// crazyflie-lib gives them (which holds the firmware's TOC checksum): a fleet of one firmware
/// downloads its tables once, and a reconnection reads none.
#[derive(Clone)]
pub struct SharedTocCache(Arc<Mutex<HashMap<Vec<u8>, String>>>);

impl SharedTocCache {
    /// The process's cache.
    pub fn process() -> Self {
        static CACHE: OnceLock<SharedTocCache> = OnceLock::new();
        CACHE.get_or_init(|| SharedTocCache(Arc::default())).clone()
    }
}

impl TocCache for SharedTocCache {
    fn get_toc(&self, key: &[u8]) -> Option<String> {
        self.0.lock().unwrap_or_else(PoisonError::into_inner).get(key).cloned()
    }

    fn store_toc(&self, key: &[u8], toc: &str) {
        self.0.lock().unwrap_or_else(PoisonError::into_inner).insert(key.to_vec(), toc.to_string());
    }
}
