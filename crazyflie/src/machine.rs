//! What one connected session does, as a state machine without I/O: events in (a state sample,
//! a status sample, the operator's land or stop, a setpoint, the end of the connect preparation,
//! the passing of time), actions out (prepare, take off, send a stop or a landing, send a
//! setpoint, show a phase or an error, end the session). The session task ([`crate::session`])
//! is a thin shell: it turns the Crazyflie's log and the link's channels into events and carries
//! the actions out, so every rule below is written once and unit-tested without a Crazyflie.
//!
//! The rules: the first state sample decides (on the ground and asked to fly: prepare, then take
//! off; in the air: fly on; stopped or landing before a loss: send that again). A take-off, a
//! landing and a stop are done only when the Crazyflie's own log says so ([`Status`]); a stop or
//! landing is sent again every `resend_every` until then and given up (reported, never shown done)
//! after its bound; a take-off not confirmed within its bound is reported and landed. A stop
//! outranks everything and is never replaced by a landing. Setpoints go out only while flying on a
//! fresh state. No state for `relog_after` ends the session (the link or its log block is lost); a
//! shorter gap only withholds the setpoints, and the session flies on when the state comes back.

use crate::confirm::{ON_GROUND_M, Status};
use crate::relay::{RelayConfig, Setpoint, Urgent};
use links::LinkPhase;
use std::time::{Duration, Instant};

/// What the operator asked for, kept across reconnections.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Intent {
    /// Take off (if on the ground) and fly.
    Fly,
    /// Land, or stay landed.
    Land,
    /// Stop the motors, or keep them stopped.
    Stop,
}

/// How a session ended.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum End {
    /// The link was dropped and the Crazyflie is down: stop for good.
    Done,
    /// The connection was lost or failed: reconnect.
    Lost(String),
    /// The link asked to be closed without landing (a handover to another server): stop for good.
    Detached,
}

/// One input of the machine.
#[derive(Debug, Clone, PartialEq)]
pub enum Event {
    /// A state sample arrived (the shell has stored it); `z` is its height (m).
    Sample {
        /// Estimated height (m).
        z: f64,
    },
    /// A status sample arrived.
    Status(Status),
    /// The operator asked to land or stop.
    Urgent(Urgent),
    /// The link was dropped (UAV removed, server shutting down): land and end once down.
    LinkDropped,
    /// The fleet handed over a setpoint.
    Setpoint(Setpoint),
    /// The fleet's setpoint channel is gone.
    SetpointsClosed,
    /// The connect preparation ([`Action::Prepare`]) finished.
    Prepared(Result<(), String>),
    /// Time passed (a deadline of [`Machine::next_deadline`] may be due).
    Time,
}

/// One output of the machine, carried out by the shell in order.
#[derive(Debug, Clone, PartialEq)]
pub enum Action {
    /// Prepare the take-off (controller, stale setpoint, supervisor); answer with
    /// [`Event::Prepared`]. Other events keep coming meanwhile.
    Prepare,
    /// Take off with the high-level commander to `altitude` in `takeoff_s`.
    TakeOff,
    /// Send a stop or a landing once.
    Send(Urgent),
    /// Send a full-state setpoint.
    SendSetpoint(Setpoint),
    /// Show this phase.
    SetPhase(LinkPhase),
    /// Show this error (or none).
    SetError(Option<String>),
    /// Count a stop, landing or take-off given up on without the Crazyflie's confirmation.
    RecordUnconfirmed,
    /// End the session.
    End(End),
}

/// A stop or a landing sent and not yet confirmed by the Crazyflie.
#[derive(Debug, Clone, Copy, PartialEq)]
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

/// The session's state.
#[derive(Debug, Clone)]
pub struct Machine {
    config: RelayConfig,
    intent: Intent,
    phase: LinkPhase,
    /// What the Crazyflie said in this session; nothing is confirmed before it speaks.
    status: Status,
    /// The newest sample's height and arrival.
    sample: Option<(f64, Instant)>,
    /// Until when the first sample may take.
    first_sample_by: Instant,
    preparing: bool,
    pending: Option<Pending>,
    takeoff_by: Option<Instant>,
    urgent_open: bool,
    setpoints_open: bool,
}

impl Machine {
    /// A session just connected at `now`, showing `phase`, asked for `intent`; `urgent_open` is
    /// false when the link was dropped already.
    pub fn new(
        config: RelayConfig,
        intent: Intent,
        phase: LinkPhase,
        urgent_open: bool,
        now: Instant,
    ) -> Self {
        let first_wait = config.relog().max(Duration::from_secs(1));
        Self {
            config,
            intent,
            phase,
            status: Status::default(),
            sample: None,
            first_sample_by: now + first_wait,
            preparing: false,
            pending: None,
            takeoff_by: None,
            urgent_open,
            setpoints_open: true,
        }
    }

