//! The simulated firmware: dispatches CRTP packets to the subsystems (platform, log, param,
//! memory, console, link, supervisor, flight control) and advances the simulation clock.

use crate::commands;
use crate::crtp::{
    self, PORT_CONSOLE, PORT_LINK, PORT_LOG, PORT_MEMORY, PORT_PARAM, PORT_PLATFORM, PORT_SUPERVISOR, Packet,
};
use crate::dynamics::Gains;
use crate::estimator::Estimator;
use crate::flight::{CONTROLLER_PID, Flight, FlightMode};
use crate::log::{Log, LogVar};
use crate::logvars::Sources;
use crate::param::Params;
use crate::services;
/// The supervisor's bits, also reachable here (`firmware::supervisor::IS_ARMED`).
pub use crate::supervisor;
use crate::supervisor::{Conditions, Supervisor};

/// The versions reported on the platform port, also reachable here.
pub use crate::services::{DEVICE_TYPE, PROTOCOL_VERSION};

/// Firmware settings that do not change while running.
#[derive(Debug, Clone)]
pub struct FirmwareSettings {
    /// Starting position on the ground.
    pub initial_position: [f64; 3],
    /// Controller gains and limits.
    pub gains: Gains,
    /// Fixed integration step (s).
    pub step: f64,
    /// Firmware version string.
    pub version: String,
    /// Without any packet for this long the link counts as lost and log blocks are reset (s).
    pub link_timeout: f64,
    /// Arms itself (the Crazyflie 2.1 default); `false` waits for an arming request, like a
    /// firmware built with `CONFIG_MOTORS_REQUIRE_ARMING`.
    pub auto_arm: bool,
    /// Answer null packets (port 15, channel 3) with an empty one, as a radio's acknowledgement
    /// would; the real firmware over UDP does not (the default).
    pub answer_null: bool,
}

/// The firmware state.
#[derive(Debug, Clone)]
pub struct Firmware {
    settings: FirmwareSettings,
    /// Log subsystem.
    pub log: Log,
    /// Param subsystem.
    pub params: Params,
    /// Flight control and dynamics.
    pub flight: Flight,
    /// The supervisor (arming, flying, locked).
    pub supervisor: Supervisor,
    /// The estimator's covariance (`kalman.var*`).
    pub estimator: Estimator,
    steps: u64,
    t: f64,
    last_rx: Option<f64>,
}

impl Firmware {
    /// Booted at time 0, on the ground at the initial position.
    pub fn new(settings: FirmwareSettings) -> Self {
        let flight = Flight::new(settings.initial_position, settings.gains);
        let supervisor = Supervisor::new(settings.auto_arm);
        let (log, params, estimator) = (Log::new(), Params::new(), Estimator::new());
        Self { settings, log, params, flight, supervisor, estimator, steps: 0, t: 0.0, last_rx: None }
    }

    /// A reboot: clears an emergency-stop lock, setpoints, log blocks, the supervisor and the
    /// estimator; the Crazyflie stays where it is.
    pub fn reboot(&mut self) {
        self.flight.reboot();
        self.log.reset();
        self.supervisor = Supervisor::new(self.settings.auto_arm);
        self.estimator.reset();
    }

    /// Simulation time (s since boot), a whole number of steps.
    pub fn time(&self) -> f64 {
        self.t
    }

    fn hl_enabled(&self) -> bool {
        self.params.get("commander", "enHighLevel").is_some_and(|v| v != 0.0)
    }

