//! Decoding of the flight-control packets: legacy commander (port 3), generic setpoints
//! (port 7), high-level commander (port 8), localization (port 6) and supervisor commands
//! (port 9). A packet of the wrong length or with non-finite numbers decodes to `None` and is
//! ignored (the firmware asserts on a wrong length).

use crate::crtp::{
    self, PORT_COMMANDER, PORT_HL_COMMANDER, PORT_LOCALIZATION, PORT_SETPOINT_GENERIC, PORT_SUPERVISOR,
    Packet,
};

/// A low-level setpoint (units converted to SI, angles kept as sent).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Setpoint {
    /// Motors off.
    Stop,
    /// Absolute position (m).
    Position([f64; 3]),
    /// Position (m), velocity (m/s) and acceleration feed-forward (m/s²).
    FullState {
        /// Position.
        p: [f64; 3],
        /// Velocity.
        v: [f64; 3],
        /// Acceleration.
        a: [f64; 3],
    },
    /// Velocity in the world frame (m/s).
    VelocityWorld([f64; 3]),
    /// Horizontal velocity (m/s; body = world, the simulator keeps yaw at 0) at height `z` (m).
    Hover {
        /// Velocity x.
        vx: f64,
        /// Velocity y.
        vy: f64,
        /// Height.
        z: f64,
    },
    /// Roll and pitch (rad) at height `z` (m).
    ZDistance {
        /// Roll.
        roll: f64,
        /// Pitch.
        pitch: f64,
        /// Height.
        z: f64,
    },
    /// Roll and pitch (rad) with a vertical velocity (m/s).
    AltHold {
        /// Roll.
        roll: f64,
        /// Pitch.
        pitch: f64,
        /// Vertical velocity.
        vz: f64,
    },
    /// Roll and pitch (rad) with a thrust fraction of full scale in [0, 1].
    Attitude {
        /// Roll.
        roll: f64,
        /// Pitch.
        pitch: f64,
        /// Thrust fraction.
        thrust: f64,
        /// True when it came from the legacy port (subject to the thrust lock).
        legacy: bool,
    },
}

/// A high-level commander command.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum HlCommand {
    /// Set this Crazyflie's group mask.
    SetGroupMask(u8),
    /// Stop the trajectory and the motors.
    Stop {
        /// Group mask the command is for.
        group: u8,
    },
    /// Take off vertically to `height` in `duration` seconds.
    Takeoff {
        /// Group mask the command is for.
        group: u8,
        /// Absolute target height (m).
        height: f64,
        /// Duration (s).
        duration: f64,
    },
    /// Land vertically to `height` in `duration` seconds, then stop the motors.
    Land {
        /// Group mask the command is for.
        group: u8,
        /// Absolute target height (m).
        height: f64,
        /// Duration (s).
        duration: f64,
    },
    /// Go to a position in `duration` seconds.
    GoTo {
        /// Group mask the command is for.
        group: u8,
        /// Relative to the current goal instead of absolute.
        relative: bool,
        /// Target (m).
        target: [f64; 3],
        /// Duration (s).
        duration: f64,
    },
}

/// A decoded flight-control command.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Command {
    /// A low-level setpoint.
    Setpoint(Setpoint),
    /// Lower the low-level priority; the setpoint stays valid for `remain_ms` more.
    NotifySetpointsStop {
        /// Milliseconds the last setpoint stays valid.
        remain_ms: u32,
    },
    /// A high-level commander command.
    Hl(HlCommand),
    /// External position measurement (m).
    ExternalPosition([f32; 3]),
    /// Emergency stop: motors off and locked until reboot.
    EmergencyStop,
    /// Arm (or re-arm) the emergency-stop watchdog.
    EmergencyStopWatchdog,
}

fn finite<const N: usize>(v: [f32; N]) -> Option<[f64; N]> {
    v.iter().all(|x| x.is_finite()).then(|| v.map(f64::from))
}

