//! The supervisor (port 9 and the platform port's arming command), after the firmware's
//! `supervisor.c`, `supervisor_state_machine.c`, `crtp_supervisor.c` and `platformservice.c`.
//!
//! The state machine runs once per supervisor cycle ([`PERIOD`], the firmware's 25 Hz) on two
//! conditions of the simulated vehicle: flying (thrust over idle within the last 2 s) and
//! emergency stop, and the commander watchdog's timeout, which in flight locks the Crazyflie as on
//! the firmware (its setpoints stopped for 2 s without a notify-stop: "free falling!", then
//! "Locked, reboot required"). Tumbling and crashes are not simulated. Arming is a request, as
//! in the firmware: it is granted from "pre-flight checks passed" only, and a firmware that
//! auto-arms (the Crazyflie 2.1 default) requests it itself on entering that state.
//!
//! Answers carry the command byte with the response flag ([`RESPONSE`], `0x80 | cmd`):
//! `[0x8C, bitfield(u16)]` to the state-bitfield request, `[0x80 | cmd, bit]` to a single-bit
//! request (`0x01..=0x0B`), `[0x81, success, armed]` to an arming request and
//! `[0x82, success, recovered]` to a crash-recovery request.

use crate::crtp::{self, PORT_PLATFORM, PORT_SUPERVISOR, Packet};

/// Bit 0: can be armed (state "pre-flight checks passed").
pub const CAN_BE_ARMED: u16 = 1 << 0;
/// Bit 1: armed.
pub const IS_ARMED: u16 = 1 << 1;
/// Bit 2: arms itself (built without `CONFIG_MOTORS_REQUIRE_ARMING`, the default).
pub const AUTO_ARM: u16 = 1 << 2;
/// Bit 3: the motors are allowed to run.
pub const CAN_FLY: u16 = 1 << 3;
/// Bit 4: flying (state "flying" or "warning, level out").
pub const IS_FLYING: u16 = 1 << 4;
/// Bit 5: tumbled.
pub const IS_TUMBLED: u16 = 1 << 5;
/// Bit 6: locked by an emergency stop until a reboot.
pub const IS_LOCKED: u16 = 1 << 6;
/// Bit 7: crashed.
pub const IS_CRASHED: u16 = 1 << 7;
/// Bit 8: the high-level commander is flying or landing.
pub const HL_ACTIVE: u16 = 1 << 8;
/// Bit 9: the high-level trajectory has finished.
pub const HL_FINISHED: u16 = 1 << 9;
/// Bit 10: the high-level commander is disabled (low-level setpoints took over).
pub const HL_DISABLED: u16 = 1 << 10;

/// Flag set in the command byte of every supervisor answer (`CMD_RESPONSE`).
pub const RESPONSE: u8 = 0x80;
/// Info channel (0): ask for the whole state bitfield.
pub const CMD_GET_STATE_BITFIELD: u8 = 0x0c;
/// Command channel (1): arm (`[0x01, 1]`) or disarm (`[0x01, 0]`).
pub const CMD_ARM_SYSTEM: u8 = 0x01;
/// Command channel (1): recover from a crash.
pub const CMD_RECOVER_SYSTEM: u8 = 0x02;
/// Platform port, command channel (0): the legacy arming request (`[0x01, arm]`).
pub const PLATFORM_REQUEST_ARMING: u8 = 0x01;
/// Platform port, command channel (0): the legacy crash-recovery request.
pub const PLATFORM_REQUEST_CRASH_RECOVERY: u8 = 0x02;
/// Platform port, command channel (0): a user notification (answered with an empty payload).
pub const PLATFORM_USER_NOTIFICATION: u8 = 0x03;

/// Supervisor cycle (s): the firmware runs the supervisor at 25 Hz.
pub const PERIOD: f64 = 0.04;
/// How long the supervisor may stay ready to fly without taking off before it disarms (s; the
/// firmware's `PREFLIGHT_TIMEOUT_MS`, param `supervisor.prefltTimeout`).
pub const PREFLIGHT_TIMEOUT: f64 = 30.0;
/// How long after a landing the supervisor stays armed before it resets (s; the firmware's
/// `LANDING_TIMEOUT_MS`, param `supervisor.landedTimeout`).
pub const LANDING_TIMEOUT: f64 = 3.0;

