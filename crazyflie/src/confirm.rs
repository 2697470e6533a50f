//! What confirms an emergency stop or a landing: the Crazyflie's own log, never the relay's timer.
//!
//! The relay logs [`STATUS_VARIABLES`] next to the state estimate. `supervisor.info` is the
//! firmware's supervisor bitfield (crazyflie-firmware `src/modules/src/supervisor.c`,
//! `updateLogData`; the same layout as crazyflie-lib's `SupervisorInfo`):
//!
//! | bit | mask | meaning |
//! |---|---|---|
//! | 0 | `0x0001` | can be armed (supervisor state "pre-flight checks passed") |
//! | 1 | `0x0002` | is armed |
//! | 2 | `0x0004` | auto-arm (firmware built without `CONFIG_MOTORS_REQUIRE_ARMING`) |
//! | 3 | `0x0008` | can fly: the motors are allowed to run |
//! | 4 | `0x0010` | is flying: state "flying" or "warning, level out" (thrust over idle within the last 2 s) |
//! | 5 | `0x0020` | is tumbled |
//! | 6 | `0x0040` | is locked: emergency stopped, motors off until a reboot |
//! | 7 | `0x0080` | is crashed |
//! | 8 | `0x0100` | high-level commander active (flying or landing) |
//! | 9 | `0x0200` | high-level trajectory finished |
//! | 10 | `0x0400` | high-level commander disabled (low-level setpoints took over) |
//!
//! `stabilizer.thrust` is the controller's collective thrust (0 when the motors are off: the
//! supervisor replaces the setpoint with a null one in every state but ready-to-fly, flying,
//! warning-level-out and landed).
//!
//! * An emergency stop is confirmed by the locked bit (and, when logged, zero thrust); a firmware
//!   without `supervisor.info` (before 2023) confirms it by zero thrust alone.
//! * A landing is confirmed when the estimated height is below [`ON_GROUND_M`] and the motors are
//!   off: zero thrust (once a landing trajectory ends, the high-level commander returns the null
//!   setpoint, `crtp_commander_high_level.c`: "when the HLcommander is stopped, it wants the motors
//!   to be off"), or the is-flying bit clear (which the firmware clears 2 s after the thrust went
//!   to idle).

/// The log variables that confirm a stop or a landing, in the order of [`Status`].
pub const STATUS_VARIABLES: [&str; 2] = ["supervisor.info", "stabilizer.thrust"];

/// Below this height (m) a Crazyflie is on the ground.
pub const ON_GROUND_M: f64 = 0.1;

/// Below this collective thrust (PWM units of 65535) the motors are off.
pub const THRUST_OFF: f64 = 1.0;

/// Bits of the firmware's `supervisor.info` (see the module documentation).
pub mod bits {
    /// The system can be armed.
    pub const CAN_BE_ARMED: u16 = 1 << 0;
    /// The system is armed.
    pub const IS_ARMED: u16 = 1 << 1;
    /// The firmware arms itself.
    pub const AUTO_ARM: u16 = 1 << 2;
    /// The motors are allowed to run.
    pub const CAN_FLY: u16 = 1 << 3;
    /// The supervisor considers the Crazyflie flying.
    pub const IS_FLYING: u16 = 1 << 4;
    /// Upside down or tilted for too long.
    pub const IS_TUMBLED: u16 = 1 << 5;
    /// Locked after an emergency stop: motors off until a reboot.
    pub const IS_LOCKED: u16 = 1 << 6;
    /// Crashed.
    pub const IS_CRASHED: u16 = 1 << 7;
    /// The high-level commander is flying or landing.
    pub const HL_ACTIVE: u16 = 1 << 8;
    /// The high-level trajectory has finished.
    pub const HL_FINISHED: u16 = 1 << 9;
    /// The high-level commander is disabled.
    pub const HL_DISABLED: u16 = 1 << 10;
}

/// What the Crazyflie's log says about its motors (each field only if the firmware logs it and a
/// sample arrived in this session).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Status {
    /// `supervisor.info`.
    pub info: Option<u16>,
    /// `stabilizer.thrust`.
    pub thrust: Option<f64>,
}