/// Decode a flight-control packet; `None` for anything else or anything malformed.
pub fn decode(pk: &Packet) -> Option<Command> {
    let d = pk.data.as_slice();
    match (pk.port, pk.channel) {
        (PORT_COMMANDER, 0) => legacy(d).map(Command::Setpoint),
        (PORT_SETPOINT_GENERIC, 0) => generic(d).map(Command::Setpoint),
        (PORT_SETPOINT_GENERIC, 1) if d.len() == 5 && d[0] == 0 => {
            Some(Command::NotifySetpointsStop { remain_ms: crtp::u32_at(d, 1)? })
        }
        (PORT_HL_COMMANDER, 0) => high_level(d).map(Command::Hl),
        (PORT_LOCALIZATION, 0) if d.len() == 12 => {
            let p: [f32; 3] = crtp::f32s_at(d, 0)?;
            finite(p)?;
            Some(Command::ExternalPosition(p))
        }
        (PORT_LOCALIZATION, 1) => match crtp::u8_at(d, 0)? {
            3 => Some(Command::EmergencyStop),
            4 => Some(Command::EmergencyStopWatchdog),
            // External pose: position then quaternion; the orientation is not simulated.
            8 if d.len() == 29 => {
                let p: [f32; 3] = crtp::f32s_at(d, 1)?;
                finite(p)?;
                Some(Command::ExternalPosition(p))
            }
            _ => None,
        },
        (PORT_SUPERVISOR, 1) => match crtp::u8_at(d, 0)? {
            3 => Some(Command::EmergencyStop),
            4 => Some(Command::EmergencyStopWatchdog),
            _ => None,
        },
        _ => None,
    }
}

/// Port 3: roll, pitch, yawrate (deg, f32) and thrust (u16).
fn legacy(d: &[u8]) -> Option<Setpoint> {
    if d.len() != 14 {
        return None;
    }
    let [roll, pitch, _yawrate] = finite(crtp::f32s_at::<3>(d, 0)?)?;
    let thrust = crtp::u16_at(d, 12)?;
    Some(if thrust == 0 {
        Setpoint::Stop
    } else {
        Setpoint::Attitude {
            roll: roll.to_radians(),
            pitch: pitch.to_radians(),
            thrust: f64::from(thrust) / 65535.0,
            legacy: true,
        }
    })
}

/// Port 7 channel 0. Types 1/2/5 are the original velocity-world/z-distance/hover packets and
/// 8/9/10 their current numbering (same layouts); 11 is the manual setpoint.
fn generic(d: &[u8]) -> Option<Setpoint> {
    let (&kind, body) = d.split_first()?;
    let four = || -> Option<[f64; 4]> {
        if body.len() != 16 {
            return None;
        }
        finite(crtp::f32s_at::<4>(body, 0)?)
    };
    match kind {
        0 => Some(Setpoint::Stop),
        1 | 8 => four().map(|[vx, vy, vz, _]| Setpoint::VelocityWorld([vx, vy, vz])),
        2 | 9 => {
            four().map(|[r, p, _, z]| Setpoint::ZDistance { roll: r.to_radians(), pitch: p.to_radians(), z })
        }
        4 => four().map(|[roll, pitch, _, vz]| Setpoint::AltHold { roll, pitch, vz }),
        5 | 10 => four().map(|[vx, vy, _, z]| Setpoint::Hover { vx, vy, z }),
        6 => full_state(body),
        7 => four().map(|[x, y, z, _]| Setpoint::Position([x, y, z])),
        11 if body.len() == 15 => {
            let [r, p, _] = finite(crtp::f32s_at::<3>(body, 0)?)?;
            let thrust = f64::from(crtp::u16_at(body, 12)?) / 65535.0;
            let rate = crtp::u8_at(body, 14)? != 0;
            // Rate mode is approximated as level attitude.
            let (roll, pitch) = if rate { (0.0, 0.0) } else { (r.to_radians(), p.to_radians()) };
            Some(Setpoint::Attitude { roll, pitch, thrust, legacy: false })
        }
        _ => None,
    }
}

/// Full state: 9 × i16 (mm, mm/s, mm/s²), compressed quaternion (u32), 3 × i16 rates.
fn full_state(body: &[u8]) -> Option<Setpoint> {
    if body.len() != 28 {
        return None;
    }
    let mut v = [0.0; 9];
    for (k, x) in v.iter_mut().enumerate() {
        *x = f64::from(crtp::i16_at(body, 2 * k)?) / 1000.0;
    }
    Some(Setpoint::FullState { p: [v[0], v[1], v[2]], v: [v[3], v[4], v[5]], a: [v[6], v[7], v[8]] })
}

