//! The task behind one [`crate::CrazyflieLink`]: connect over CRTP, take off with the high-level
//! commander, stream a full-state setpoint for every command while the state is fresh, forward
//! motion-capture positions, land or stop on request, and reconnect after a loss. A failure here
//! (an error, even a panic inside the client library) ends one session, never the server: the
//! supervisor records it, waits and reconnects.

use crate::confirm::{ON_GROUND_M, STATUS_VARIABLES, Status};
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

/// How a session ended.
enum End {
    /// The link was dropped and the Crazyflie is down: stop for good.
    Done,
    /// The connection was lost or failed: reconnect.
    Lost(String),
    /// The link asked to be closed without landing (a handover to another server): stop for good.
    Detached,
}

/// What the operator asked for, kept across reconnections.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Intent {
    Fly,
    Land,
    Stop,
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
        end = fly(&cf, config, &shared, &mut ch, &mut intent) => end,
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

/// A stop or a landing sent and not yet confirmed by the Crazyflie.
#[derive(Debug, Clone, Copy)]
struct Pending {
    request: Urgent,
    since: Instant,
    /// When to send it again.
    resend_at: Instant,
    /// When to give up.
    deadline: Instant,
    /// The bound passed without a confirmation: reported, no longer resent.
    given_up: bool,
}

impl Pending {
    /// The next time something has to happen: a resend or giving up.
    fn wake_at(&self) -> Option<Instant> {
        (!self.given_up).then(|| self.resend_at.min(self.deadline))
    }
}

/// The phase shown while `request` waits for its confirmation, and once confirmed.
fn phases(request: Urgent) -> (LinkPhase, LinkPhase) {
    match request {
        Urgent::Stop => (LinkPhase::Stopping, LinkPhase::Stopped),
        Urgent::Land => (LinkPhase::Landing, LinkPhase::Landed),
    }
}

/// Sends `request` once.
async fn send(cf: &Crazyflie, config: RelayConfig, request: Urgent) -> Result<(), String> {
    match request {
        Urgent::Stop => emergency_stop(cf).await,
        Urgent::Land => land(cf, config).await,
    }
}

/// Sends `request` and waits for the Crazyflie to confirm it (the phase says so meanwhile).
async fn start(
    cf: &Crazyflie,
    config: RelayConfig,
    shared: &Shared,
    request: Urgent,
) -> Result<Pending, String> {
    let (waiting, _) = phases(request);
    // The phase first: whatever happens to the packets, the operator never sees less than this.
    shared.set_phase(waiting);
    send(cf, config, request).await?;
    let now = Instant::now();
    Ok(Pending {
        request,
        since: now,
        resend_at: now + Duration::from_secs_f64(config.resend_every.max(0.01)),
        deadline: now + config.confirm_bound(request),
        given_up: false,
    })
}