/// The supervisor states the simulator reaches (the firmware's `supervisorState_t` less the
/// tumbled, crashed and level-out states, which need conditions it does not simulate).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SupervisorState {
    /// Pre-flight checks not passed (the state after a reset).
    PreFlightChecksNotPassed,
    /// Pre-flight checks passed: can be armed.
    PreFlightChecksPassed,
    /// Armed, on the ground: the motors may run.
    ReadyToFly,
    /// Flying.
    Flying,
    /// Landed, still armed until the landing timeout.
    Landed,
    /// Passing through after the landing timeout: disarmed.
    Reset,
    /// An emergency stop or a disarm in flight: motors off, locked in the next cycle.
    ExceptFreeFall,
    /// Locked until a reboot.
    Locked,
}

/// What the supervisor observes of the vehicle in one cycle.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Conditions {
    /// The thrust was over idle within the last 2 s.
    pub is_flying: bool,
    /// An emergency stop was requested (supervisor or localization port, or its watchdog).
    pub emergency_stop: bool,
    /// The commander watchdog's shutdown: no setpoint for 2 s while low-level setpoints had
    /// priority (`SUPERVISOR_CB_COMMANDER_WDT_TIMEOUT`).
    pub commander_timeout: bool,
}

/// The supervisor's state, armed flag and timers.
#[derive(Debug, Clone)]
pub struct Supervisor {
    state: SupervisorState,
    armed: bool,
    auto_arm: bool,
    latest_arming: f64,
    latest_landing: Option<f64>,
}

impl Supervisor {
    /// Booted and settled at time 0: ready to fly (armed) if it auto-arms, else waiting in
    /// "pre-flight checks passed" for an arming request.
    pub fn new(auto_arm: bool) -> Self {
        let state =
            if auto_arm { SupervisorState::ReadyToFly } else { SupervisorState::PreFlightChecksPassed };
        Self { state, armed: auto_arm, auto_arm, latest_arming: 0.0, latest_landing: None }
    }

    /// The current state.
    pub fn state(&self) -> SupervisorState {
        self.state
    }

    /// Whether the system is armed.
    pub fn is_armed(&self) -> bool {
        self.armed
    }

    /// Whether the motors may run (`supervisorAreMotorsAllowedToRun`: ready to fly, flying,
    /// landed).
    pub fn motors_allowed(&self) -> bool {
        use SupervisorState::*;
        matches!(self.state, ReadyToFly | Flying | Landed)
    }

    /// Whether the supervisor stopped the motors for good (emergency stop or disarmed in flight).
    pub fn is_stopped(&self) -> bool {
        matches!(self.state, SupervisorState::ExceptFreeFall | SupervisorState::Locked)
    }

    /// Arm or disarm (`supervisorRequestArming`); returns whether the request was granted.
    /// Arming is granted in "pre-flight checks passed" only; asking for the current state always
    /// succeeds.
    pub fn request_arming(&mut self, arm: bool) -> bool {
        if arm == self.armed {
            return true;
        }
        if arm && self.state != SupervisorState::PreFlightChecksPassed {
            return false;
        }
        self.armed = arm;
        true
    }

    /// An emergency stop, seen at once: locked and disarmed (the firmware passes through
    /// "exception, free fall" in the next cycle; the simulator cuts the motors in the same step).
    pub fn lock(&mut self) {
        self.state = SupervisorState::Locked;
        self.armed = false;
    }

    /// One supervisor cycle at time `t` (s): the first transition whose conditions hold, then the
    /// firmware's post-transition actions (disarm outside the flight states, auto-arm).
    pub fn update(&mut self, t: f64, c: Conditions) {
        use SupervisorState::*;
        let next = match self.state {
            _ if c.emergency_stop && !self.is_stopped() => ExceptFreeFall,
            PreFlightChecksNotPassed => PreFlightChecksPassed,
            PreFlightChecksPassed if self.armed => ReadyToFly,
            // Disarmed, or armed too long on the ground: "pre-flight checks passed" again.
            ReadyToFly if !self.armed || t - self.latest_arming > PREFLIGHT_TIMEOUT => PreFlightChecksPassed,
            ReadyToFly if c.is_flying => Flying,
            Flying if !self.armed || c.commander_timeout => ExceptFreeFall,
            Flying if !c.is_flying => Landed,
            Landed if self.latest_landing.is_some_and(|l| t - l > LANDING_TIMEOUT) => Reset,
            Landed if c.is_flying => Flying,
            Reset => PreFlightChecksNotPassed,
            ExceptFreeFall => Locked,
            s => s,
        };
        if next == self.state {
            return;
        }
        self.state = next;
        match next {
            ReadyToFly => self.latest_arming = t,
            Landed => self.latest_landing = Some(t),
            _ => {}
        }
        if !matches!(next, ReadyToFly | Flying | Landed) {
            self.armed = false;
        }
        if self.auto_arm && next == PreFlightChecksPassed {
            self.armed = true;
        }
    }

