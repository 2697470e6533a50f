//! The task behind one [`crate::CrazyflieLink`]: connect over CRTP, take off with the high-level
//! commander, stream a full-state setpoint for every command while the state is fresh, forward
//! motion-capture positions, land or stop on request, and reconnect after a loss. A failure here
//! (an error, even a panic inside the client library) ends one session, never the server: the
//! supervisor records it, waits and reconnects.

use crate::relay::{RelayConfig, Setpoint, Shared, Urgent};
use crate::transport::open;
use crazyflie_lib::subsystems::log::LogPeriod;
use crazyflie_lib::{Crazyflie, TocCache};
use links::LinkPhase;
use std::sync::Arc;
use std::time::Duration;
use tokio::sync::{mpsc, watch};
use tokio::time::{Instant, sleep_until, timeout};

/// The log variables of the state estimate, in the order of [`crate::relay::Sample`].
pub const STATE_VARIABLES: [&str; 6] = [
    "stateEstimate.x",
    "stateEstimate.y",
    "stateEstimate.z",
    "stateEstimate.vx",
    "stateEstimate.vy",
    "stateEstimate.vz",
];

/// Below this height (m) a connected Crazyflie is on the ground.
const ON_GROUND_M: f64 = 0.1;
/// Identity attitude and no body rates for the full-state setpoint (the fleet does not steer yaw).
const LEVEL: [f32; 4] = [0.0, 0.0, 0.0, 1.0];

/// The session's ends of the link's channels.
pub struct Channels {
    /// Latest setpoint (latest wins).
    pub setpoints: watch::Receiver<Option<Setpoint>>,
    /// Land / stop, ahead of setpoints; closed when the link is dropped.
    pub urgent: mpsc::UnboundedReceiver<Urgent>,
    /// Motion-capture positions to forward.
    pub external: mpsc::Receiver<[f32; 3]>,
}

/// How a session ended.
enum End {
    /// The link was dropped and the Crazyflie is down: stop for good.
    Done,
    /// The connection was lost or failed: reconnect.
    Lost(String),
}

/// What the operator asked for, kept across reconnections.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Intent {
    Fly,
    Land,
    Stop,
}

/// Runs sessions for `uri` until the link is dropped and the Crazyflie is down.
pub async fn supervise(uri: String, config: RelayConfig, shared: Arc<Shared>, mut channels: Channels) {
    let mut intent = Intent::Fly;
    let cache = MemoryTocCache::default();
    let mut connected_before = false;
    let mut failures = 0u32;
    loop {
        if !matches!(shared.phase(), LinkPhase::Landed | LinkPhase::Stopped) {
            shared.set_phase(LinkPhase::Connecting);
        }
        // The session runs in its own task so a panic in the client library ends only the session.
        let limit = if connected_before { config.reconnect_timeout } else { config.connect_timeout };
        let run = session(uri.clone(), config, shared.clone(), channels, intent, cache.clone(), limit);
        let (end, back) = match tokio::spawn(run).await {
            Ok((end, back, last_intent, connected)) => {
                intent = last_intent;
                connected_before |= connected;
                failures = if connected { 0 } else { failures.saturating_add(1) };
                (end, back)
            }
            Err(e) => {
                // The channels went down with the task: the link can no longer be flown. The fleet
                // sees no more states and treats the UAV as lost; its watchdog brings it down.
                shared.set_phase(LinkPhase::Connecting);
                shared.set_error(Some(format!("session task failed: {e}")));
                return;
            }
        };
        channels = back;
        match end {
            End::Done => return,
            End::Lost(reason) => {
                shared.set_error(Some(reason));
                if channels.urgent.is_closed() && !shared.phase().airborne() {
                    return;
                }
                tokio::time::sleep(retry_delay(config.reconnect_after, failures)).await;
            }
        }
    }
}

/// The wait before the next attempt: `base` for the first three failed attempts in a row (a
/// Crazyflie lost in flight must be back within its watchdog's 2 s), then doubling up to 2 s so an
/// absent Crazyflie (or a mistyped URI) costs little.
pub fn retry_delay(base: f64, failures: u32) -> Duration {
    let doublings = failures.saturating_sub(3).min(16);
    Duration::from_secs_f64((base * f64::from(1u32 << doublings)).clamp(0.0, 2.0))
}

