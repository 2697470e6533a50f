//! Flight control: which setpoint source drives the motors (low-level setpoints with the
//! commander watchdog, the high-level commander, emergency stop), after the firmware's
//! `commander.c`, and the dynamics step.

use crate::commands::{Command, HlCommand, Setpoint};
use crate::dynamics::{Axis, Body, G, Gains};
use crate::planner::{PlanState, Planner};

/// After this long without a low-level setpoint the firmware levels out (s).
const WDT_STABILIZE: f64 = 0.5;
/// After this long without a low-level setpoint the firmware stops the motors (s).
const WDT_SHUTDOWN: f64 = 2.0;
/// Emergency-stop watchdog timeout once armed (s).
const ESTOP_WATCHDOG: f64 = 1.0;
/// `stabilizer.controller` of the firmware's PID controller (its default), which follows only the
/// position of a full-state setpoint (its velocity and acceleration are replaced by its own
/// position loop).
pub const CONTROLLER_PID: u8 = 1;
/// Thrust fraction that hovers (about 36000 PWM on a Crazyflie 2.1).
const HOVER_THRUST: f64 = 0.55;
/// The supervisor calls the Crazyflie flying until this long after the thrust was last over idle
/// (s; the firmware's `IS_FLYING_HYSTERESIS_THRESHOLD` in `supervisor.c`).
pub const IS_FLYING_HYSTERESIS: f64 = 2.0;

/// What currently drives the simulated Crazyflie.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FlightMode {
    /// Motors off, no active setpoint.
    Idle,
    /// Tracking low-level setpoints (ports 3 and 7).
    LowLevel,
    /// Low-level setpoints stopped for more than 500 ms: levelling out, holding altitude.
    Leveling,
    /// Following the high-level commander.
    HighLevel,
    /// Emergency stopped: motors off until [`crate::SimHandle::reboot`].
    Locked,
}

#[derive(Debug, Clone, Copy)]
struct LowLevel {
    sp: Setpoint,
    stamp: f64,
    relaxed: bool,
    hold_z: Option<f64>,
    /// Given up by the client (notify setpoint stop): its expiry is no watchdog timeout.
    notified: bool,
}

/// The flight-control state of one simulated Crazyflie.
#[derive(Debug, Clone)]
pub struct Flight {
    /// Position, velocity, acceleration (the estimate equals the truth).
    pub body: Body,
    /// Controller gains and limits.
    pub gains: Gains,
    /// Whether the motors are spinning.
    pub motors_on: bool,
    /// The current source.
    pub mode: FlightMode,
    /// Last external position received, and how many were received.
    pub external: Option<[f32; 3]>,
    /// Number of external positions received.
    pub external_count: u64,
    /// Seconds flown with motors on (drains the simulated battery).
    pub motor_time: f64,
    ll: Option<LowLevel>,
    planner: Planner,
    estop_deadline: Option<f64>,
    thrust_unlocked: bool,
    /// When the motors last ran (s), for the supervisor's is-flying hysteresis.
    last_thrust: Option<f64>,
    /// Low-level setpoints hold the commander's priority (`commanderSetSetpoint`): the high-level
    /// commander's setpoints are refused until a notify-stop relaxes it (`commanderRelaxPriority`)
    /// or a reboot, however old the last low-level setpoint is. A take-off after a session that
    /// ended without a notify-stop is ignored, as on the firmware.
    low_level_priority: bool,
    /// The firmware's controller (`stabilizer.controller`), set by the firmware before each step.
    pub controller: u8,
    /// A low-level setpoint expired in flight without a notify-stop (the commander watchdog's
    /// shutdown, which the supervisor turns into a lock when flying); cleared by a reboot.
    watchdog_expired: bool,
}

impl Flight {
    /// On the ground at `p`, motors off.
    pub fn new(p: [f64; 3], gains: Gains) -> Self {
        Self {
            body: Body::at(p),
            gains,
            motors_on: false,
            mode: FlightMode::Idle,
            external: None,
            external_count: 0,
            motor_time: 0.0,
            ll: None,
            planner: Planner::new(),
            estop_deadline: None,
            thrust_unlocked: false,
            last_thrust: None,
            low_level_priority: false,
            controller: CONTROLLER_PID,
            watchdog_expired: false,
        }
    }

