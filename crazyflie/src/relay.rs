//! [`CrazyflieLink`]: the fleet's [`Link`] to one Crazyflie. The fleet loop's side is synchronous and
//! never waits: it reads the newest state sample under a short lock and hands each tick's command
//! over on a `watch` channel (latest wins). A tokio task per Crazyflie ([`crate::session`]) owns the
//! CRTP connection: it connects, takes off, streams setpoints, lands, and reconnects after a loss.

use crate::session;
use links::{Link, LinkPhase, VehicleReport};
use std::sync::atomic::{AtomicBool, AtomicU8, AtomicU64, Ordering};
use std::sync::{Arc, Mutex, PoisonError};
use std::time::{Duration, Instant};
use tokio::sync::{mpsc, watch};
use uav::{UavState, Vec2};

/// How a Crazyflie is flown.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RelayConfig {
    /// Flight altitude z (m); the fleet works in the horizontal plane at this height.
    pub altitude: f64,
    /// Duration of the high-level commander's take-off (s).
    pub takeoff_s: f64,
    /// Duration of the high-level commander's landing (s).
    pub land_s: f64,
    /// Period of the state log block (ms, 10–20 typical).
    pub log_period_ms: u64,
    /// A state older than this is not given to the fleet, and no setpoint is sent on it (s).
    pub stale_after: f64,
    /// No state for this long ends the session and reconnects (s): its log blocks may be gone
    /// (a rebooted Crazyflie). A shorter gap in the state stream keeps the session, which flies on
    /// when the state comes back: a reconnection takes a dozen request–reply exchanges, and on a
    /// lossy link without retransmission (UDP) losing any of them fails it. A lost link ends the
    /// session sooner (the UDP link after 1 s of silence).
    pub relog_after: f64,
    /// Wait between reconnection attempts (s).
    pub reconnect_after: f64,
    /// Longest first connection, tables of contents included (s).
    pub connect_timeout: f64,
    /// Longest reconnection (s): the tables of contents are cached by then, and a Crazyflie must
    /// be back before its watchdog cuts the motors 2 s after the loss.
    pub reconnect_timeout: f64,
    /// The fleet's tick (s): a setpoint is the state the command leads to one tick ahead.
    pub dt: f64,
    /// Period of the status log block (`supervisor.info`, `stabilizer.thrust`) that confirms a
    /// stop or a landing (ms).
    pub status_period_ms: u64,
    /// An emergency stop or a landing is sent again this often until the Crazyflie confirms it (s).
    pub resend_every: f64,
    /// An emergency stop not confirmed within this time is given up and reported (s).
    pub stop_confirm_s: f64,
    /// A landing not confirmed within `land_s` plus this margin is given up and reported (s). It
    /// covers the firmware's 2 s before it stops calling itself flying once the thrust is idle.
    pub land_margin_s: f64,
    /// The firmware controller set on connect (`stabilizer.controller`, read back), or `None` to
    /// keep the Crazyflie's own. The full-state setpoints need one that follows their velocity and
    /// acceleration feed-forward: Mellinger ([`Controller::Mellinger`]); the default PID follows
    /// only their position.
    pub controller: Option<Controller>,
    /// A take-off the firmware has not confirmed (flying, within 0.15 m of the altitude) within
    /// `takeoff_s` plus this margin is reported and landed (s).
    pub takeoff_margin_s: f64,
}

/// The firmware's controllers, by their `stabilizer.controller` values.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Controller {
    /// PID (1), the firmware's default: follows a full-state setpoint's position only.
    Pid = 1,
    /// Mellinger (2): follows position, velocity and acceleration.
    Mellinger = 2,
}

impl Controller {
    /// The value of `stabilizer.controller`.
    pub fn value(self) -> u8 {
        self as u8
    }

    /// Parses `pid` or `mellinger`.
    pub fn parse(name: &str) -> Option<Self> {
        match name {
            "pid" => Some(Self::Pid),
            "mellinger" => Some(Self::Mellinger),
            _ => None,
        }
    }
}

impl Default for RelayConfig {
    fn default() -> Self {
        Self {
            altitude: 1.0,
            takeoff_s: 2.0,
            land_s: 2.0,
            log_period_ms: 10,
            stale_after: 0.3,
            relog_after: 1.0,
            reconnect_after: 0.1,
            connect_timeout: 15.0,
            reconnect_timeout: 1.0,
            dt: 0.05,
            status_period_ms: 20,
            resend_every: 0.15,
            stop_confirm_s: 3.0,
            land_margin_s: 3.0,
            controller: Some(Controller::Mellinger),
            takeoff_margin_s: 3.0,
        }
    }
}

/// One state estimate from the Crazyflie's log block.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sample {
    /// Position [x, y, z] (m).
    pub p: [f64; 3],
    /// Velocity [vx, vy, vz] (m/s).
    pub v: [f64; 3],
    /// When it arrived.
    pub at: Instant,
    /// Increases with every sample.
    pub seq: u64,
}

