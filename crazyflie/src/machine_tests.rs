//! Every transition of the session machine, without a Crazyflie: connect (on the ground, in the
//! air, after a stop or a landing), prepare, arm-and-take-off confirmed or not, fly, land, stop,
//! resend and give up, confirm late, link loss, the link dropped.

use super::*;
use crate::confirm::Status;
use cfsim::firmware::supervisor as bits;

const FLYING: u16 = bits::IS_ARMED | bits::AUTO_ARM | bits::CAN_FLY | bits::IS_FLYING;
const ON_GROUND: u16 = bits::IS_ARMED | bits::AUTO_ARM | bits::CAN_FLY;
const LOCKED: u16 = bits::AUTO_ARM | bits::IS_LOCKED;

fn config() -> RelayConfig {
    RelayConfig::default()
}

fn status(info: u16, thrust: f64) -> Event {
    Event::Status(Status { info: Some(info), thrust: Some(thrust), vbat: Some(4.0) })
}

fn setpoint(t0: Instant) -> Setpoint {
    Setpoint { p: [1.0, 0.0, 1.0], v: [0.5, 0.0, 0.0], a: [0.0; 3], issued: t0 }
}

/// A machine and a clock: `at(s)` is `s` seconds after its start.
struct Run {
    machine: Machine,
    t0: Instant,
}

impl Run {
    fn new(intent: Intent, phase: LinkPhase, urgent_open: bool) -> Self {
        let t0 = Instant::now();
        Self { machine: Machine::new(config(), intent, phase, urgent_open, t0), t0 }
    }

    fn at(&self, seconds: f64) -> Instant {
        self.t0 + Duration::from_secs_f64(seconds)
    }

    /// Handles `event` at `seconds`; the actions it produced.
    fn send(&mut self, seconds: f64, event: Event) -> Vec<Action> {
        let mut out = Vec::new();
        self.machine.handle(self.at(seconds), event, &mut out);
        out
    }

    /// On the ground, asked to fly: prepared, taking off at 0.1 s, confirmed flying at 2 s.
    fn flying() -> Self {
        let mut run = Self::new(Intent::Fly, LinkPhase::Connecting, true);
        run.send(0.0, Event::Sample { z: 0.0 });
        run.send(0.1, Event::Prepared(Ok(())));
        run.send(2.0, status(FLYING, 36000.0));
        let out = run.send(2.0, Event::Sample { z: 1.0 });
        assert_eq!(out, [Action::SetPhase(LinkPhase::Flying)]);
        run
    }
}

#[test]
fn on_the_ground_it_prepares_then_takes_off_and_flies_once_the_firmware_says_so() {
    let mut run = Run::new(Intent::Fly, LinkPhase::Connecting, true);
    assert_eq!(run.send(0.0, Event::Sample { z: 0.01 }), [Action::SetError(None), Action::Prepare]);
    // Nothing is flown while preparing.
    assert!(run.send(0.05, Event::Setpoint(setpoint(run.t0))).is_empty());
    assert_eq!(
        run.send(0.1, Event::Prepared(Ok(()))),
        [Action::TakeOff, Action::SetPhase(LinkPhase::TakingOff)]
    );
    // Half-way up: not yet; no setpoint while taking off.
    assert!(run.send(1.0, status(FLYING, 36000.0)).is_empty());
    assert!(run.send(1.0, Event::Sample { z: 0.5 }).is_empty());
    assert!(run.send(1.0, Event::Setpoint(setpoint(run.t0))).is_empty());
    assert_eq!(run.send(2.1, Event::Sample { z: 0.95 }), [Action::SetPhase(LinkPhase::Flying)]);
    let sp = setpoint(run.t0);
    assert_eq!(run.send(2.15, Event::Setpoint(sp)), [Action::SendSetpoint(sp)]);
}

#[test]
fn in_the_air_it_flies_on_without_a_take_off() {
    let mut run = Run::new(Intent::Fly, LinkPhase::Connecting, true);
    assert_eq!(
        run.send(0.0, Event::Sample { z: 0.98 }),
        [Action::SetError(None), Action::SetPhase(LinkPhase::Flying)]
    );
}

#[test]
fn a_failed_preparation_ends_the_session_with_its_reason() {
    let mut run = Run::new(Intent::Fly, LinkPhase::Connecting, true);
    run.send(0.0, Event::Sample { z: 0.0 });
    let reason = "the Crazyflie is locked: reboot it".to_string();
    assert_eq!(run.send(0.2, Event::Prepared(Err(reason.clone()))), [Action::End(End::Lost(reason))]);
}

