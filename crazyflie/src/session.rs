//! The task behind one [`crate::CrazyflieLink`]: connect over CRTP, take off with the high-level
//! commander, stream a full-state setpoint for every command while the state is fresh, forward
//! motion-capture positions, land or stop on request, and reconnect after a loss. A failure here
//! (an error, even a panic inside the client library) ends one session, never the server: the
//! supervisor records it, waits and reconnects.

use crate::confirm::{STATUS_VARIABLES, Status};
use crate::machine::{Action, End, Event, Intent, Machine};
use crate::prepare::{SharedTocCache, ready_for_take_off, set_controller};
use crate::relay::{RelayConfig, Setpoint, Shared, Urgent};
use crate::transport::open;
use crazyflie_lib::Crazyflie;
use crazyflie_lib::subsystems::log::LogPeriod;
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

/// Longest wait for the client library's disconnect after a detach or the end of a session.
const DISCONNECT_WAIT: Duration = Duration::from_millis(500);

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
    /// Becomes true when the link is to be closed without landing (`Link::detach`).
    pub detach: watch::Receiver<bool>,
}

/// Resolves once a detach has been asked for (never, if the link is gone without one).
async fn detach_asked(detach: &mut watch::Receiver<bool>) {
    if detach.wait_for(|asked| *asked).await.is_err() {
        std::future::pending::<()>().await;
    }
}

/// The operator's words for a session task that ended without returning (a panic in the client
/// library: for a radio link, typically no Crazyradio, or one this user may not open).
fn task_failure(uri: &str, e: tokio::task::JoinError) -> String {
    if !e.is_panic() {
        return format!("session task failed: {e}");
    }
    let payload = e.into_panic();
    let message = payload
        .downcast_ref::<&str>()
        .map(|s| s.to_string())
        .or_else(|| payload.downcast_ref::<String>().cloned())
        .unwrap_or_else(|| "no message".into());
    let hint = if uri.starts_with("radio://") { "; is a Crazyradio plugged in and accessible?" } else { "" };
    format!("the Crazyflie library failed on {uri}: {message}{hint}")
}

/// Runs sessions for `uri` until the link is dropped and the Crazyflie is down, or until the link
/// is detached (then the connection is closed, whichever way the sessions ended, and
/// [`Shared::detached`] says so).
pub async fn supervise(uri: String, config: RelayConfig, shared: Arc<Shared>, channels: Channels) {
    let detach = channels.detach.clone();
    run_sessions(uri, config, shared.clone(), channels).await;
    if *detach.borrow() {
        shared.set_detached();
    }
}