/// One session: connect (within `limit` seconds), then fly. Also says whether it connected.
async fn session(
    uri: String,
    config: RelayConfig,
    shared: Arc<Shared>,
    mut ch: Channels,
    mut intent: Intent,
    cache: MemoryTocCache,
    limit: f64,
) -> (End, Channels, Intent, bool) {
    let connect = async {
        let link = open(&uri).await.map_err(|e| e.to_string())?;
        Crazyflie::connect_from_link(link, cache).await.map_err(|e| format!("connect: {e}"))
    };
    let cf = match timeout(Duration::from_secs_f64(limit), connect).await {
        Ok(Ok(cf)) => cf,
        Ok(Err(e)) => return (End::Lost(e), ch, intent, false),
        Err(_) => return (End::Lost(format!("connect: timed out after {limit} s")), ch, intent, false),
    };
    let end = fly(&cf, config, &shared, &mut ch, &mut intent).await;
    cf.disconnect().await;
    (end, ch, intent, true)
}

/// The tables of contents of one Crazyflie, kept across its reconnections.
#[derive(Clone, Default)]
struct MemoryTocCache(Arc<std::sync::Mutex<std::collections::HashMap<Vec<u8>, String>>>);

impl TocCache for MemoryTocCache {
    fn get_toc(&self, key: &[u8]) -> Option<String> {
        self.0.lock().unwrap_or_else(std::sync::PoisonError::into_inner).get(key).cloned()
    }

    fn store_toc(&self, key: &[u8], toc: &str) {
        self.0
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .insert(key.to_vec(), toc.to_string());
    }
}

async fn start_log(
    cf: &Crazyflie,
    period_ms: u64,
) -> Result<crazyflie_lib::subsystems::log::LogStream, String> {
    let mut block = cf.log.create_block().await.map_err(|e| format!("log block: {e}"))?;
    for name in STATE_VARIABLES {
        block.add_variable(name).await.map_err(|e| format!("log variable {name}: {e}"))?;
    }
    let period = LogPeriod::from_millis(period_ms).map_err(|e| format!("log period: {e}"))?;
    block.start(period).await.map_err(|e| format!("log start: {e}"))
}

/// Flies one connected session; returns when the connection is lost or the link is dropped and
/// the Crazyflie is down.
async fn fly(
    cf: &Crazyflie,
    config: RelayConfig,
    shared: &Shared,
    ch: &mut Channels,
    intent: &mut Intent,
) -> End {
    let stream = match start_log(cf, config.log_period_ms).await {
        Ok(s) => s,
        Err(e) => return End::Lost(e),
    };
    let stale = Duration::from_secs_f64(config.stale_after);
    // The first sample tells whether it is on the ground (a first connection or after a crash) or
    // still in the air (a reconnection within the watchdog's time).
    let first = match timeout(stale.max(Duration::from_secs(1)), stream.next()).await {
        Ok(Ok(data)) => data,
        Ok(Err(e)) => return End::Lost(format!("log: {e}")),
        Err(_) => return End::Lost("no state from the log block".into()),
    };
    let Some((p, v)) = decode(&first.data) else { return End::Lost("log data without the state".into()) };
    shared.set_sample(p, v);
    shared.set_error(None);
    let hl = &cf.high_level_commander;
    let mut phase_until = None;
    let on_ground = p[2] < ON_GROUND_M;
    match (*intent, on_ground) {
        (Intent::Fly, true) if !ch.urgent.is_closed() => {
            if let Err(e) = hl.take_off(config.altitude as f32, None, config.takeoff_s as f32, None).await {
                return End::Lost(format!("take-off: {e}"));
            }
            shared.set_phase(LinkPhase::TakingOff);
            phase_until = Some(Instant::now() + Duration::from_secs_f64(config.takeoff_s + 0.2));
        }
        (Intent::Fly, false) => shared.set_phase(LinkPhase::Flying),
        (Intent::Stop, _) => shared.set_phase(LinkPhase::Stopped),
        (_, true) => shared.set_phase(LinkPhase::Landed),
        (Intent::Land, false) => {
            if let Err(e) = land(cf, config).await {
                return End::Lost(e);
            }
            shared.set_phase(LinkPhase::Landing);
            phase_until = Some(Instant::now() + Duration::from_secs_f64(config.land_s + 0.2));
        }
    }
    let (mut urgent_open, mut setpoints_open) = (true, true);
    let mut last_sample = Instant::now();
    loop {
        if !urgent_open && matches!(shared.phase(), LinkPhase::Landed | LinkPhase::Stopped) {
            return End::Done;
        }
        tokio::select! {
            biased;
            request = ch.urgent.recv(), if urgent_open => {
                let request = match request {
                    Some(r) => r,
                    None => {
                        // The link was dropped (UAV removed, server shutting down): land.
                        urgent_open = false;
                        Urgent::Land
                    }
                };
                match request {
                    Urgent::Stop => {
                        *intent = Intent::Stop;
                        if let Err(e) = emergency_stop(cf).await {
                            return End::Lost(e);
                        }
                        shared.set_phase(LinkPhase::Stopped);
                    }
                    Urgent::Land if shared.phase().airborne() => {
                        *intent = Intent::Land;
                        if let Err(e) = land(cf, config).await {
                            return End::Lost(e);
                        }
                        shared.set_phase(LinkPhase::Landing);
                        phase_until = Some(Instant::now() + Duration::from_secs_f64(config.land_s + 0.2));
                    }
                    Urgent::Land => *intent = Intent::Land,
                }
            }
            data = stream.next() => match data {
                Ok(data) => {
                    if let Some((p, v)) = decode(&data.data) {
                        shared.set_sample(p, v);
                        last_sample = Instant::now();
                    }
                }
                Err(e) => return End::Lost(format!("log: {e}")),
            },
            _ = sleep_until(last_sample + stale) => {
                return End::Lost(format!("no state for {} ms", stale.as_millis()));
            }
            changed = ch.setpoints.changed(), if setpoints_open => {
                if changed.is_err() {
                    // The link is gone (its urgent channel closes with it): no more setpoints.
                    setpoints_open = false;
                    continue;
                }
                let setpoint = *ch.setpoints.borrow_and_update();
                let fresh = shared.sample().is_some_and(|s| s.at.elapsed() <= stale);
                if let (Some(sp), LinkPhase::Flying, true) = (setpoint, shared.phase(), fresh) {
                    let sent = cf.commander.setpoint_full_state(sp.p, sp.v, sp.a, LEVEL, [0.0; 3]).await;
                    if let Err(e) = sent {
                        return End::Lost(format!("setpoint: {e}"));
                    }
                }
            }
            Some(position) = ch.external.recv() => {
                if let Err(e) = cf.localization.external_pose.send_external_position(position).await {
                    return End::Lost(format!("external position: {e}"));
                }
            }
            _ = sleep_until(phase_until.unwrap_or_else(far_future)), if phase_until.is_some() => {
                phase_until = None;
                match shared.phase() {
                    LinkPhase::TakingOff if *intent == Intent::Fly => shared.set_phase(LinkPhase::Flying),
                    LinkPhase::Landing => shared.set_phase(LinkPhase::Landed),
                    _ => {}
                }
            }
        }
    }
}