    /// Clear the emergency lock and all setpoints (a reboot), keeping the physical state.
    pub fn reboot(&mut self) {
        let (body, gains) = (self.body, self.gains);
        *self = Self::new(body.p, gains);
        self.body = body;
    }

    /// The high-level planner's state.
    pub fn plan_state(&self) -> PlanState {
        self.planner.state()
    }

    /// Whether the supervisor calls it flying at time `t`: not locked, and the motors ran within
    /// the last [`IS_FLYING_HYSTERESIS`] seconds (so it stays "flying" for 2 s after a landing).
    pub fn is_flying(&self, t: f64) -> bool {
        self.mode != FlightMode::Locked && self.last_thrust.is_some_and(|l| t - l < IS_FLYING_HYSTERESIS)
    }

    /// Whether a low-level setpoint outlived the commander watchdog's shutdown time (2 s) without a
    /// notify-stop: the supervisor's "commander watchdog timeout".
    pub fn watchdog_expired(&self) -> bool {
        self.watchdog_expired
    }

    /// Whether the high-level planner's current trajectory has ended.
    pub fn hl_finished(&self, t: f64) -> bool {
        matches!(self.planner.state(), PlanState::Flying | PlanState::Landing) && self.planner.finished(t)
    }

    /// The high-level commander's supervisor bits at time `t` (active, finished, disabled), as the
    /// firmware's `updateLogData` sets them.
    pub fn hl_bits(&self, t: f64, hl_enabled: bool) -> u16 {
        use crate::supervisor::{HL_ACTIVE, HL_DISABLED, HL_FINISHED};
        let plan = self.planner.state();
        let bits = [
            (HL_ACTIVE, matches!(plan, PlanState::Flying | PlanState::Landing)),
            (HL_FINISHED, self.hl_finished(t)),
            (HL_DISABLED, plan == PlanState::Disabled || !hl_enabled),
        ];
        bits.iter().filter(|(_, on)| *on).fold(0, |acc, (bit, _)| acc | bit)
    }

    /// Apply a decoded command at time `t`.
    pub fn command(&mut self, cmd: Command, t: f64, hl_enabled: bool) {
        match cmd {
            Command::EmergencyStop => self.lock(),
            Command::EmergencyStopWatchdog => self.estop_deadline = Some(t + ESTOP_WATCHDOG),
            Command::ExternalPosition(p) => {
                self.external = Some(p);
                self.external_count += 1;
            }
            _ if self.mode == FlightMode::Locked => {}
            Command::Setpoint(sp) => {
                let sp = match sp {
                    Setpoint::Attitude { legacy: true, .. } if !self.thrust_unlocked => Setpoint::Stop,
                    other => other,
                };
                if matches!(sp, Setpoint::Stop) {
                    self.thrust_unlocked = true;
                }
                // A low-level setpoint takes priority and disables the high-level planner.
                self.ll = Some(LowLevel { sp, stamp: t, relaxed: false, hold_z: None, notified: false });
                self.low_level_priority = true;
                self.planner.disable();
            }
            Command::NotifySetpointsStop { remain_ms } => {
                self.low_level_priority = false;
                if let Some(ll) = &mut self.ll {
                    let remain = f64::from(remain_ms) / 1000.0;
                    ll.stamp = t - (WDT_SHUTDOWN - remain).max(0.0);
                    ll.relaxed = true;
                    ll.notified = true;
                }
            }
            Command::Hl(hl) if hl_enabled => self.high_level(hl, t),
            Command::Hl(_) => {}
        }
    }

    fn high_level(&mut self, hl: HlCommand, t: f64) {
        let pos = self.body.p;
        match hl {
            HlCommand::SetGroupMask(m) => self.planner.set_group_mask(m),
            HlCommand::Stop { group } if self.planner.in_group(group) => self.planner.stop(),
            HlCommand::Takeoff { group, height, duration } if self.planner.in_group(group) => {
                self.planner.takeoff(pos, height, duration, t);
            }
            HlCommand::Land { group, height, duration } if self.planner.in_group(group) => {
                self.planner.land(pos, height, duration, t);
            }
            HlCommand::GoTo { group, relative, target, duration } if self.planner.in_group(group) => {
                self.planner.go_to(pos, relative, target, duration, t);
            }
            _ => {}
        }
    }