/// A full-state setpoint for the coming tick: where the filtered command leads.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Setpoint {
    /// Position [x, y, z] (m).
    pub p: [f32; 3],
    /// Velocity (m/s).
    pub v: [f32; 3],
    /// Acceleration feed-forward: the filtered input u (m/s²).
    pub a: [f32; 3],
    /// When the fleet handed the command over (for latency measurements).
    pub issued: Instant,
}

impl RelayConfig {
    /// A state older than this is stale ([`RelayConfig::stale_after`]).
    pub fn stale(&self) -> Duration {
        Duration::from_secs_f64(self.stale_after.clamp(0.0, 3600.0))
    }

    /// No state for this long ends the session ([`RelayConfig::relog_after`], never shorter
    /// than [`RelayConfig::stale`]).
    pub fn relog(&self) -> Duration {
        Duration::from_secs_f64(self.relog_after.clamp(0.0, 3600.0)).max(self.stale())
    }

    /// How often an unconfirmed stop or landing is sent again (at least every 10 ms).
    pub fn resend_period(&self) -> Duration {
        Duration::from_secs_f64(self.resend_every.clamp(0.01, 3600.0))
    }

    /// How long a take-off may wait for the firmware's confirmation before it is given up.
    pub fn takeoff_bound(&self) -> Duration {
        Duration::from_secs_f64((self.takeoff_s + self.takeoff_margin_s).clamp(0.0, 3600.0))
    }

    /// How long a request may wait for the Crazyflie's confirmation before it is given up.
    pub fn confirm_bound(&self, request: Urgent) -> Duration {
        let seconds = match request {
            Urgent::Stop => self.stop_confirm_s,
            Urgent::Land => self.land_s + self.land_margin_s,
        };
        Duration::from_secs_f64(seconds.clamp(0.0, 3600.0))
    }
}

/// A request that goes out ahead of any setpoint.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Urgent {
    /// Land with the high-level commander.
    Land,
    /// Emergency stop: motors off at once.
    Stop,
}

impl Urgent {
    /// What the operator asked for, in words.
    pub fn describe(&self) -> &'static str {
        match self {
            Urgent::Land => "landing",
            Urgent::Stop => "emergency stop",
        }
    }
}

/// State shared by the link (fleet thread) and its session task.
#[derive(Debug, Default)]
pub struct Shared {
    sample: Mutex<Option<Sample>>,
    phase: AtomicU8,
    /// The last connection error, or a request the Crazyflie did not confirm, for the operator.
    error: Mutex<Option<String>>,
    /// Stops and landings given up on without the Crazyflie's confirmation.
    unconfirmed: AtomicU64,
    /// The session closed the connection on a detach and ended.
    detached: AtomicBool,
    /// What the firmware last reported (supervisor, battery, link quality).
    report: Mutex<VehicleReport>,
}

impl Shared {
    /// The newest sample.
    pub fn sample(&self) -> Option<Sample> {
        *self.sample.lock().unwrap_or_else(PoisonError::into_inner)
    }

    /// Stores a new sample.
    pub fn set_sample(&self, p: [f64; 3], v: [f64; 3]) {
        let mut slot = self.sample.lock().unwrap_or_else(PoisonError::into_inner);
        let seq = slot.map_or(1, |s| s.seq + 1);
        *slot = Some(Sample { p, v, at: Instant::now(), seq });
    }

    /// The session's phase.
    pub fn phase(&self) -> LinkPhase {
        LinkPhase::ALL[usize::from(self.phase.load(Ordering::Acquire)).min(LinkPhase::ALL.len() - 1)]
    }

    /// Sets the session's phase.
    pub fn set_phase(&self, phase: LinkPhase) {
        let index = LinkPhase::ALL.iter().position(|p| *p == phase).unwrap_or(0);
        // LinkPhase::ALL has 7 entries: the index fits in a u8.
        self.phase.store(index as u8, Ordering::Release);
    }

    /// Records the last error.
    pub fn set_error(&self, error: Option<String>) {
        *self.error.lock().unwrap_or_else(PoisonError::into_inner) = error;
    }

    /// The last error: why the link is not connected, or a stop or landing the Crazyflie did not
    /// confirm in time (e.g. `emergency stop not confirmed after 3 s`).
    pub fn error(&self) -> Option<String> {
        self.error.lock().unwrap_or_else(PoisonError::into_inner).clone()
    }

    /// What the firmware last reported.
    pub fn report(&self) -> VehicleReport {
        *self.report.lock().unwrap_or_else(PoisonError::into_inner)
    }

    /// Changes the firmware's report.
    pub fn update_report(&self, change: impl FnOnce(&mut VehicleReport)) {
        change(&mut self.report.lock().unwrap_or_else(PoisonError::into_inner));
    }

    /// Records a request given up on without the Crazyflie's confirmation.
    pub fn record_unconfirmed(&self) {
        self.unconfirmed.fetch_add(1, Ordering::AcqRel);
    }

    /// Records that the connection was closed on a detach (the session has ended).
    pub fn set_detached(&self) {
        self.detached.store(true, Ordering::Release);
    }

