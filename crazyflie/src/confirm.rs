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

use crazyflie_lib::subsystems::supervisor::SupervisorInfo;

/// The log variables that confirm a stop or a landing, and the battery, in the order of [`Status`].
pub const STATUS_VARIABLES: [&str; 3] = ["supervisor.info", "stabilizer.thrust", "pm.vbat"];

/// Below this height (m) a Crazyflie is on the ground.
pub const ON_GROUND_M: f64 = 0.1;

/// A take-off is done within this distance of the flight altitude (m).
pub const TAKEOFF_TOLERANCE_M: f64 = 0.15;

/// Below this collective thrust (PWM units of 65535) the motors are off.
pub const THRUST_OFF: f64 = 1.0;

/// What the Crazyflie's log says about its motors (each field only if the firmware logs it and a
/// sample arrived in this session).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Status {
    /// `supervisor.info`.
    pub info: Option<u16>,
    /// `stabilizer.thrust`.
    pub thrust: Option<f64>,
    /// `pm.vbat` (V).
    pub vbat: Option<f64>,
}

impl Status {
    fn thrust_off(&self) -> Option<bool> {
        self.thrust.map(|t| t.abs() < THRUST_OFF)
    }

    /// `supervisor.info` decoded by crazyflie-lib (the layout above).
    fn supervisor(&self) -> Option<SupervisorInfo> {
        self.info.map(SupervisorInfo::from_bits)
    }

    /// The emergency stop is confirmed: locked (and zero thrust when logged), or, on a firmware
    /// without `supervisor.info`, zero thrust.
    pub fn confirms_stop(&self) -> bool {
        match (self.supervisor().map(|s| s.is_locked()), self.thrust_off()) {
            (Some(locked), off) => locked && off != Some(false),
            (None, Some(off)) => off,
            (None, None) => false,
        }
    }

    /// A landing is confirmed at estimated height `z` (m): on the ground with the motors off (zero
    /// thrust) or the supervisor no longer flying.
    pub fn confirms_landed(&self, z: f64) -> bool {
        let off = self.thrust_off() == Some(true) || self.supervisor().is_some_and(|s| !s.is_flying());
        z < ON_GROUND_M && off
    }

    /// A take-off to `altitude` is confirmed at estimated height `z` (m): within
    /// [`TAKEOFF_TOLERANCE_M`] of it, with the motors running and (when logged) the supervisor
    /// flying and not locked. Nothing heard yet confirms nothing.
    pub fn confirms_airborne(&self, z: f64, altitude: f64) -> bool {
        let heard = self.info.is_some() || self.thrust.is_some();
        let supervisor_flying = self.supervisor().is_none_or(|s| s.is_flying() && !s.is_locked());
        heard
            && supervisor_flying
            && self.thrust_off() != Some(true)
            && (z - altitude).abs() <= TAKEOFF_TOLERANCE_M
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    // The simulated firmware's bits, checked against crazyflie-lib in cfsim's own tests.
    use cfsim::firmware::supervisor as bits;

    const FLYING: u16 = bits::IS_ARMED | bits::AUTO_ARM | bits::CAN_FLY | bits::IS_FLYING;
    const LOCKED: u16 = bits::AUTO_ARM | bits::IS_LOCKED;

    #[test]
    fn a_stop_needs_the_lock_and_no_thrust() {
        let s = |info, thrust| Status { info, thrust, vbat: None };
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
        let s = |info, thrust| Status { info, thrust, vbat: None };
        assert!(s(Some(FLYING), Some(0.0)).confirms_landed(0.0), "thrust off, still within the 2 s");
        assert!(s(Some(bits::AUTO_ARM | bits::CAN_FLY), None).confirms_landed(0.02));
        assert!(!s(Some(FLYING), Some(12000.0)).confirms_landed(0.02), "on the ground, motors on");
        assert!(!s(Some(FLYING), None).confirms_landed(0.02), "is-flying still set, thrust not logged");
        assert!(!s(Some(0), Some(0.0)).confirms_landed(0.5), "motors off but not down (falling)");
        assert!(!Status::default().confirms_landed(0.0), "nothing heard yet");
    }

    #[test]
    fn a_take_off_needs_the_height_the_motors_and_the_supervisor() {
        let s = |info, thrust| Status { info, thrust, vbat: None };
        assert!(s(Some(FLYING), Some(36000.0)).confirms_airborne(0.95, 1.0));
        assert!(s(Some(FLYING), None).confirms_airborne(1.1, 1.0));
        assert!(s(None, Some(36000.0)).confirms_airborne(1.0, 1.0), "older firmware: thrust alone");
        assert!(!s(Some(FLYING), Some(36000.0)).confirms_airborne(0.5, 1.0), "still climbing");
        assert!(!s(Some(FLYING), Some(36000.0)).confirms_airborne(1.3, 1.0), "overshot");
        assert!(
            !s(Some(bits::AUTO_ARM | bits::CAN_FLY), Some(36000.0)).confirms_airborne(1.0, 1.0),
            "not flying"
        );
        assert!(!s(Some(FLYING | bits::IS_LOCKED), Some(36000.0)).confirms_airborne(1.0, 1.0), "locked");
        assert!(!s(Some(FLYING), Some(0.0)).confirms_airborne(1.0, 1.0), "motors off");
        assert!(!Status::default().confirms_airborne(1.0, 1.0), "nothing heard yet");
    }
}