    /// Emergency stop (or the supervisor's lock): motors off, setpoints dropped, every command but
    /// the external position ignored until [`Flight::reboot`].
    pub fn lock(&mut self) {
        self.mode = FlightMode::Locked;
        self.ll = None;
        self.planner.stop();
        self.estop_deadline = None;
        self.motors_on = false;
    }

    /// Advance by `dt` seconds to time `t`. Without `motors_allowed` (the supervisor's verdict,
    /// e.g. not armed) the setpoints are followed as usual but the motors stay off.
    pub fn step(&mut self, t: f64, dt: f64, hl_enabled: bool, motors_allowed: bool) {
        if self.estop_deadline.is_some_and(|d| t > d) {
            self.lock();
        }
        let refs = self.select(t, hl_enabled).filter(|_| motors_allowed);
        match refs {
            Some(refs) => {
                self.motors_on = true;
                self.last_thrust = Some(t);
                self.motor_time += dt;
                self.body.step_controlled(refs, &self.gains, dt);
            }
            None => {
                self.motors_on = false;
                self.body.step_free(dt);
            }
        }
    }

    /// Pick the source and its references; `None` means motors off.
    fn select(&mut self, t: f64, hl_enabled: bool) -> Option<[Axis; 3]> {
        if self.mode == FlightMode::Locked {
            return None;
        }
        let age = self.ll.map(|l| t - l.stamp);
        let fresh = age.is_some_and(|a| a <= WDT_STABILIZE);
        if let Some(ll) = self.ll.filter(|l| fresh && !l.relaxed) {
            return self.low_level(ll.sp);
        }
        if hl_enabled
            && !self.low_level_priority
            && let Some((p, v, a)) = self.planner.goal(t)
        {
            // The planner's setpoints replace the (relaxed or stale) low-level one.
            self.ll = None;
            self.mode = FlightMode::HighLevel;
            return Some([0, 1, 2].map(|k| Axis::Pos { p: p[k], v: v[k], a: a[k] }));
        }
        match (self.ll, age) {
            (Some(ll), _) if fresh => self.low_level(ll.sp),
            (Some(ll), Some(a)) if a <= WDT_SHUTDOWN && !matches!(ll.sp, Setpoint::Stop) => {
                // Level out: brake horizontally, keep the altitude.
                let z = ll.hold_z.unwrap_or(match ll.sp {
                    Setpoint::Position(p) | Setpoint::FullState { p, .. } => p[2],
                    Setpoint::Hover { z, .. } | Setpoint::ZDistance { z, .. } => z,
                    _ => self.body.p[2],
                });
                self.ll = Some(LowLevel { relaxed: true, hold_z: Some(z), ..ll });
                self.mode = FlightMode::Leveling;
                Some([Axis::Vel(0.0), Axis::Vel(0.0), Axis::hold(z)])
            }
            _ => {
                if self.ll.is_some_and(|ll| !ll.notified && !matches!(ll.sp, Setpoint::Stop))
                    && self.motors_on
                {
                    self.watchdog_expired = true;
                }
                self.ll = None;
                self.mode = FlightMode::Idle;
                None
            }
        }
    }