/// Sets the confirmed phase if the Crazyflie's log confirms the pending request.
fn check_confirmed(shared: &Shared, status: &Status, pending: &mut Option<Pending>) {
    let Some(p) = *pending else { return };
    let confirmed = match p.request {
        Urgent::Stop => status.confirms_stop(),
        Urgent::Land => shared.sample().is_some_and(|s| status.confirms_landed(s.p[2])),
    };
    if !confirmed {
        return;
    }
    shared.set_phase(phases(p.request).1);
    if p.given_up {
        let after = p.since.elapsed().as_secs_f64();
        shared.set_error(Some(format!(
            "{} confirmed late, {after:.1} s after the request",
            p.request.describe()
        )));
    }
    *pending = None;
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

/// Sets the phase to flying once the firmware confirms the take-off (then nothing waits for its
/// deadline any more).
fn check_airborne(
    shared: &Shared,
    status: &Status,
    config: RelayConfig,
    intent: Intent,
    until: &mut Option<Instant>,
) {
    if shared.phase() != LinkPhase::TakingOff || intent != Intent::Fly {
        return;
    }
    if shared.sample().is_some_and(|s| status.confirms_airborne(s.p[2], config.altitude)) {
        shared.set_phase(LinkPhase::Flying);
        *until = None;
    }
}

/// Flies one connected session; returns when the connection is lost or the link is dropped and
/// the Crazyflie is down (or a stop or landing was given up on).
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
    let status_stream = match start_status_log(cf, config.status_period_ms).await {
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
    // What the Crazyflie said in this session; nothing is confirmed before it speaks.
    let mut status = Status::default();
    let mut pending: Option<Pending> = None;
    let on_ground = p[2] < ON_GROUND_M;
    let request = match (*intent, on_ground) {
        (Intent::Fly, true) if !ch.urgent.is_closed() => {
            if let Some(controller) = config.controller
                && let Err(e) = set_controller(cf, controller).await
            {
                return End::Lost(e);
            }
            if let Err(e) = ready_for_take_off(cf).await {
                return End::Lost(e);
            }
            if let Err(e) = hl.take_off(config.altitude as f32, None, config.takeoff_s as f32, None).await {
                return End::Lost(format!("take-off: {e}"));
            }
            shared.set_phase(LinkPhase::TakingOff);
            phase_until = Some(Instant::now() + config.takeoff_bound());
            None
        }
        (Intent::Fly, false) => {
            shared.set_phase(LinkPhase::Flying);
            None
        }
        // Stopped before (or during) a loss: stop again; a Crazyflie still locked confirms at once.
        (Intent::Stop, _) => Some(Urgent::Stop),
        // Landed, landing, or on the ground with the link dropped: landed once it says so.
        (Intent::Land | Intent::Fly, _) => {
            *intent = Intent::Land;
            Some(Urgent::Land)
        }
    };
    if let Some(request) = request {
        match start(cf, config, shared, request).await {
            Ok(p) => pending = Some(p),
            Err(e) => return End::Lost(e),
        }
    }
    let (mut urgent_open, mut setpoints_open) = (true, true);
    let mut last_sample = Instant::now();
    let mut quality = QualityWindow::new();
    loop {
        let settled = matches!(shared.phase(), LinkPhase::Landed | LinkPhase::Stopped)
            || pending.is_some_and(|p| p.given_up);
        if !urgent_open && settled {
            return End::Done;
        }
        let wake_at = pending.and_then(|p| p.wake_at());
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
                let phase = shared.phase();
                let restart = match request {
                    // A stop outranks everything, and is never replaced by a landing.
                    Urgent::Stop => {
                        *intent = Intent::Stop;
                        match pending {
                            // Already on its way: one more copy now, the bound runs from the first.
                            Some(p) if p.request == Urgent::Stop && !p.given_up => {
                                if let Err(e) = send(cf, config, Urgent::Stop).await {
                                    return End::Lost(e);
                                }
                                false
                            }
                            _ => phase != LinkPhase::Stopped,
                        }
                    }
                    Urgent::Land if *intent == Intent::Stop => false,
                    Urgent::Land => {
                        *intent = Intent::Land;
                        // Taking off or flying; or asked again after a landing was given up on.
                        matches!(phase, LinkPhase::TakingOff | LinkPhase::Flying)
                            || pending.is_some_and(|p| p.request == Urgent::Land && p.given_up)
                    }
                };
                if restart {
                    match start(cf, config, shared, request).await {
                        Ok(p) => pending = Some(p),
                        Err(e) => return End::Lost(e),
                    }
                    check_confirmed(shared, &status, &mut pending);
                }
            }
            data = stream.next() => match data {
                Ok(data) => {
                    if let Some((p, v)) = decode(&data.data) {
                        shared.set_sample(p, v);
                        last_sample = Instant::now();
                        quality.sample(shared, config.log_period_ms);
                        check_confirmed(shared, &status, &mut pending);
                        check_airborne(shared, &status, config, *intent, &mut phase_until);
                    }
                }
                Err(e) => return End::Lost(format!("log: {e}")),
            },
            data = next_status(status_stream.as_ref()) => match data {
                Ok(data) => {
                    status = decode_status(&data.data);
                    shared.update_report(|r| {
                        r.supervisor_info = status.info.or(r.supervisor_info);
                        r.battery_v = status.vbat.or(r.battery_v);
                    });
                    check_confirmed(shared, &status, &mut pending);
                    check_airborne(shared, &status, config, *intent, &mut phase_until);
                }
                Err(e) => return End::Lost(format!("status log: {e}")),
            },
            _ = sleep_until(last_sample + stale) => {
                return End::Lost(format!("no state for {} ms", stale.as_millis()));
            }
            _ = sleep_until(wake_at.unwrap_or_else(far_future)), if wake_at.is_some() => {
                let Some(p) = pending.as_mut() else { continue };
                let now = Instant::now();
                if now >= p.deadline {
                    // Reported, never shown confirmed: the phase stays stopping/landing.
                    p.given_up = true;
                    let bound = config.confirm_bound(p.request).as_secs_f64();
                    shared.set_error(Some(format!("{} not confirmed after {bound} s", p.request.describe())));
                    shared.record_unconfirmed();
                } else {
                    p.resend_at = now + Duration::from_secs_f64(config.resend_every.max(0.01));
                    if let Err(e) = send(cf, config, p.request).await {
                        return End::Lost(e);
                    }
                }
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
                if shared.phase() == LinkPhase::TakingOff && *intent == Intent::Fly {
                    // The firmware never said it was up: bring it down rather than fly it.
                    let z = shared.sample().map_or(f64::NAN, |s| s.p[2]);
                    shared.set_error(Some(format!(
                        "take-off not confirmed after {} s (height {z:.2} m, supervisor.info {}, thrust {})",
                        config.takeoff_bound().as_secs_f64(),
                        status.info.map_or("not logged".into(), |i| format!("{i:#06x}")),
                        status.thrust.map_or("not logged".into(), |t| format!("{t:.0}")),
                    )));
                    shared.record_unconfirmed();
                    *intent = Intent::Land;
                    match start(cf, config, shared, Urgent::Land).await {
                        Ok(p) => pending = Some(p),
                        Err(e) => return End::Lost(e),
                    }
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

fn far_future() -> Instant {
    Instant::now() + Duration::from_secs(3600)
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