    /// Integrate up to time `t` (s) in fixed steps; returns the log data that became due.
    pub fn advance_to(&mut self, t: f64) -> Vec<Packet> {
        let dt = self.settings.step;
        // The supervisor runs every `PERIOD` on the step grid.
        let supervisor_steps = ((supervisor::PERIOD / dt).round() as u64).max(1);
        let mut out = Vec::new();
        while (self.steps + 1) as f64 * dt <= t + 1e-12 {
            self.steps += 1;
            self.t = self.steps as f64 * dt;
            let hl = self.hl_enabled();
            self.flight.controller =
                self.params.get("stabilizer", "controller").map_or(CONTROLLER_PID, |c| c as u8);
            self.flight.step(self.t, dt, hl, self.supervisor.motors_allowed());
            self.sync_lock();
            if self.steps.is_multiple_of(supervisor_steps) {
                let locked = self.flight.mode == FlightMode::Locked;
                let conditions = Conditions {
                    is_flying: self.flight.is_flying(self.t),
                    emergency_stop: locked,
                    commander_timeout: self.flight.watchdog_expired(),
                };
                self.supervisor.update(self.t, conditions);
                if self.supervisor.is_stopped() {
                    self.flight.lock();
                }
            }
            let std_dev = self.params.get("locSrv", "extPosStdDev").unwrap_or(0.01);
            self.estimator.step(dt, std_dev);
            if self.last_rx.is_some_and(|r| self.t - r > self.settings.link_timeout) {
                // The firmware resets logging when the radio link goes quiet.
                self.last_rx = None;
                self.log.reset();
            }
            let now = self.t;
            let sources = Sources {
                flight: &self.flight,
                supervisor: &self.supervisor,
                estimator: &self.estimator,
                hl_bits: self.flight.hl_bits(now, hl),
            };
            out.extend(self.log.due(now * 1000.0, |v| sources.sample(v)));
        }
        out
    }

    /// A client said hello (the UDP connect datagram): print a greeting on the console.
    pub fn on_connect(&mut self) -> Vec<Packet> {
        self.last_rx = Some(self.t);
        let text = format!("SYS: {DEVICE_TYPE} (cfsim) {}\n", self.settings.version);
        text.as_bytes().chunks(crtp::MAX_PAYLOAD).map(|c| Packet::new(PORT_CONSOLE, 0, c.to_vec())).collect()
    }

    /// The client said goodbye: the link is down, logging is reset.
    pub fn on_disconnect(&mut self) {
        self.last_rx = None;
        self.log.reset();
    }

    /// Handle one packet from the client at the current time; returns the answers.
    pub fn handle(&mut self, pk: &Packet) -> Vec<Packet> {
        self.last_rx = Some(self.t);
        let t = self.t;
        if let Some(cmd) = commands::decode(pk) {
            let hl = self.hl_enabled();
            self.flight.command(cmd, t, hl);
            self.sync_lock();
            return Vec::new();
        }
        let answer = match pk.port {
            PORT_PLATFORM => self.platform(pk),
            PORT_LOG => self.log.handle(pk, t * 1000.0),
            PORT_PARAM => {
                let (answer, written) = self.params.handle(pk);
                if let Some(i) = written {
                    self.param_written(i);
                }
                answer
            }
            PORT_MEMORY => services::memory(pk),
            PORT_SUPERVISOR => {
                let bits = self.supervisor_bits();
                self.supervisor.handle(pk, bits)
            }
            PORT_LINK => services::link(pk, self.settings.answer_null),
            _ => None,
        };
        answer.into_iter().collect()
    }

    /// An emergency stop locked the flight: the supervisor locks in the same step.
    fn sync_lock(&mut self) {
        if self.flight.mode == FlightMode::Locked && !self.supervisor.is_stopped() {
            self.supervisor.lock();
        }
    }

    fn param_written(&mut self, id: usize) {
        let entry = self.params.toc().entries().get(id).copied();
        if let Some(e) = entry
            && (e.group, e.name) == ("kalman", "resetEstimation")
        {
            // The estimate is the truth, its variances start over; the firmware clears the flag
            // once reset.
            self.estimator.reset();
            self.params.set("kalman", "resetEstimation", 0.0);
        }
    }

    /// Platform port: commands (channel 0, arming among them) and versions (channel 1).
    fn platform(&mut self, pk: &Packet) -> Option<Packet> {
        match pk.channel {
            0 => self.supervisor.platform_command(pk),
            1 => services::version(pk, &self.settings.version),
            _ => None,
        }
    }

