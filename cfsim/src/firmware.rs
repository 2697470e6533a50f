//! The simulated firmware: dispatches CRTP packets to the subsystems (platform, log, param,
//! memory, console, link, supervisor, flight control) and advances the simulation clock.

use crate::commands;
use crate::crtp::{
    self, PORT_CONSOLE, PORT_LINK, PORT_LOG, PORT_MEMORY, PORT_PARAM, PORT_PLATFORM, PORT_SUPERVISOR, Packet,
};
use crate::dynamics::{G, Gains};
use crate::flight::{Flight, FlightMode};
use crate::log::{Log, LogVar};
use crate::param::Params;
use crate::planner::PlanState;

/// CRTP protocol version reported on the platform port (crazyflie-lib 0.8 accepts 12..=13).
pub const PROTOCOL_VERSION: u8 = 12;
/// Device type name reported on the platform port.
pub const DEVICE_TYPE: &str = "Crazyflie 2.1";

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
    steps: u64,
    t: f64,
    last_rx: Option<f64>,
}

impl Firmware {
    /// Booted at time 0, on the ground at the initial position.
    pub fn new(settings: FirmwareSettings) -> Self {
        let flight = Flight::new(settings.initial_position, settings.gains);
        Self { settings, log: Log::new(), params: Params::new(), flight, steps: 0, t: 0.0, last_rx: None }
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
        let mut out = Vec::new();
        while (self.steps + 1) as f64 * dt <= t + 1e-12 {
            self.steps += 1;
            self.t = self.steps as f64 * dt;
            let hl = self.hl_enabled();
            self.flight.step(self.t, dt, hl);
            if self.last_rx.is_some_and(|r| self.t - r > self.settings.link_timeout) {
                // The firmware resets logging when the radio link goes quiet.
                self.last_rx = None;
                self.log.reset();
            }
            let (flight, now) = (&self.flight, self.t);
            out.extend(self.log.due(now * 1000.0, |v| sample(flight, hl, now, v)));
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
            PORT_MEMORY => memory(pk),
            PORT_SUPERVISOR if pk.channel == 0 && pk.data.first() == Some(&0x0c) => {
                let mut d = vec![0x0c];
                d.extend_from_slice(&self.supervisor_bits().to_le_bytes());
                Some(Packet::new(PORT_SUPERVISOR, 0, d))
            }
            PORT_LINK => link(pk),
            _ => None,
        };
        answer.into_iter().collect()
    }

    fn param_written(&mut self, id: usize) {
        let entry = self.params.toc().entries().get(id).copied();
        if let Some(e) = entry
            && (e.group, e.name) == ("kalman", "resetEstimation")
        {
            // The estimate is the truth; the firmware clears the flag once reset.
            self.params.set("kalman", "resetEstimation", 0.0);
        }
    }

    fn platform(&self, pk: &Packet) -> Option<Packet> {
        if pk.channel != 1 {
            return None;
        }
        let cmd = crtp::u8_at(&pk.data, 0)?;
        let mut d = vec![cmd];
        match cmd {
            0 => d.push(PROTOCOL_VERSION),
            1 => d.extend_from_slice(self.settings.version.as_bytes()),
            2 => d.extend_from_slice(DEVICE_TYPE.as_bytes()),
            _ => return None,
        }
        d.truncate(crtp::MAX_PAYLOAD);
        Some(Packet::new(PORT_PLATFORM, 1, d))
    }

    /// Supervisor bitfield (see crazyflie-lib's `SupervisorInfo`).
    pub fn supervisor_bits(&self) -> u16 {
        supervisor_bits(&self.flight, self.hl_enabled(), self.t)
    }

    /// The current value of a log variable.
    pub fn sample(&self, var: LogVar) -> f64 {
        sample(&self.flight, self.hl_enabled(), self.t, var)
    }
}

/// Bits of `supervisor.info`, as the firmware's `supervisor.c` (`updateLogData`) sets them (the
/// relay reads them through crazyflie-lib's `SupervisorInfo`; a test checks they agree).
pub mod supervisor {
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
}

/// The supervisor bitfield of `f` at time `t`. The simulated Crazyflie auto-arms, never tumbles
/// or crashes. Its supervisor states: ready to fly (armed, can fly) on the ground; flying while
/// the motors ran within the last 2 s ([`Flight::is_flying`]); locked after an emergency stop
/// (only auto-arm and locked: disarmed, motors not allowed, not flying). "Can be armed" is the
/// pre-flight-checks-passed state, which an auto-arming firmware leaves in the same supervisor
/// cycle, so it is never reported.
fn supervisor_bits(f: &Flight, hl_enabled: bool, t: f64) -> u16 {
    use supervisor::*;
    let locked = f.mode == FlightMode::Locked;
    let plan = f.plan_state();
    let bits = [
        (IS_ARMED, !locked),
        (AUTO_ARM, true),
        (CAN_FLY, !locked),
        (IS_FLYING, f.is_flying(t)),
        (IS_LOCKED, locked),
        (HL_ACTIVE, matches!(plan, PlanState::Flying | PlanState::Landing)),
        (HL_FINISHED, f.hl_finished(t)),
        (HL_DISABLED, plan == PlanState::Disabled || !hl_enabled),
    ];
    bits.iter().filter(|(_, on)| *on).fold(0, |acc, (bit, _)| acc | bit)
}