#[test]
fn a_take_off_the_firmware_never_confirms_is_reported_and_landed() {
    let mut run = Run::new(Intent::Fly, LinkPhase::Connecting, true);
    run.send(0.0, Event::Sample { z: 0.0 });
    run.send(0.1, Event::Prepared(Ok(())));
    run.send(0.2, status(ON_GROUND, 0.0));
    let bound = 0.1 + config().takeoff_bound().as_secs_f64();
    assert_eq!(run.machine.next_deadline(), run.at(1.0).min(run.at(bound)), "the state's relog bound first");
    // The state keeps coming (on the ground): only the take-off's bound is due.
    for k in 0..((bound - 0.2) / 0.1) as usize {
        assert!(run.send(0.3 + 0.1 * k as f64, Event::Sample { z: 0.0 }).is_empty());
    }
    run.send(bound - 0.01, Event::Sample { z: 0.0 });
    let out = run.send(bound, Event::Time);
    let Action::SetError(Some(error)) = &out[0] else { panic!("{out:?}") };
    assert!(error.starts_with("take-off not confirmed after 5 s") && error.contains("0x000e"), "{error}");
    assert_eq!(
        &out[1..],
        [
            Action::RecordUnconfirmed,
            Action::SetPhase(LinkPhase::Landing),
            Action::Send(Urgent::Land),
            Action::SetPhase(LinkPhase::Landed)
        ],
        "on the ground with the motors off, the landing is confirmed at once"
    );
    assert_eq!(run.machine.intent(), Intent::Land);
}

#[test]
fn setpoints_go_out_only_while_flying_on_a_fresh_state() {
    let mut run = Run::flying();
    let sp = setpoint(run.t0);
    assert_eq!(run.send(2.1, Event::Setpoint(sp)), [Action::SendSetpoint(sp)]);
    // 0.3 s after the last sample the state is stale: no setpoint on it, but the session stays.
    assert!(run.send(2.31, Event::Setpoint(sp)).is_empty());
    assert!(run.send(2.31, Event::Time).is_empty(), "a gap in the state stream keeps the session");
    // The state comes back: the setpoints go out again, without a new session.
    assert!(run.send(2.8, Event::Sample { z: 1.0 }).is_empty());
    assert_eq!(run.send(2.85, Event::Setpoint(sp)), [Action::SendSetpoint(sp)]);
}

#[test]
fn no_state_for_relog_after_ends_the_session() {
    let mut run = Run::flying();
    assert_eq!(run.machine.next_deadline(), run.at(3.0), "1 s after the last sample");
    assert!(run.send(2.99, Event::Time).is_empty());
    assert_eq!(run.send(3.01, Event::Time), [Action::End(End::Lost("no state for 1000 ms".into()))]);
    // Never shorter than stale_after.
    let config = RelayConfig { stale_after: 0.5, relog_after: 0.1, ..RelayConfig::default() };
    assert_eq!(config.relog(), Duration::from_millis(500));
}

#[test]
fn a_landing_is_resent_until_the_firmware_confirms_it() {
    let mut run = Run::flying();
    run.send(3.0, Event::Sample { z: 1.0 });
    assert_eq!(
        run.send(3.0, Event::Urgent(Urgent::Land)),
        [Action::SetPhase(LinkPhase::Landing), Action::Send(Urgent::Land)]
    );
    assert_eq!(run.machine.next_deadline(), run.at(3.0) + config().resend_period());
    run.send(3.1, Event::Sample { z: 0.8 });
    assert_eq!(run.send(3.15, Event::Time), [Action::Send(Urgent::Land)]);
    // Down, but the motors still run: not landed.
    run.send(5.0, status(FLYING, 12000.0));
    assert!(run.send(5.0, Event::Sample { z: 0.02 }).is_empty());
    assert_eq!(run.send(5.1, status(FLYING, 0.0)), [Action::SetPhase(LinkPhase::Landed)]);
    assert!(run.send(5.2, Event::Time).is_empty(), "nothing more is sent");
}