    fn sources(&self) -> Sources<'_> {
        Sources {
            flight: &self.flight,
            supervisor: &self.supervisor,
            estimator: &self.estimator,
            hl_bits: self.flight.hl_bits(self.t, self.hl_enabled()),
        }
    }

    /// Supervisor bitfield (see crazyflie-lib's `SupervisorInfo`).
    pub fn supervisor_bits(&self) -> u16 {
        self.sources().supervisor_bits()
    }

    /// The current value of a log variable.
    pub fn sample(&self, var: LogVar) -> f64 {
        self.sources().sample(var)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::crtp::{PORT_HL_COMMANDER, PORT_SETPOINT_GENERIC};

    fn fw_arming(auto_arm: bool) -> Firmware {
        Firmware::new(FirmwareSettings {
            initial_position: [1.0, 2.0, 0.0],
            gains: Gains { kp: 2.0, kv: 8.0, max_accel: 4.0, max_speed: 5.0 },
            step: 0.002,
            version: "test".into(),
            link_timeout: 1.0,
            auto_arm,
            answer_null: false,
        })
    }

    fn fw() -> Firmware {
        fw_arming(true)
    }

    #[test]
    fn answers_platform_memory_link_supervisor() {
        let mut f = fw();
        let ask = |f: &mut Firmware, port, ch, d: &[u8]| f.handle(&Packet::new(port, ch, d.to_vec()));
        assert_eq!(ask(&mut f, 13, 1, &[1])[0].data, b"\x01test".to_vec());
        assert_eq!(ask(&mut f, 4, 0, &[1])[0].data, vec![1, 0]);
        assert!(ask(&mut f, 15, 3, &[]).is_empty(), "null packets unanswered, as on the firmware");
        assert_eq!(ask(&mut f, 15, 0, &[7])[0].data, vec![7], "the link echo answers");
        let sup = ask(&mut f, 9, 0, &[0x0c]);
        assert_eq!(sup[0].data, [vec![0x8c], f.supervisor_bits().to_le_bytes().to_vec()].concat());
        assert_eq!(ask(&mut f, 9, 1, &[1, 1])[0].data, vec![0x81, 1, 1], "auto-armed: already armed");
        assert_eq!(ask(&mut f, 13, 0, &[0, 1])[0].data, vec![0, 1], "platform commands are echoed");
        assert!(ask(&mut f, 13, 1, &[]).is_empty());
        assert!(ask(&mut f, 11, 0, &[1, 2, 3]).is_empty());
    }

    #[test]
    fn log_stream_timing_and_link_loss_reset() {
        let mut f = fw();
        f.handle(&Packet::new(5, 1, vec![6, 0, 7, 0, 0]));
        f.handle(&Packet::new(5, 1, vec![3, 0, 1]));
        let pk = f.advance_to(0.1);
        assert_eq!(pk.len(), 10);
        assert_eq!(f32::from_le_bytes(pk[0].data[4..8].try_into().expect("4")), 1.0);
        f.advance_to(1.2);
        assert_eq!(f.log.block_count(), 0, "reset after a second without packets");
    }

    fn hl(cmd: u8, height: f32, duration: f32) -> Packet {
        let mut d = vec![cmd, 0];
        d.extend_from_slice(&height.to_le_bytes());
        d.extend_from_slice(&0f32.to_le_bytes());
        d.push(1);
        d.extend_from_slice(&duration.to_le_bytes());
        Packet::new(PORT_HL_COMMANDER, 0, d)
    }

    fn hold(z: f32) -> Packet {
        let mut d = vec![7];
        for x in [0.0f32, 0.0, z, 0.0] {
            d.extend_from_slice(&x.to_le_bytes());
        }
        Packet::new(PORT_SETPOINT_GENERIC, 0, d)
    }

    #[test]
    fn supervisor_bits_follow_the_firmware_states() {
        use supervisor::*;
        let lib = crazyflie_lib::subsystems::supervisor::SupervisorInfo::from_bits;
        let mut f = fw();
        let ready = IS_ARMED | AUTO_ARM | CAN_FLY;
        assert_eq!(f.supervisor_bits(), ready, "on the ground, auto-armed");
        let info = lib(f.supervisor_bits());
        assert!(info.is_armed() && info.is_auto_armed() && info.can_fly() && !info.can_be_armed());
        assert!(!info.is_flying() && !info.is_locked());

        f.handle(&hl(7, 1.0, 1.0));
        f.advance_to(0.5);
        assert_eq!(f.supervisor_bits(), ready | IS_FLYING | HL_ACTIVE, "taking off");
        f.advance_to(1.5);
        assert_eq!(f.supervisor_bits(), ready | IS_FLYING | HL_ACTIVE | HL_FINISHED, "hovering");
        f.handle(&hold(1.0));
        f.advance_to(1.6);
        assert_eq!(f.supervisor_bits(), ready | IS_FLYING | HL_DISABLED, "low-level setpoints");
        assert!(lib(f.supervisor_bits()).hl_control_disabled());

        // Land: the motors stop when the trajectory ends; the supervisor calls it flying for 2 s more.
        f.handle(&Packet::new(PORT_SETPOINT_GENERIC, 1, vec![0, 0, 0, 0, 0]));
        f.handle(&hl(8, 0.0, 1.0));
        f.advance_to(2.0);
        assert_eq!(f.supervisor_bits(), ready | IS_FLYING | HL_ACTIVE, "landing");
        assert!(f.sample(LogVar::Thrust) > 0.0);
        f.advance_to(3.0);
        assert!(!f.flight.motors_on && f.sample(LogVar::Z) < 0.01);
        assert_eq!(f.sample(LogVar::Thrust), 0.0, "motors off, thrust logged as 0");
        assert_eq!(f.supervisor_bits() & IS_FLYING, IS_FLYING, "within the 2 s hysteresis");
        f.advance_to(5.0);
        assert_eq!(f.supervisor_bits(), ready, "down for more than 2 s: not flying");
        assert_eq!(f.sample(LogVar::IsFlying), 0.0);

        // Emergency stop in flight: locked at once, motors off, and the log says so.
        f.handle(&hl(7, 1.0, 1.0));
        f.advance_to(6.5);
        assert!(f.flight.motors_on && f.supervisor_bits() & IS_FLYING != 0);
        f.handle(&Packet::new(PORT_SUPERVISOR, 1, vec![3]));
        let stopped = AUTO_ARM | IS_LOCKED;
        assert_eq!(f.supervisor_bits(), stopped, "locked: disarmed, cannot fly, not flying");
        assert!(!f.flight.motors_on);
        assert_eq!((f.sample(LogVar::Thrust), f.sample(LogVar::CanFly)), (0.0, 0.0));
        let info = lib(f.supervisor_bits());
        assert!(info.is_locked() && !info.can_fly() && !info.is_flying() && !info.is_armed());
        // It stays locked: commands are ignored, it falls and rests on the ground.
        f.handle(&hold(1.0));
        f.handle(&hl(7, 1.0, 1.0));
        f.advance_to(8.0);
        assert_eq!(f.supervisor_bits(), stopped);
        assert!(!f.flight.motors_on && f.sample(LogVar::Z) == 0.0);
        // The supervisor port answers with the same bitfield as the log.
        let answer = f.handle(&Packet::new(PORT_SUPERVISOR, 0, vec![0x0c]));
        assert_eq!(answer[0].data, [vec![0x8c], stopped.to_le_bytes().to_vec()].concat());
        assert_eq!(f.sample(LogVar::SupervisorInfo), f64::from(stopped));
    }

    #[test]
    fn arming_gates_the_motors_and_disarming_in_flight_locks() {
        use supervisor::*;
        let mut f = fw_arming(false);
        let arm = |f: &mut Firmware, on: u8| f.handle(&Packet::new(PORT_SUPERVISOR, 1, vec![1, on]));
        assert_eq!(f.supervisor_bits(), CAN_BE_ARMED);
        // Not armed: the take-off is planned but the motors stay off.
        f.handle(&hl(7, 1.0, 1.0));
        f.advance_to(1.5);
        assert!(!f.flight.motors_on && f.sample(LogVar::Z) == 0.0 && f.sample(LogVar::CanFly) == 0.0);
        assert_eq!(f.supervisor_bits() & (IS_ARMED | CAN_FLY | IS_FLYING), 0);
        // The legacy platform request arms too; its answer is [cmd, success].
        let answer = f.handle(&Packet::new(PORT_PLATFORM, 0, vec![1, 1]));
        assert_eq!((answer[0].port, answer[0].channel, answer[0].data.clone()), (13, 0, vec![1, 1]));
        assert_eq!(arm(&mut f, 0)[0].data, vec![0x81, 1, 0], "disarmed");
        assert_eq!(arm(&mut f, 1)[0].data, vec![0x81, 1, 1], "armed");
        f.advance_to(1.6);
        assert_eq!(f.supervisor_bits() & (CAN_BE_ARMED | IS_ARMED | CAN_FLY), IS_ARMED | CAN_FLY);
        // The planned take-off ended while disarmed: armed, it climbs to the planned height.
        f.advance_to(4.0);
        assert!(f.flight.motors_on && (f.sample(LogVar::Z) - 1.0).abs() < 0.02);
        assert_eq!(f.supervisor_bits() & IS_FLYING, IS_FLYING);
        assert_eq!(arm(&mut f, 1)[0].data, vec![0x81, 1, 1], "arming when armed succeeds in flight");
        // Disarmed in flight: the firmware cuts the motors ("exception, free fall") and locks.
        assert_eq!(arm(&mut f, 0)[0].data, vec![0x81, 1, 0]);
        f.advance_to(4.1);
        assert!(!f.flight.motors_on && f.flight.mode == FlightMode::Locked);
        assert_eq!(f.supervisor_bits() & !HL_DISABLED, IS_LOCKED);
        assert_eq!(arm(&mut f, 1)[0].data, vec![0x81, 0, 0], "no arming while locked");
        f.advance_to(5.0);
        assert_eq!(f.sample(LogVar::Z), 0.0);
        // A reboot waits for arming again.
        f.reboot();
        assert_eq!(f.supervisor_bits() & !HL_DISABLED, CAN_BE_ARMED);
    }

    #[test]
    fn reset_estimation_restarts_the_variances() {
        let mut f = fw();
        f.advance_to(1.0);
        assert!(f.sample(LogVar::VarPosition(0)) < 1e-4 && f.sample(LogVar::VarVelocity(2)) < 1e-3);
        let id = f.params.toc().find("kalman", "resetEstimation").expect("param") as u16;
        f.handle(&Packet::new(PORT_PARAM, 2, [id.to_le_bytes().as_slice(), &[1]].concat()));
        assert_eq!(f.params.get("kalman", "resetEstimation"), Some(0.0), "the flag clears");
        assert!(f.sample(LogVar::VarPosition(0)) > 1000.0, "uncertain again");
        f.advance_to(1.5);
        assert!(f.sample(LogVar::VarPosition(0)) < 1e-4);
    }

    #[test]
    fn random_packets_never_panic() {
        let mut f = fw();
        let mut x = 12345u32;
        for _ in 0..20_000 {
            x ^= x << 13;
            x ^= x >> 17;
            x ^= x << 5;
            let len = (x % 32) as usize;
            let d: Vec<u8> = (0..len).map(|i| (x >> (i % 24)) as u8).collect();
            if let Some(pk) = Packet::parse(&d) {
                f.handle(&pk);
            }
        }
        f.advance_to(1.0);
    }
}