    /// What the operator asked for (kept for the next session).
    pub fn intent(&self) -> Intent {
        self.intent
    }

    /// Whether land and stop requests are still listened to.
    pub fn urgent_open(&self) -> bool {
        self.urgent_open
    }

    /// Whether setpoints are still listened to.
    pub fn setpoints_open(&self) -> bool {
        self.setpoints_open
    }

    /// When [`Event::Time`] must come at the latest.
    pub fn next_deadline(&self) -> Instant {
        let relog = match self.sample {
            Some((_, at)) => at + self.config.relog(),
            None => self.first_sample_by,
        };
        [Some(relog), self.pending.and_then(|p| p.wake_at()), self.takeoff_by]
            .into_iter()
            .flatten()
            .min()
            .unwrap_or(relog)
    }

    /// Handles `event` at `now`, appending the actions to `out`.
    pub fn handle(&mut self, now: Instant, event: Event, out: &mut Vec<Action>) {
        match event {
            Event::Sample { z } => {
                let first = self.sample.is_none();
                self.sample = Some((z, now));
                if first {
                    self.begin(now, z, out);
                }
                self.check_confirmed(now, out);
                self.check_airborne(out);
            }
            Event::Status(status) => {
                self.status = status;
                self.check_confirmed(now, out);
                self.check_airborne(out);
            }
            Event::Urgent(request) => self.urgent(now, request, out),
            Event::LinkDropped => {
                self.urgent_open = false;
                self.urgent(now, Urgent::Land, out);
            }
            Event::Setpoint(sp) => {
                let fresh = self
                    .sample
                    .is_some_and(|(_, at)| now.saturating_duration_since(at) <= self.config.stale());
                if self.phase == LinkPhase::Flying && fresh {
                    out.push(Action::SendSetpoint(sp));
                }
            }
            Event::SetpointsClosed => self.setpoints_open = false,
            Event::Prepared(result) => {
                self.preparing = false;
                match result {
                    Err(e) => out.push(Action::End(End::Lost(e))),
                    // A land or stop asked meanwhile has been handled already.
                    Ok(()) if self.intent == Intent::Fly && self.phase == LinkPhase::Connecting => {
                        out.push(Action::TakeOff);
                        self.set_phase(LinkPhase::TakingOff, out);
                        self.takeoff_by = Some(now + self.config.takeoff_bound());
                    }
                    Ok(()) => {}
                }
            }
            Event::Time => self.time(now, out),
        }
        if !self.urgent_open && self.settled() && !out.iter().any(|a| matches!(a, Action::End(_))) {
            out.push(Action::End(End::Done));
        }
    }

    /// Landed or stopped, or a request given up on: nothing more will happen.
    fn settled(&self) -> bool {
        matches!(self.phase, LinkPhase::Landed | LinkPhase::Stopped)
            || self.pending.is_some_and(|p| p.given_up)
    }

    fn set_phase(&mut self, phase: LinkPhase, out: &mut Vec<Action>) {
        self.phase = phase;
        out.push(Action::SetPhase(phase));
    }

    /// The first sample: on the ground or in the air decides what the session does.
    fn begin(&mut self, now: Instant, z: f64, out: &mut Vec<Action>) {
        out.push(Action::SetError(None));
        let on_ground = z < ON_GROUND_M;
        match (self.intent, on_ground) {
            (Intent::Fly, true) if self.urgent_open => {
                self.preparing = true;
                out.push(Action::Prepare);
            }
            (Intent::Fly, false) => self.set_phase(LinkPhase::Flying, out),
            // Stopped before (or during) a loss: stop again; a Crazyflie still locked confirms at once.
            (Intent::Stop, _) => self.start(now, Urgent::Stop, out),
            // Landed, landing, or on the ground with the link dropped: landed once it says so.
            (Intent::Land | Intent::Fly, _) => {
                self.intent = Intent::Land;
                self.start(now, Urgent::Land, out);
            }
        }
    }

    /// Sends `request` and waits for the Crazyflie to confirm it (the phase says so meanwhile).
    fn start(&mut self, now: Instant, request: Urgent, out: &mut Vec<Action>) {
        // The phase first: whatever happens to the packets, the operator never sees less than this.
        self.set_phase(phases(request).0, out);
        out.push(Action::Send(request));
        self.takeoff_by = None;
        self.pending = Some(Pending {
            request,
            since: now,
            resend_at: now + self.config.resend_period(),
            deadline: now + self.config.confirm_bound(request),
            given_up: false,
        });
        self.check_confirmed(now, out);
    }