/// Port 8 channel 0.
fn high_level(d: &[u8]) -> Option<HlCommand> {
    let (&cmd, b) = d.split_first()?;
    let f = |i: usize| crtp::f32_at(b, i).filter(|x| x.is_finite()).map(f64::from);
    match (cmd, b.len()) {
        (0, 1) => Some(HlCommand::SetGroupMask(b[0])),
        (3, 1) => Some(HlCommand::Stop { group: b[0] }),
        // v1: group, height, duration.
        (1, 9) => Some(HlCommand::Takeoff { group: b[0], height: f(1)?, duration: f(5)? }),
        (2, 9) => Some(HlCommand::Land { group: b[0], height: f(1)?, duration: f(5)? }),
        // v2: group, height, yaw, use-current-yaw, duration.
        (7, 14) => Some(HlCommand::Takeoff { group: b[0], height: f(1)?, duration: f(10)? }),
        (8, 14) => Some(HlCommand::Land { group: b[0], height: f(1)?, duration: f(10)? }),
        // v1: group, relative, x, y, z, yaw, duration.
        (4, 22) => Some(HlCommand::GoTo {
            group: b[0],
            relative: b[1] != 0,
            target: [f(2)?, f(6)?, f(10)?],
            duration: f(18)?,
        }),
        // v2: group, relative, linear, x, y, z, yaw, duration.
        (12, 23) => Some(HlCommand::GoTo {
            group: b[0],
            relative: b[1] != 0,
            target: [f(3)?, f(7)?, f(11)?],
            duration: f(19)?,
        }),
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pk(port: u8, ch: u8, d: &[u8]) -> Packet {
        Packet::new(port, ch, d.to_vec())
    }

    fn floats(kind: u8, v: &[f32]) -> Vec<u8> {
        let mut out = vec![kind];
        v.iter().for_each(|x| out.extend_from_slice(&x.to_le_bytes()));
        out
    }

    #[test]
    fn decodes_what_the_client_sends() {
        let p = decode(&pk(7, 0, &floats(7, &[1.0, 2.0, 3.0, 0.0])));
        assert_eq!(p, Some(Command::Setpoint(Setpoint::Position([1.0, 2.0, 3.0]))));
        let mut fs = vec![6];
        for x in [1000i16, -500, 250, 100, 0, 0, 0, 0, -9810] {
            fs.extend_from_slice(&x.to_le_bytes());
        }
        fs.extend_from_slice(&[0; 10]);
        let Some(Command::Setpoint(Setpoint::FullState { p, v, a })) = decode(&pk(7, 0, &fs)) else {
            panic!("full state not decoded");
        };
        assert_eq!((p, v[0], a[2]), ([1.0, -0.5, 0.25], 0.1, -9.81));
        let mut to = vec![7, 0];
        for x in [1.0f32, 0.0] {
            to.extend_from_slice(&x.to_le_bytes());
        }
        to.push(1);
        to.extend_from_slice(&2.0f32.to_le_bytes());
        assert_eq!(
            decode(&pk(8, 0, &to)),
            Some(Command::Hl(HlCommand::Takeoff { group: 0, height: 1.0, duration: 2.0 }))
        );
        assert_eq!(decode(&pk(9, 1, &[3])), Some(Command::EmergencyStop));
        assert_eq!(
            decode(&pk(7, 1, &[0, 100, 0, 0, 0])),
            Some(Command::NotifySetpointsStop { remain_ms: 100 })
        );
        let mut rpyt = vec![0u8; 12];
        rpyt.extend_from_slice(&0u16.to_le_bytes());
        assert_eq!(decode(&pk(3, 0, &rpyt)), Some(Command::Setpoint(Setpoint::Stop)));
    }

    #[test]
    fn garbage_is_ignored() {
        for port in 0..16 {
            for ch in 0..4 {
                for len in 0..31 {
                    let d: Vec<u8> = (0..len).map(|i| (i * 37 + port * 11 + ch) as u8).collect();
                    let _ = decode(&pk(port as u8, ch as u8, &d));
                }
            }
        }
        assert_eq!(decode(&pk(7, 0, &floats(7, &[f32::NAN, 0.0, 0.0, 0.0]))), None);
        assert_eq!(decode(&pk(7, 0, &floats(7, &[1.0, 0.0, 0.0]))), None);
        assert_eq!(decode(&pk(6, 0, &[0; 11])), None);
        assert_eq!(decode(&pk(8, 0, &[])), None);
    }
}