/// The sessions of [`supervise`], one after another.
async fn run_sessions(uri: String, config: RelayConfig, shared: Arc<Shared>, mut channels: Channels) {
    let mut intent = Intent::Fly;
    let cache = SharedTocCache::process();
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
                shared.set_error(Some(task_failure(&uri, e)));
                return;
            }
        };
        channels = back;
        match end {
            End::Done => return,
            End::Detached => return,
            End::Lost(reason) => {
                shared.set_error(Some(reason));
                // Not connected: no quality to speak of (the supervisor's last word stays).
                shared.update_report(|r| r.link_quality = Some(0.0));
                if channels.urgent.is_closed() && !shared.phase().airborne() {
                    return;
                }
                tokio::select! {
                    () = tokio::time::sleep(retry_delay(config.reconnect_after, failures)) => {}
                    () = detach_asked(&mut channels.detach) => return,
                }
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
    cache: SharedTocCache,
    limit: f64,
) -> (End, Channels, Intent, bool) {
    let connect = async {
        let link = open(&uri).await.map_err(|e| e.to_string())?;
        Crazyflie::connect_from_link(link, cache).await.map_err(|e| format!("connect: {e}"))
    };
    let connected = tokio::select! {
        biased;
        () = detach_asked(&mut ch.detach) => return (End::Detached, ch, intent, false),
        connected = timeout(Duration::from_secs_f64(limit), connect) => connected,
    };
    let cf = match connected {
        Ok(Ok(cf)) => cf,
        Ok(Err(e)) => return (End::Lost(e), ch, intent, false),
        Err(_) => return (End::Lost(format!("connect: timed out after {limit} s")), ch, intent, false),
    };
    let mut detach = ch.detach.clone();
    let end = tokio::select! {
        // Detach first: a link detached and then dropped must not be taken for one dropped alone
        // (which lands).
        biased;
        () = detach_asked(&mut detach) => End::Detached,
        end = fly(&cf, config, &shared, &mut ch, &mut intent, limit) => end,
    };
    // Bounded: a closed link is what the next owner waits for, and the socket closes when `cf`
    // is dropped in any case.
    let _ = timeout(DISCONNECT_WAIT, cf.disconnect()).await;
    (end, ch, intent, true)
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

/// Starts the status block: those of [`STATUS_VARIABLES`] the firmware logs (none: no block, and
/// no stop or landing can be confirmed).
async fn start_status_log(
    cf: &Crazyflie,
    period_ms: u64,
) -> Result<Option<crazyflie_lib::subsystems::log::LogStream>, String> {
    let names = cf.log.names();
    let available: Vec<&str> =
        STATUS_VARIABLES.into_iter().filter(|v| names.iter().any(|n| n == v)).collect();
    if available.is_empty() {
        return Ok(None);
    }
    let mut block = cf.log.create_block().await.map_err(|e| format!("status log block: {e}"))?;
    for name in available {
        block.add_variable(name).await.map_err(|e| format!("log variable {name}: {e}"))?;
    }
    let period = LogPeriod::from_millis(period_ms).map_err(|e| format!("status log period: {e}"))?;
    block.start(period).await.map(Some).map_err(|e| format!("status log start: {e}"))
}

/// The next sample of the status block; never resolves without one.
async fn next_status(
    stream: Option<&crazyflie_lib::subsystems::log::LogStream>,
) -> crazyflie_lib::Result<crazyflie_lib::subsystems::log::LogData> {
    match stream {
        Some(s) => s.next().await,
        None => std::future::pending().await,
    }
}

/// Sends `request` once.
async fn send(cf: &Crazyflie, config: RelayConfig, request: Urgent) -> Result<(), String> {
    match request {
        Urgent::Stop => emergency_stop(cf).await,
        Urgent::Land => land(cf, config).await,
    }
}

/// Counts the state samples of the last second against the log block's period: the link quality
/// of [`links::VehicleReport`].
struct QualityWindow {
    since: Instant,
    samples: u32,
}

impl QualityWindow {
    fn new() -> Self {
        Self { since: Instant::now(), samples: 0 }
    }

    /// One more sample; every second, the fraction of the expected ones that came.
    fn sample(&mut self, shared: &Shared, period_ms: u64) {
        self.samples += 1;
        let elapsed = self.since.elapsed();
        if elapsed >= Duration::from_secs(1) {
            let expected = elapsed.as_secs_f64() * 1000.0 / period_ms.max(1) as f64;
            let quality = (f64::from(self.samples) / expected).clamp(0.0, 1.0);
            shared.update_report(|r| r.link_quality = Some(quality));
            *self = Self::new();
        }
    }
}

/// The connect preparation of a Crazyflie on the ground ([`Action::Prepare`]): the controller,
/// then the commander and the supervisor (`crate::prepare`).
async fn prepare(cf: &Crazyflie, config: RelayConfig) -> Result<(), String> {
    if let Some(controller) = config.controller {
        set_controller(cf, controller).await?;
    }
    ready_for_take_off(cf).await.map(|_| ())
}

/// Resolves with the preparation's result, or never without one.
async fn prepared(preparing: &mut Option<Preparing<'_>>) -> Result<(), String> {
    match preparing {
        Some(future) => future.await,
        None => std::future::pending().await,
    }
}

/// A running [`prepare`].
type Preparing<'a> = std::pin::Pin<Box<dyn std::future::Future<Output = Result<(), String>> + Send + 'a>>;

/// Flies one connected session: the shell of [`Machine`]. It turns the Crazyflie's log, the
/// link's channels and the time into events and carries out the machine's actions; returns when
/// the machine ends the session or an I/O call fails (the connection is lost). The log blocks are
/// set up within `limit` seconds, like the connection: crazyflie-lib waits for each answer without
/// a bound, and a lossy link without retransmission (UDP) may lose one.
async fn fly(
    cf: &Crazyflie,
    config: RelayConfig,
    shared: &Shared,
    ch: &mut Channels,
    intent: &mut Intent,
    limit: f64,
) -> End {
    let blocks = async {
        let state = start_log(cf, config.log_period_ms).await?;
        let status = start_status_log(cf, config.status_period_ms).await?;
        Ok::<_, String>((state, status))
    };
    let (stream, status_stream) = match timeout(Duration::from_secs_f64(limit), blocks).await {
        Ok(Ok(streams)) => streams,
        Ok(Err(e)) => return End::Lost(e),
        Err(_) => return End::Lost(format!("log blocks: not set up within {limit} s")),
    };
    let mut machine =
        Machine::new(config, *intent, shared.phase(), !ch.urgent.is_closed(), Instant::now().into());
    let mut quality = QualityWindow::new();
    let mut preparing: Option<Preparing<'_>> = None;
    let mut actions = Vec::new();
    loop {
        let deadline = Instant::from_std(machine.next_deadline());
        let event = tokio::select! {
            biased;
            request = ch.urgent.recv(), if machine.urgent_open() => match request {
                Some(request) => Event::Urgent(request),
                None => Event::LinkDropped,
            },
            data = stream.next() => match data {
                Ok(data) => {
                    let Some((p, v)) = decode(&data.data) else { continue };
                    shared.set_sample(p, v);
                    quality.sample(shared, config.log_period_ms);
                    Event::Sample { z: p[2] }
                }
                Err(e) => return End::Lost(format!("log: {e}")),
            },
            data = next_status(status_stream.as_ref()) => match data {
                Ok(data) => {
                    let status = decode_status(&data.data);
                    shared.update_report(|r| {
                        r.supervisor_info = status.info.or(r.supervisor_info);
                        r.battery_v = status.vbat.or(r.battery_v);
                    });
                    Event::Status(status)
                }
                Err(e) => return End::Lost(format!("status log: {e}")),
            },
            result = prepared(&mut preparing) => {
                preparing = None;
                Event::Prepared(result)
            }
            () = sleep_until(deadline) => Event::Time,
            changed = ch.setpoints.changed(), if machine.setpoints_open() => match changed {
                Err(_) => Event::SetpointsClosed,
                Ok(()) => match *ch.setpoints.borrow_and_update() {
                    Some(sp) => Event::Setpoint(sp),
                    None => continue,
                },
            },
            Some(position) = ch.external.recv() => {
                if let Err(e) = cf.localization.external_pose.send_external_position(position).await {
                    return End::Lost(format!("external position: {e}"));
                }
                continue;
            }
        };
        machine.handle(Instant::now().into(), event, &mut actions);
        *intent = machine.intent();
        for action in actions.drain(..) {
            let done = match action {
                Action::Prepare => {
                    preparing = Some(Box::pin(prepare(cf, config)));
                    Ok(())
                }
                Action::TakeOff => cf
                    .high_level_commander
                    .take_off(config.altitude as f32, None, config.takeoff_s as f32, None)
                    .await
                    .map_err(|e| format!("take-off: {e}")),
                Action::Send(request) => send(cf, config, request).await,
                Action::SendSetpoint(sp) => cf
                    .commander
                    .setpoint_full_state(sp.p, sp.v, sp.a, LEVEL, [0.0; 3])
                    .await
                    .map_err(|e| format!("setpoint: {e}")),
                Action::SetPhase(phase) => {
                    shared.set_phase(phase);
                    Ok(())
                }
                Action::SetError(error) => {
                    shared.set_error(error);
                    Ok(())
                }
                Action::RecordUnconfirmed => {
                    shared.record_unconfirmed();
                    Ok(())
                }
                Action::End(end) => return end,
            };
            if let Err(e) = done {
                return End::Lost(e);
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

/// Lands with the high-level commander, then hands control back to it. In this order the planner
/// is landing before the low-level setpoint is given up: the other way round, until the land
/// packet arrives nothing holds the Crazyflie up (the stopped setpoint counts as 2 s old, past the
/// watchdog's motor cut-off). Sent again, a land is refused by a planner already landing or idle.
async fn land(cf: &Crazyflie, config: RelayConfig) -> Result<(), String> {
    cf.high_level_commander
        .land(0.0, None, config.land_s as f32, None)
        .await
        .map_err(|e| format!("land: {e}"))?;
    cf.commander.notify_setpoint_stop(0).await.map_err(|e| format!("setpoint stop: {e}"))
}

/// What one sample of the status block says (a variable missing or out of range is unknown).
fn decode_status(data: &std::collections::HashMap<String, crazyflie_lib::Value>) -> Status {
    let value = |name: &str| data.get(name).map(|v| v.to_f64_lossy()).filter(|x| x.is_finite());
    let [info, thrust, vbat] = STATUS_VARIABLES;
    Status {
        // u16 in the firmware; anything else is not a bitfield.
        info: value(info).filter(|x| (0.0..=f64::from(u16::MAX)).contains(x)).map(|x| x as u16),
        thrust: value(thrust),
        vbat: value(vbat).filter(|v| *v >= 0.0),
    }
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