    fn urgent(&mut self, now: Instant, request: Urgent, out: &mut Vec<Action>) {
        let restart = match request {
            // A stop outranks everything, and is never replaced by a landing.
            Urgent::Stop => {
                self.intent = Intent::Stop;
                match self.pending {
                    // Already on its way: one more copy now, the bound runs from the first.
                    Some(p) if p.request == Urgent::Stop && !p.given_up => {
                        out.push(Action::Send(Urgent::Stop));
                        false
                    }
                    _ => self.phase != LinkPhase::Stopped,
                }
            }
            Urgent::Land if self.intent == Intent::Stop => false,
            Urgent::Land => {
                self.intent = Intent::Land;
                // Preparing, taking off or flying; or asked again after a landing was given up on.
                matches!(self.phase, LinkPhase::TakingOff | LinkPhase::Flying)
                    || (self.preparing && self.phase == LinkPhase::Connecting)
                    || self.pending.is_some_and(|p| p.request == Urgent::Land && p.given_up)
            }
        };
        if restart {
            self.start(now, request, out);
        }
    }

    /// Shows the pending request done once the Crazyflie's log confirms it.
    fn check_confirmed(&mut self, now: Instant, out: &mut Vec<Action>) {
        let Some(p) = self.pending else { return };
        let confirmed = match p.request {
            Urgent::Stop => self.status.confirms_stop(),
            Urgent::Land => self.sample.is_some_and(|(z, _)| self.status.confirms_landed(z)),
        };
        if !confirmed {
            return;
        }
        self.set_phase(phases(p.request).1, out);
        if p.given_up {
            let late = now.saturating_duration_since(p.since).as_secs_f64();
            out.push(Action::SetError(Some(format!(
                "{} confirmed late, {late:.1} s after the request",
                p.request.describe()
            ))));
        }
        self.pending = None;
    }

    /// Shows flying once the firmware confirms the take-off.
    fn check_airborne(&mut self, out: &mut Vec<Action>) {
        if self.phase != LinkPhase::TakingOff || self.intent != Intent::Fly {
            return;
        }
        if self.sample.is_some_and(|(z, _)| self.status.confirms_airborne(z, self.config.altitude)) {
            self.set_phase(LinkPhase::Flying, out);
            self.takeoff_by = None;
        }
    }

    fn time(&mut self, now: Instant, out: &mut Vec<Action>) {
        let relog = self.config.relog();
        match self.sample {
            Some((_, at)) if now.saturating_duration_since(at) > relog => {
                out.push(Action::End(End::Lost(format!("no state for {} ms", relog.as_millis()))));
                return;
            }
            None if now >= self.first_sample_by => {
                out.push(Action::End(End::Lost("no state from the log block".into())));
                return;
            }
            _ => {}
        }
        if let Some(p) = self.pending.as_mut().filter(|p| !p.given_up) {
            if now >= p.deadline {
                // Reported, never shown confirmed: the phase stays stopping/landing.
                p.given_up = true;
                let bound = self.config.confirm_bound(p.request).as_secs_f64();
                out.push(Action::SetError(Some(format!(
                    "{} not confirmed after {bound} s",
                    p.request.describe()
                ))));
                out.push(Action::RecordUnconfirmed);
            } else if now >= p.resend_at {
                p.resend_at = now + self.config.resend_period();
                out.push(Action::Send(p.request));
            }
        }
        if self.takeoff_by.is_some_and(|by| now >= by) {
            self.takeoff_by = None;
            if self.phase == LinkPhase::TakingOff && self.intent == Intent::Fly {
                // The firmware never said it was up: bring it down rather than fly it.
                let z = self.sample.map_or(f64::NAN, |(z, _)| z);
                let shown = |v: Option<String>| v.unwrap_or_else(|| "not logged".into());
                out.push(Action::SetError(Some(format!(
                    "take-off not confirmed after {} s (height {z:.2} m, supervisor.info {}, thrust {})",
                    self.config.takeoff_bound().as_secs_f64(),
                    shown(self.status.info.map(|i| format!("{i:#06x}"))),
                    shown(self.status.thrust.map(|t| format!("{t:.0}"))),
                ))));
                out.push(Action::RecordUnconfirmed);
                self.intent = Intent::Land;
                self.start(now, Urgent::Land, out);
            }
        }
    }
}

#[cfg(test)]
#[path = "machine_tests.rs"]
mod tests;