    fn low_level(&mut self, sp: Setpoint) -> Option<[Axis; 3]> {
        self.mode = FlightMode::LowLevel;
        let tilt = |roll: f64, pitch: f64| [Axis::Acc(G * pitch.tan()), Axis::Acc(-G * roll.tan())];
        Some(match sp {
            Setpoint::Stop => {
                self.mode = FlightMode::Idle;
                return None;
            }
            Setpoint::Position(p) => p.map(Axis::hold),
            // PID tracks the position alone (a setpoint one tick ahead: the Crazyflie creeps).
            Setpoint::FullState { p, .. } if self.controller == CONTROLLER_PID => p.map(Axis::hold),
            Setpoint::FullState { p, v, a } => [0, 1, 2].map(|k| Axis::Pos { p: p[k], v: v[k], a: a[k] }),
            Setpoint::VelocityWorld(v) => v.map(Axis::Vel),
            Setpoint::Hover { vx, vy, z } => [Axis::Vel(vx), Axis::Vel(vy), Axis::hold(z)],
            Setpoint::ZDistance { roll, pitch, z } => {
                let [x, y] = tilt(roll, pitch);
                [x, y, Axis::hold(z)]
            }
            Setpoint::AltHold { roll, pitch, vz } => {
                let [x, y] = tilt(roll, pitch);
                [x, y, Axis::Vel(vz)]
            }
            Setpoint::Attitude { roll, pitch, thrust, .. } => {
                let [x, y] = tilt(roll, pitch);
                [x, y, Axis::Acc(G * (thrust / HOVER_THRUST - 1.0))]
            }
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const GAINS: Gains = Gains { kp: 2.0, kv: 8.0, max_accel: 4.0, max_speed: 5.0 };
    const DT: f64 = 0.002;

    fn run(f: &mut Flight, t: &mut f64, secs: f64) {
        let n = (secs / DT).round() as usize;
        for _ in 0..n {
            *t += DT;
            f.step(*t, DT, true, true);
        }
    }

    #[test]
    fn watchdog_levels_out_then_stops() {
        let mut f = Flight::new([0.0; 3], GAINS);
        let mut t = 0.0;
        for _ in 0..100 {
            f.command(Command::Setpoint(Setpoint::Position([0.0, 0.0, 1.0])), t, true);
            run(&mut f, &mut t, 0.02);
        }
        assert_eq!(f.mode, FlightMode::LowLevel);
        assert!((f.body.p[2] - 1.0).abs() < 0.05);
        run(&mut f, &mut t, 0.6);
        assert_eq!(f.mode, FlightMode::Leveling);
        assert!(f.motors_on && (f.body.p[2] - 1.0).abs() < 0.05);
        assert!(!f.watchdog_expired());
        run(&mut f, &mut t, 1.5);
        assert_eq!(f.mode, FlightMode::Idle);
        assert!(!f.motors_on);
        assert!(f.watchdog_expired(), "the supervisor is told (and locks)");
        run(&mut f, &mut t, 1.0);
        assert_eq!(f.body.p[2], 0.0);
        f.reboot();
        assert!(!f.watchdog_expired());
    }

    /// A session that ended on low-level setpoints without a notify-stop keeps their priority: the
    /// next session's take-off is ignored until it sends one (as on the firmware).
    #[test]
    fn a_stale_low_level_setpoint_outranks_a_take_off_until_a_notify_stop() {
        let mut f = Flight::new([0.0; 3], GAINS);
        let mut t = 0.0;
        f.command(Command::Setpoint(Setpoint::Stop), t, true);
        run(&mut f, &mut t, 5.0);
        let take_off = HlCommand::Takeoff { group: 0, height: 1.0, duration: 1.0 };
        f.command(Command::Hl(take_off), t, true);
        run(&mut f, &mut t, 2.0);
        assert!(!f.motors_on && f.body.p[2] == 0.0, "ignored: {:?}", f.body.p);
        f.command(Command::NotifySetpointsStop { remain_ms: 0 }, t, true);
        f.command(Command::Hl(take_off), t, true);
        run(&mut f, &mut t, 2.0);
        assert!(f.motors_on && (f.body.p[2] - 1.0).abs() < 0.05, "flown: {:?}", f.body.p);
    }

    /// Setpoints given up with a notify-stop expire without a watchdog timeout.
    #[test]
    fn notified_setpoints_expire_quietly() {
        let mut f = Flight::new([0.0; 3], GAINS);
        let mut t = 0.0;
        for _ in 0..50 {
            f.command(Command::Setpoint(Setpoint::Position([0.0, 0.0, 1.0])), t, true);
            run(&mut f, &mut t, 0.02);
        }
        f.command(Command::NotifySetpointsStop { remain_ms: 0 }, t, true);
        run(&mut f, &mut t, 3.0);
        assert!(!f.motors_on && !f.watchdog_expired());
    }

    /// Full-state setpoints one tick ahead of a Crazyflie moving at 1 m/s: Mellinger follows
    /// their velocity; PID, the firmware's default, only their position (it creeps).
    #[test]
    fn full_state_feed_forward_needs_mellinger() {
        let speed_after = |controller: u8| {
            let mut f = Flight::new([0.0, 0.0, 1.0], GAINS);
            f.controller = controller;
            let mut t = 0.0;
            for _ in 0..100 {
                let p = f.body.p;
                let sp = Setpoint::FullState { p: [p[0] + 0.05, p[1], 1.0], v: [1.0, 0.0, 0.0], a: [0.0; 3] };
                f.command(Command::Setpoint(sp), t, true);
                run(&mut f, &mut t, 0.05);
            }
            f.body.v[0]
        };
        assert!((speed_after(2) - 1.0).abs() < 0.05, "Mellinger: {}", speed_after(2));
        assert!(speed_after(CONTROLLER_PID) < 0.15, "PID: {}", speed_after(CONTROLLER_PID));
    }

    #[test]
    fn high_level_takeoff_land_and_handover() {
        let mut f = Flight::new([1.0, 0.0, 0.0], GAINS);
        let mut t = 0.0;
        f.command(Command::Hl(HlCommand::Takeoff { group: 0, height: 1.0, duration: 2.0 }), t, true);
        run(&mut f, &mut t, 2.5);
        assert_eq!(f.mode, FlightMode::HighLevel);
        assert!((f.body.p[2] - 1.0).abs() < 0.02, "{:?}", f.body.p);
        f.command(Command::Setpoint(Setpoint::VelocityWorld([0.5, 0.0, 0.0])), t, true);
        run(&mut f, &mut t, 0.2);
        assert_eq!(f.mode, FlightMode::LowLevel);
        f.command(Command::NotifySetpointsStop { remain_ms: 0 }, t, true);
        f.command(
            Command::Hl(HlCommand::GoTo {
                group: 0,
                relative: false,
                target: [1.0, 0.0, 1.0],
                duration: 1.0,
            }),
            t,
            true,
        );
        run(&mut f, &mut t, 1.5);
        assert_eq!(f.mode, FlightMode::HighLevel);
        f.command(Command::Hl(HlCommand::Land { group: 0, height: 0.0, duration: 1.5 }), t, true);
        run(&mut f, &mut t, 2.0);
        assert_eq!(f.mode, FlightMode::Idle);
        assert!(f.body.p[2] < 0.05);
    }

    #[test]
    fn emergency_stop_locks_until_reboot() {
        let mut f = Flight::new([0.0; 3], GAINS);
        let mut t = 0.0;
        f.command(Command::Hl(HlCommand::Takeoff { group: 0, height: 1.0, duration: 1.0 }), t, true);
        run(&mut f, &mut t, 1.2);
        f.command(Command::EmergencyStop, t, true);
        f.command(Command::Setpoint(Setpoint::Position([0.0, 0.0, 1.0])), t, true);
        run(&mut f, &mut t, 1.0);
        assert_eq!((f.mode, f.motors_on, f.body.p[2]), (FlightMode::Locked, false, 0.0));
        f.reboot();
        f.command(Command::Setpoint(Setpoint::Position([0.0, 0.0, 1.0])), t, true);
        run(&mut f, &mut t, 0.1);
        assert!(f.motors_on);
        f.command(Command::EmergencyStopWatchdog, t, true);
        run(&mut f, &mut t, 0.5);
        f.command(Command::Setpoint(Setpoint::Position([0.0, 0.0, 1.0])), t, true);
        run(&mut f, &mut t, 0.6);
        assert_eq!(f.mode, FlightMode::Locked);
    }

    #[test]
    fn legacy_thrust_needs_unlocking() {
        let mut f = Flight::new([0.0; 3], GAINS);
        let att = Setpoint::Attitude { roll: 0.0, pitch: 0.0, thrust: 0.8, legacy: true };
        f.command(Command::Setpoint(att), 0.0, true);
        f.step(0.002, DT, true, true);
        assert!(!f.motors_on);
        f.command(Command::Setpoint(Setpoint::Stop), 0.002, true);
        f.command(Command::Setpoint(att), 0.004, true);
        f.step(0.006, DT, true, true);
        assert!(f.motors_on);
    }
}