    /// The connection was closed on a detach.
    pub fn detached(&self) -> bool {
        self.detached.load(Ordering::Acquire)
    }

    /// How many emergency stops and landings were given up on without the Crazyflie's confirmation
    /// since the link was created.
    pub fn unconfirmed_commands(&self) -> u64 {
        self.unconfirmed.load(Ordering::Acquire)
    }
}

/// Sends one Crazyflie an emergency stop straight to its session task, bypassing the fleet loop.
#[derive(Debug, Clone)]
pub struct StopHandle(mpsc::WeakUnboundedSender<Urgent>);

impl StopHandle {
    /// Sends the stop; false when the link is gone (nothing left to stop).
    pub fn stop(&self) -> bool {
        self.0.upgrade().is_some_and(|urgent| urgent.send(Urgent::Stop).is_ok())
    }
}

/// The fleet's link to one Crazyflie (`radio://…` through a Crazyradio, `udp://HOST:PORT` to a
/// simulator). Dropping it lands the Crazyflie, unless it was detached first.
pub struct CrazyflieLink {
    uri: String,
    config: RelayConfig,
    shared: Arc<Shared>,
    setpoints: watch::Sender<Option<Setpoint>>,
    detach: watch::Sender<bool>,
    urgent: mpsc::UnboundedSender<Urgent>,
    external: mpsc::Sender<[f32; 3]>,
    last_seq: u64,
}

impl CrazyflieLink {
    /// Starts the session task for `uri` on `runtime`. Nothing is awaited here: the task connects
    /// in the background and the link reports `connecting` until then.
    pub fn spawn(runtime: &tokio::runtime::Handle, uri: &str, config: RelayConfig) -> Self {
        let shared = Arc::new(Shared::default());
        let (setpoints, setpoint_rx) = watch::channel(None);
        let (urgent, urgent_rx) = mpsc::unbounded_channel();
        // Motion-capture poses: a short queue, the newest matter; full means drop (never block).
        let (external, external_rx) = mpsc::channel(8);
        let (detach, detach_rx) = watch::channel(false);
        let channels = session::Channels {
            setpoints: setpoint_rx,
            urgent: urgent_rx,
            external: external_rx,
            detach: detach_rx,
        };
        runtime.spawn(session::supervise(uri.to_string(), config, shared.clone(), channels));
        Self { uri: uri.to_string(), config, shared, setpoints, detach, urgent, external, last_seq: 0 }
    }

    /// The state shared with the session (phase, newest sample, last error).
    pub fn shared(&self) -> &Arc<Shared> {
        &self.shared
    }

    /// A handle that sends this Crazyflie an emergency stop from outside the fleet loop (which may
    /// be stalled); it does not keep the session alive.
    pub fn stop_handle(&self) -> StopHandle {
        StopHandle(self.urgent.downgrade())
    }

    /// A sender for motion-capture positions of this Crazyflie (forwarded as external position).
    pub fn external_position_sender(&self) -> mpsc::Sender<[f32; 3]> {
        self.external.clone()
    }
}

impl Link for CrazyflieLink {
    fn state(&mut self) -> Option<UavState> {
        let s = self.shared.sample()?;
        if s.seq == self.last_seq || s.at.elapsed() > Duration::from_secs_f64(self.config.stale_after) {
            return None;
        }
        self.last_seq = s.seq;
        Some(UavState { p: Vec2::new(s.p[0], s.p[1]), v: Vec2::new(s.v[0], s.v[1]) })
    }

    fn send(&mut self, u: Vec2) {
        let Some(s) = self.shared.sample() else { return };
        if !uav::is_finite(&u) {
            return;
        }
        let dt = self.config.dt;
        let state = UavState { p: Vec2::new(s.p[0], s.p[1]), v: Vec2::new(s.v[0], s.v[1]) };
        let next = state.stepped(u, dt);
        let setpoint = Setpoint {
            p: [next.p.x as f32, next.p.y as f32, self.config.altitude as f32],
            v: [next.v.x as f32, next.v.y as f32, 0.0],
            a: [u.x as f32, u.y as f32, 0.0],
            issued: Instant::now(),
        };
        self.setpoints.send_replace(Some(setpoint));
    }

    fn phase(&self) -> LinkPhase {
        self.shared.phase()
    }

    fn land(&mut self) {
        // Unbounded: never blocks; fails only when the session is gone (nothing left to land).
        let _ = self.urgent.send(Urgent::Land);
    }

    fn emergency_stop(&mut self) {
        let _ = self.urgent.send(Urgent::Stop);
    }

    fn describe(&self) -> &str {
        &self.uri
    }

    fn detach(&mut self) {
        self.detach.send_replace(true);
    }

    fn detached(&self) -> bool {
        self.shared.detached()
    }

    fn error(&self) -> Option<String> {
        self.shared.error()
    }

    fn unconfirmed_commands(&self) -> u64 {
        self.shared.unconfirmed_commands()
    }

    fn vehicle(&self) -> Option<VehicleReport> {
        Some(self.shared.report())
    }
}