    /// The state bitfield (`supervisor.info`) with the high-level commander's bits `hl` (of
    /// [`HL_ACTIVE`], [`HL_FINISHED`], [`HL_DISABLED`]), as `updateLogData` sets it.
    pub fn bits(&self, hl: u16) -> u16 {
        let bits = [
            (CAN_BE_ARMED, self.state == SupervisorState::PreFlightChecksPassed),
            (IS_ARMED, self.armed),
            (AUTO_ARM, self.auto_arm),
            (CAN_FLY, self.motors_allowed()),
            (IS_FLYING, self.state == SupervisorState::Flying),
            (IS_LOCKED, self.state == SupervisorState::Locked),
        ];
        let hl = hl & (HL_ACTIVE | HL_FINISHED | HL_DISABLED);
        bits.iter().filter(|(_, on)| *on).fold(hl, |acc, (bit, _)| acc | bit)
    }

    /// Answer a supervisor-port packet (port 9) given the current bitfield. The emergency stops
    /// (command channel, `0x03`/`0x04`) are flight commands and never reach here.
    pub fn handle(&mut self, pk: &Packet, bits: u16) -> Option<Packet> {
        let cmd = crtp::u8_at(&pk.data, 0)?;
        let mut out = vec![RESPONSE | cmd];
        match (pk.channel, cmd) {
            (0, CMD_GET_STATE_BITFIELD) => out.extend_from_slice(&bits.to_le_bytes()),
            // CMD_CAN_BE_ARMED (1) .. CMD_HL_CONTROL_DISABLED (11): bit cmd - 1.
            (0, 1..=11) => out.push(u8::from(bits & (1 << (cmd - 1)) != 0)),
            (1, CMD_ARM_SYSTEM) => {
                // The firmware reads the argument byte even if the packet is one byte long.
                let arm = crtp::u8_at(&pk.data, 1).unwrap_or(0) != 0;
                let granted = self.request_arming(arm);
                out.extend_from_slice(&[u8::from(granted), u8::from(self.armed)]);
            }
            // Nothing crashes in the simulator: recovery succeeds and it is not crashed.
            (1, CMD_RECOVER_SYSTEM) => out.extend_from_slice(&[1, 1]),
            _ => return None,
        }
        Some(Packet::new(PORT_SUPERVISOR, pk.channel, out))
    }