impl Status {
    fn thrust_off(&self) -> Option<bool> {
        self.thrust.map(|t| t.abs() < THRUST_OFF)
    }

    fn bit(&self, mask: u16) -> Option<bool> {
        self.info.map(|i| i & mask != 0)
    }

    /// The emergency stop is confirmed: locked (and zero thrust when logged), or, on a firmware
    /// without `supervisor.info`, zero thrust.
    pub fn confirms_stop(&self) -> bool {
        match (self.bit(bits::IS_LOCKED), self.thrust_off()) {
            (Some(locked), off) => locked && off != Some(false),
            (None, Some(off)) => off,
            (None, None) => false,
        }
    }

    /// A landing is confirmed at estimated height `z` (m): on the ground with the motors off (zero
    /// thrust) or the supervisor no longer flying.
    pub fn confirms_landed(&self, z: f64) -> bool {
        let off = self.thrust_off() == Some(true) || self.bit(bits::IS_FLYING) == Some(false);
        z < ON_GROUND_M && off
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const FLYING: u16 = bits::IS_ARMED | bits::AUTO_ARM | bits::CAN_FLY | bits::IS_FLYING;
    const LOCKED: u16 = bits::AUTO_ARM | bits::IS_LOCKED;

    #[test]
    fn bits_match_crazyflie_lib() {
        let info = crazyflie_lib::subsystems::supervisor::SupervisorInfo::from_bits(LOCKED);
        assert!(info.is_locked() && info.is_auto_armed() && !info.can_fly() && !info.is_flying());
        let info = crazyflie_lib::subsystems::supervisor::SupervisorInfo::from_bits(FLYING | bits::HL_ACTIVE);
        assert!(info.is_flying() && info.can_fly() && info.is_armed() && info.hl_control_active());
        let all = crazyflie_lib::subsystems::supervisor::SupervisorInfo::from_bits(
            bits::CAN_BE_ARMED | bits::IS_TUMBLED | bits::IS_CRASHED | bits::HL_FINISHED | bits::HL_DISABLED,
        );
        assert!(all.can_be_armed() && all.is_tumbled() && all.is_crashed());
        assert!(all.hl_traj_finished() && all.hl_control_disabled() && !all.is_locked());
    }

    #[test]
    fn a_stop_needs_the_lock_and_no_thrust() {
        let s = |info, thrust| Status { info, thrust };
        assert!(s(Some(LOCKED), Some(0.0)).confirms_stop());
        assert!(s(Some(LOCKED), None).confirms_stop());
        // Motors off by the setpoint watchdog, but not locked: a new setpoint would restart them.
        assert!(!s(Some(bits::AUTO_ARM | bits::CAN_FLY), Some(0.0)).confirms_stop());
        assert!(!s(Some(FLYING), Some(36000.0)).confirms_stop());
        assert!(!s(Some(LOCKED), Some(36000.0)).confirms_stop(), "locked but still thrusting");
        // Older firmware: no supervisor.info, zero thrust is all there is.
        assert!(s(None, Some(0.0)).confirms_stop() && !s(None, Some(20000.0)).confirms_stop());
        assert!(!Status::default().confirms_stop(), "nothing heard yet");
    }

    #[test]
    fn a_landing_needs_the_ground_and_the_motors_off() {
        let s = |info, thrust| Status { info, thrust };
        assert!(s(Some(FLYING), Some(0.0)).confirms_landed(0.0), "thrust off, still within the 2 s");
        assert!(s(Some(bits::AUTO_ARM | bits::CAN_FLY), None).confirms_landed(0.02));
        assert!(!s(Some(FLYING), Some(12000.0)).confirms_landed(0.02), "on the ground, motors on");
        assert!(!s(Some(FLYING), None).confirms_landed(0.02), "is-flying still set, thrust not logged");
        assert!(!s(Some(0), Some(0.0)).confirms_landed(0.5), "motors off but not down (falling)");
        assert!(!Status::default().confirms_landed(0.0), "nothing heard yet");
    }
}