fn sample(f: &Flight, hl_enabled: bool, t: f64, var: LogVar) -> f64 {
    let b = &f.body;
    let ext = |k: usize| f.external.map_or(0.0, |p| f64::from(p[k]));
    let flag = |x: bool| if x { 1.0 } else { 0.0 };
    match var {
        LogVar::X => b.p[0],
        LogVar::Y => b.p[1],
        LogVar::Z => b.p[2],
        LogVar::Vx => b.v[0],
        LogVar::Vy => b.v[1],
        LogVar::Vz => b.v[2],
        LogVar::Ax => b.a[0],
        LogVar::Ay => b.a[1],
        LogVar::Az => b.a[2],
        LogVar::Roll | LogVar::Yaw => 0.0,
        // Small-angle tilt that produces the horizontal acceleration.
        LogVar::Pitch => (b.a[0] / G).atan().to_degrees(),
        LogVar::Vbat => (4.15 - 0.004 * f.motor_time).max(3.0),
        LogVar::PmState => 0.0,
        LogVar::SupervisorInfo => f64::from(supervisor_bits(f, hl_enabled, t)),
        LogVar::CanFly => flag(f.mode != FlightMode::Locked),
        LogVar::IsFlying => flag(f.is_flying(t)),
        LogVar::IsTumbled => 0.0,
        LogVar::ExtX => ext(0),
        LogVar::ExtY => ext(1),
        LogVar::ExtZ => ext(2),
        LogVar::Thrust if f.motors_on => (36000.0 * (1.0 + b.a[2] / G)).clamp(0.0, 65535.0),
        LogVar::Thrust => 0.0,
    }
}

/// Memory port: the simulator has no memories.
fn memory(pk: &Packet) -> Option<Packet> {
    match (pk.channel, crtp::u8_at(&pk.data, 0)?) {
        // CMD_INFO_VER, CMD_INFO_NBR.
        (0, 0) => Some(Packet::new(PORT_MEMORY, 0, vec![0, 1])),
        (0, 1) => Some(Packet::new(PORT_MEMORY, 0, vec![1, 0])),
        _ => None,
    }
}

/// Link port: echo (0), source (1), sink (2); null packets (3) are answered with an empty
/// channel-3 packet (`0xF3`), the UDP stand-in for the radio's empty acknowledgement (cflib's UDP
/// scan relies on an answer).
fn link(pk: &Packet) -> Option<Packet> {
    match pk.channel {
        0 => Some(Packet::new(PORT_LINK, 0, pk.data.clone())),
        1 => {
            let mut d = b"Bitcraze Crazyflie".to_vec();
            d.resize(crtp::MAX_PAYLOAD, 0);
            Some(Packet::new(PORT_LINK, 1, d))
        }
        3 => Some(Packet::new(PORT_LINK, 3, Vec::new())),
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::crtp::{PORT_HL_COMMANDER, PORT_SETPOINT_GENERIC};

    fn fw() -> Firmware {
        Firmware::new(FirmwareSettings {
            initial_position: [1.0, 2.0, 0.0],
            gains: Gains { kp: 2.0, kv: 8.0, max_accel: 4.0, max_speed: 5.0 },
            step: 0.002,
            version: "test".into(),
            link_timeout: 1.0,
        })
    }

    #[test]
    fn answers_platform_memory_link_supervisor() {
        let mut f = fw();
        let ask = |f: &mut Firmware, port, ch, d: &[u8]| f.handle(&Packet::new(port, ch, d.to_vec()));
        assert_eq!(ask(&mut f, 13, 1, &[0])[0].data, vec![0, PROTOCOL_VERSION]);
        assert_eq!(ask(&mut f, 13, 1, &[1])[0].data, b"\x01test".to_vec());
        assert_eq!(ask(&mut f, 4, 0, &[1])[0].data, vec![1, 0]);
        assert_eq!(ask(&mut f, 15, 0, &[1, 2])[0].data, vec![1, 2]);
        assert!(ask(&mut f, 15, 2, &[1, 2]).is_empty());
        assert_eq!(ask(&mut f, 15, 3, &[])[0].to_datagram(), vec![0xf3]);
        let sup = ask(&mut f, 9, 0, &[0x0c]);
        assert_eq!(sup[0].data.len(), 3);
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
    fn every_supervisor_bit_means_what_crazyflie_lib_reads() {
        use supervisor::*;
        let lib = crazyflie_lib::subsystems::supervisor::SupervisorInfo::from_bits;
        let one = |bit: u16, read: fn(&crazyflie_lib::subsystems::supervisor::SupervisorInfo) -> bool| {
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
        assert_eq!(answer[0].data, [vec![0x0c], stopped.to_le_bytes().to_vec()].concat());
        assert_eq!(f.sample(LogVar::SupervisorInfo), f64::from(stopped));
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