    /// Answer a platform-port command (channel 0), which the firmware echoes after acting on it.
    /// The legacy arming request's answer is `[0x01, success]`: the firmware writes the armed flag
    /// after it but sends two bytes only (`p->size = 2`). A user notification is answered with an
    /// empty payload; any other command is echoed unchanged.
    pub fn platform_command(&mut self, pk: &Packet) -> Option<Packet> {
        let cmd = crtp::u8_at(&pk.data, 0)?;
        let data = match cmd {
            PLATFORM_REQUEST_ARMING => {
                let arm = crtp::u8_at(&pk.data, 1).unwrap_or(0) != 0;
                vec![cmd, u8::from(self.request_arming(arm))]
            }
            PLATFORM_REQUEST_CRASH_RECOVERY => vec![cmd, 1],
            PLATFORM_USER_NOTIFICATION => Vec::new(),
            _ => pk.data.clone(),
        };
        Some(Packet::new(PORT_PLATFORM, 0, data))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use SupervisorState::*;

    const GROUND: Conditions =
        Conditions { is_flying: false, emergency_stop: false, commander_timeout: false };
    const AIR: Conditions = Conditions { is_flying: true, emergency_stop: false, commander_timeout: false };

    fn cycles(s: &mut Supervisor, t: &mut f64, n: usize, c: Conditions) {
        for _ in 0..n {
            *t += PERIOD;
            s.update(*t, c);
        }
    }

    #[test]
    fn every_bit_means_what_crazyflie_lib_reads() {
        use crazyflie_lib::subsystems::supervisor::SupervisorInfo;
        let lib = SupervisorInfo::from_bits;
        let one = |bit: u16, read: fn(&SupervisorInfo) -> bool| {
            assert!(read(&lib(bit)) && !read(&lib(!bit & 0x07ff)), "bit {bit:#06x}");
        };
        one(CAN_BE_ARMED, |i| i.can_be_armed());
        one(IS_ARMED, |i| i.is_armed());
        one(AUTO_ARM, |i| i.is_auto_armed());
        one(CAN_FLY, |i| i.can_fly());
        one(IS_FLYING, |i| i.is_flying());
        one(IS_TUMBLED, |i| i.is_tumbled());
        one(IS_LOCKED, |i| i.is_locked());
        one(IS_CRASHED, |i| i.is_crashed());
        one(HL_ACTIVE, |i| i.hl_control_active());
        one(HL_FINISHED, |i| i.hl_traj_finished());
        one(HL_DISABLED, |i| i.hl_control_disabled());
    }

    #[test]
    fn arming_required_flight_cycle() {
        let (mut s, mut t) = (Supervisor::new(false), 0.0);
        assert_eq!((s.state(), s.bits(0)), (PreFlightChecksPassed, CAN_BE_ARMED));
        assert!(!s.motors_allowed());
        cycles(&mut s, &mut t, 10, GROUND);
        assert_eq!(s.state(), PreFlightChecksPassed, "waits for an arming request");
        assert!(s.request_arming(true));
        cycles(&mut s, &mut t, 1, GROUND);
        assert_eq!((s.state(), s.bits(0)), (ReadyToFly, IS_ARMED | CAN_FLY));
        assert!(s.request_arming(true), "arming when armed succeeds");
        cycles(&mut s, &mut t, 1, AIR);
        assert_eq!((s.state(), s.bits(0)), (Flying, IS_ARMED | CAN_FLY | IS_FLYING));
        cycles(&mut s, &mut t, 1, GROUND);
        assert_eq!((s.state(), s.bits(0)), (Landed, IS_ARMED | CAN_FLY));
        // Taking off again within the landing timeout needs no new arming.
        cycles(&mut s, &mut t, 1, AIR);
        assert_eq!(s.state(), Flying);
        cycles(&mut s, &mut t, 1, GROUND);
        let landed = t;
        while s.state() == Landed {
            cycles(&mut s, &mut t, 1, GROUND);
        }
        assert!(t - landed > LANDING_TIMEOUT && t - landed < LANDING_TIMEOUT + 2.0 * PERIOD);
        assert_eq!((s.state(), s.is_armed()), (Reset, false), "disarmed after the landing timeout");
        cycles(&mut s, &mut t, 2, GROUND);
        assert_eq!((s.state(), s.bits(0)), (PreFlightChecksPassed, CAN_BE_ARMED));
    }

    #[test]
    fn disarm_on_the_ground_and_in_flight() {
        let (mut s, mut t) = (Supervisor::new(false), 0.0);
        assert!(s.request_arming(false) && !s.is_armed(), "disarming when disarmed succeeds");
        s.request_arming(true);
        cycles(&mut s, &mut t, 1, GROUND);
        assert!(s.request_arming(false));
        assert_eq!(s.bits(0) & IS_ARMED, 0, "disarmed at once");
        cycles(&mut s, &mut t, 1, GROUND);
        assert_eq!(s.state(), PreFlightChecksPassed);
        // Arming is refused outside "pre-flight checks passed".
        s.request_arming(true);
        cycles(&mut s, &mut t, 2, AIR);
        assert_eq!(s.state(), Flying);
        assert!(s.request_arming(false));
        assert!(!s.request_arming(true), "re-arming in flight is refused");
        cycles(&mut s, &mut t, 1, AIR);
        assert!(s.is_stopped() && !s.motors_allowed(), "disarmed in flight: motors cut");
        cycles(&mut s, &mut t, 1, GROUND);
        assert_eq!((s.state(), s.bits(0)), (Locked, IS_LOCKED));
        cycles(&mut s, &mut t, 100, GROUND);
        assert_eq!(s.state(), Locked, "until a reboot");
        assert!(!s.request_arming(true));
    }

    #[test]
    fn auto_arm_rearms_and_preflight_timeout() {
        let (mut s, mut t) = (Supervisor::new(true), 0.0);
        assert_eq!((s.state(), s.bits(0)), (ReadyToFly, IS_ARMED | AUTO_ARM | CAN_FLY));
        assert!(s.request_arming(false));
        cycles(&mut s, &mut t, 1, GROUND);
        assert_eq!(s.bits(0), CAN_BE_ARMED | IS_ARMED | AUTO_ARM, "re-armed on passing the checks");
        cycles(&mut s, &mut t, 1, GROUND);
        assert_eq!(s.state(), ReadyToFly);
        let armed = t;
        while s.state() == ReadyToFly {
            cycles(&mut s, &mut t, 1, GROUND);
        }
        assert!((t - armed - PREFLIGHT_TIMEOUT).abs() <= PERIOD + 1e-9, "{}", t - armed);
        cycles(&mut s, &mut t, 1, GROUND);
        assert_eq!(s.state(), ReadyToFly);
        s.lock();
        assert_eq!(s.bits(HL_DISABLED), AUTO_ARM | IS_LOCKED | HL_DISABLED);
        let (mut s, mut t) = (Supervisor::new(true), 0.0);
        cycles(&mut s, &mut t, 1, Conditions { emergency_stop: true, ..GROUND });
        assert_eq!((s.state(), s.motors_allowed()), (ExceptFreeFall, false));
        cycles(&mut s, &mut t, 1, GROUND);
        assert_eq!(s.state(), Locked);
    }

    #[test]
    fn answers_carry_the_response_flag() {
        let mut s = Supervisor::new(false);
        let ask = |s: &mut Supervisor, ch, d: &[u8]| s.handle(&Packet::new(9, ch, d.to_vec()), 0x0409);
        assert_eq!(ask(&mut s, 0, &[0x0c]).map(|p| p.data), Some(vec![0x8c, 0x09, 0x04]));
        assert_eq!(ask(&mut s, 0, &[0x01]).map(|p| p.data), Some(vec![0x81, 1]));
        assert_eq!(ask(&mut s, 0, &[0x02]).map(|p| p.data), Some(vec![0x82, 0]));
        assert_eq!(ask(&mut s, 0, &[0x0b]).map(|p| p.data), Some(vec![0x8b, 1]));
        assert!(ask(&mut s, 0, &[0x0d]).is_none() && ask(&mut s, 0, &[]).is_none());
        let arm = ask(&mut s, 1, &[0x01, 1]).expect("answer");
        assert_eq!((arm.port, arm.channel, arm.data), (9, 1, vec![0x81, 1, 1]));
        assert_eq!(ask(&mut s, 1, &[0x02]).map(|p| p.data), Some(vec![0x82, 1, 1]));
        assert!(ask(&mut s, 1, &[0x05]).is_none() && ask(&mut s, 2, &[0x0c]).is_none());
        let mut s = Supervisor::new(false);
        let plat = |s: &mut Supervisor, d: &[u8]| s.platform_command(&Packet::new(13, 0, d.to_vec()));
        let arm = plat(&mut s, &[1, 1]).expect("answer");
        assert_eq!((arm.port, arm.channel, arm.data), (13, 0, vec![1, 1]));
        assert!(s.is_armed());
        assert_eq!(plat(&mut s, &[3, 1]).map(|p| p.data), Some(vec![]));
        assert_eq!(plat(&mut s, &[0, 1]).map(|p| p.data), Some(vec![0, 1]));
        assert!(plat(&mut s, &[]).is_none());
    }

    /// The commander watchdog's timeout locks a flying Crazyflie ("free falling!", then "Locked,
    /// reboot required"), and means nothing on the ground.
    #[test]
    fn commander_timeout_locks_in_flight_only() {
        let (mut s, mut t) = (Supervisor::new(true), 0.0);
        cycles(&mut s, &mut t, 2, Conditions { commander_timeout: true, ..GROUND });
        assert_eq!(s.state(), ReadyToFly);
        cycles(&mut s, &mut t, 1, AIR);
        assert_eq!(s.state(), Flying);
        cycles(&mut s, &mut t, 1, Conditions { commander_timeout: true, ..AIR });
        assert_eq!((s.state(), s.motors_allowed()), (ExceptFreeFall, false));
        cycles(&mut s, &mut t, 1, GROUND);
        assert_eq!((s.state(), s.bits(0) & IS_LOCKED), (Locked, IS_LOCKED));
    }
}