#[test]
fn a_landing_given_up_stays_shown_landing_and_a_late_confirmation_says_so() {
    let mut run = Run::flying();
    run.send(3.0, Event::Urgent(Urgent::Land));
    let bound = 3.0 + config().confirm_bound(Urgent::Land).as_secs_f64();
    // Still in the air 0.1 s before the bound (resent meanwhile).
    for k in 1..50 {
        let t = 3.0 + 0.1 * f64::from(k);
        run.send(t, Event::Sample { z: 0.5 });
        run.send(t, Event::Time);
    }
    run.send(bound, Event::Sample { z: 0.5 });
    let out = run.send(bound, Event::Time);
    assert_eq!(
        out,
        [Action::SetError(Some("landing not confirmed after 5 s".into())), Action::RecordUnconfirmed]
    );
    run.send(bound + 0.1, Event::Sample { z: 0.0 });
    let out = run.send(bound + 0.1, status(ON_GROUND, 0.0));
    assert_eq!(out[0], Action::SetPhase(LinkPhase::Landed));
    let Action::SetError(Some(late)) = &out[1] else { panic!("{out:?}") };
    assert!(late.starts_with("landing confirmed late, 5.1 s"), "{late}");
}

#[test]
fn a_stop_outranks_a_landing_and_is_never_replaced_by_one() {
    let mut run = Run::flying();
    run.send(3.0, Event::Urgent(Urgent::Land));
    assert_eq!(
        run.send(3.05, Event::Urgent(Urgent::Stop)),
        [Action::SetPhase(LinkPhase::Stopping), Action::Send(Urgent::Stop)]
    );
    assert!(run.send(3.06, Event::Urgent(Urgent::Land)).is_empty(), "a landing after a stop is ignored");
    assert_eq!(run.send(3.07, Event::Urgent(Urgent::Stop)), [Action::Send(Urgent::Stop)], "one more copy");
    assert_eq!(run.machine.intent(), Intent::Stop);
    // Locked with the motors off: stopped.
    assert_eq!(run.send(3.1, status(LOCKED, 0.0)), [Action::SetPhase(LinkPhase::Stopped)]);
}

#[test]
fn a_stop_while_preparing_is_sent_and_the_take_off_never_follows() {
    let mut run = Run::new(Intent::Fly, LinkPhase::Connecting, true);
    run.send(0.0, Event::Sample { z: 0.0 });
    assert_eq!(
        run.send(0.05, Event::Urgent(Urgent::Stop)),
        [Action::SetPhase(LinkPhase::Stopping), Action::Send(Urgent::Stop)]
    );
    assert!(run.send(0.1, Event::Prepared(Ok(()))).is_empty(), "no take-off after a stop");
}

#[test]
fn reconnected_after_a_stop_it_stops_again_and_a_locked_one_confirms_at_once() {
    let mut run = Run::new(Intent::Stop, LinkPhase::Stopping, true);
    run.send(0.0, status(LOCKED, 0.0));
    assert_eq!(
        run.send(0.0, Event::Sample { z: 0.0 }),
        [
            Action::SetError(None),
            Action::SetPhase(LinkPhase::Stopping),
            Action::Send(Urgent::Stop),
            Action::SetPhase(LinkPhase::Stopped)
        ]
    );
}

#[test]
fn no_first_state_within_a_second_ends_the_session() {
    let mut run = Run::new(Intent::Fly, LinkPhase::Connecting, true);
    assert_eq!(run.machine.next_deadline(), run.at(1.0));
    assert!(run.send(0.5, Event::Time).is_empty());
    assert_eq!(run.send(1.0, Event::Time), [Action::End(End::Lost("no state from the log block".into()))]);
}

#[test]
fn a_dropped_link_lands_and_ends_the_session_once_down() {
    let mut run = Run::flying();
    assert_eq!(
        run.send(3.0, Event::LinkDropped),
        [Action::SetPhase(LinkPhase::Landing), Action::Send(Urgent::Land)]
    );
    assert!(!run.machine.urgent_open());
    run.send(5.0, Event::Sample { z: 0.0 });
    assert_eq!(
        run.send(5.0, status(ON_GROUND, 0.0)),
        [Action::SetPhase(LinkPhase::Landed), Action::End(End::Done)]
    );
}

#[test]
fn a_link_dropped_before_the_first_state_lands_rather_than_takes_off() {
    let mut run = Run::new(Intent::Fly, LinkPhase::Connecting, false);
    run.send(0.0, status(ON_GROUND, 0.0));
    let out = run.send(0.0, Event::Sample { z: 0.0 });
    assert_eq!(
        out,
        [
            Action::SetError(None),
            Action::SetPhase(LinkPhase::Landing),
            Action::Send(Urgent::Land),
            Action::SetPhase(LinkPhase::Landed),
            Action::End(End::Done)
        ]
    );
}

#[test]
fn the_setpoint_channel_closing_stops_listening_to_it() {
    let mut run = Run::flying();
    assert!(run.machine.setpoints_open());
    assert!(run.send(3.0, Event::SetpointsClosed).is_empty());
    assert!(!run.machine.setpoints_open());
}