/// Cuts the motors: the supervisor's stop (current firmware) and the localization service's (older
/// firmware, which has no supervisor port); a Crazyflie acts on whichever it knows.
async fn emergency_stop(cf: &Crazyflie) -> Result<(), String> {
    let supervisor = cf.supervisor.send_emergency_stop().await;
    #[allow(deprecated)] // still the only stop older firmware understands
    let localization = cf.localization.emergency.send_emergency_stop().await;
    supervisor.or(localization).map_err(|e| format!("emergency stop: {e}"))
}

/// Hands control back to the high-level commander and lands.
async fn land(cf: &Crazyflie, config: RelayConfig) -> Result<(), String> {
    cf.commander.notify_setpoint_stop(0).await.map_err(|e| format!("setpoint stop: {e}"))?;
    cf.high_level_commander
        .land(0.0, None, config.land_s as f32, None)
        .await
        .map_err(|e| format!("land: {e}"))
}

fn far_future() -> Instant {
    Instant::now() + Duration::from_secs(3600)
}

/// Position and velocity from one log sample, if every variable is there and finite.
fn decode(data: &std::collections::HashMap<String, crazyflie_lib::Value>) -> Option<([f64; 3], [f64; 3])> {
    let mut values = [0.0; 6];
    for (slot, name) in values.iter_mut().zip(STATE_VARIABLES) {
        *slot = data.get(name)?.to_f64_lossy();
        if !slot.is_finite() {
            return None;
        }
    }
    Some(([values[0], values[1], values[2]], [values[3], values[4], values[5]]))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn retries_fast_after_a_loss_then_back_off_to_two_seconds() {
        let delays: Vec<f64> = (0..12).map(|n| retry_delay(0.1, n).as_secs_f64()).collect();
        assert_eq!(&delays[..4], &[0.1; 4]);
        assert!((delays[4] - 0.2).abs() < 1e-12 && (delays[5] - 0.4).abs() < 1e-12);
        assert_eq!(delays[11], 2.0);
        assert_eq!(retry_delay(0.1, u32::MAX), Duration::from_secs(2));
    }
}
