//! The datagrams between the physics and the SITL firmware: one CRTP packet per datagram, the
//! header byte `(port << 4) | channel` then the payload, values little-endian.

use crate::crtp::{PORT_LOCALIZATION, u16_at};
use crate::quadrotor::{BaroSample, ImuSample};

/// The firmware's hello, repeated until the physics answers with the same byte; the physics also
/// accepts it from a client (CrazySim's "connect").
pub const HELLO: u8 = 0xf3;
/// A client's goodbye (CrazySim's "close"): forget the client.
pub const CLIENT_CLOSE: u8 = 0xf4;
/// A null packet (port 15, channel 3, no payload), sent by clients to poll.
pub const NULL_PACKET: u8 = 0xff;
/// The CRTP port of sensor and motor packets in the protocol-12 SITL firmware.
pub const SIM_PORT: u8 = 10;
/// The CRTP port of generic setpoints (the client's full-state setpoints among them).
pub const SETPOINT_PORT: u8 = 7;
/// Header of sensor and motor packets: [`SIM_PORT`], channel 0.
pub const SIM_HEADER: u8 = SIM_PORT << 4;
/// Sensor type of an IMU packet.
pub const SENSOR_IMU: u8 = 0;
/// Sensor type of a barometer packet.
pub const SENSOR_BARO: u8 = 2;
/// Header of an external pose: localization port, channel 1 (generic).
pub const EXT_POSE_HEADER: u8 = (PORT_LOCALIZATION << 4) | 1;
/// Generic localization packet type of an external pose.
pub const EXT_POSE: u8 = 8;
/// Length of a motor datagram: header and four `u16`.
pub const MOTOR_DATAGRAM_LEN: usize = 9;
/// Mask of a header without its two link-layer bits.
const LINK_BITS_CLEARED: u8 = 0xf3;

/// The IMU datagram: `[0xA0, 0, ax, ay, az, gx, gy, gz]` as `i16`.
pub fn imu_datagram(imu: &ImuSample) -> [u8; 14] {
    let mut out = [0; 14];
    out[0] = SIM_HEADER;
    out[1] = SENSOR_IMU;
    for (k, v) in imu.accel.iter().chain(&imu.gyro).enumerate() {
        out[2 + 2 * k..4 + 2 * k].copy_from_slice(&v.to_le_bytes());
    }
    out
}

/// The barometer datagram: `[0xA0, 2, pressure, temperature, altitude]` as `f32`.
pub fn baro_datagram(baro: &BaroSample) -> [u8; 14] {
    let mut out = [0; 14];
    out[0] = SIM_HEADER;
    out[1] = SENSOR_BARO;
    for (k, v) in [baro.pressure, baro.temperature, baro.altitude].iter().enumerate() {
        out[2 + 4 * k..6 + 4 * k].copy_from_slice(&v.to_le_bytes());
    }
    out
}

/// The external pose datagram: `[0x61, 8, x, y, z, qx, qy, qz, qw]` as `f32`, from a position
/// (m) and an attitude `[w, x, y, z]`.
pub fn pose_datagram(position: [f64; 3], attitude: [f64; 4]) -> [u8; 30] {
    let [w, x, y, z] = attitude;
    let values = [position[0], position[1], position[2], x, y, z, w];
    let mut out = [0; 30];
    out[0] = EXT_POSE_HEADER;
    out[1] = EXT_POSE;
    for (k, v) in values.iter().enumerate() {
        out[2 + 4 * k..6 + 4 * k].copy_from_slice(&(*v as f32).to_le_bytes());
    }
    out
}

/// The four motor PWM values of a motor datagram, or `None` if `datagram` is not one.
pub fn motor_pwm(datagram: &[u8]) -> Option<[u16; 4]> {
    let (&header, payload) = datagram.split_first()?;
    if datagram.len() != MOTOR_DATAGRAM_LEN || header & LINK_BITS_CLEARED != SIM_HEADER {
        return None;
    }
    Some([u16_at(payload, 0)?, u16_at(payload, 2)?, u16_at(payload, 4)?, u16_at(payload, 6)?])
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::crtp::{Packet, f32s_at, i16_at};

    #[test]
    fn imu_layout() {
        let d = imu_datagram(&ImuSample { accel: [1, -2, 2048], gyro: [-300, 4, i16::MIN] });
        let p = Packet::parse(&d).expect("non-empty");
        assert_eq!((p.port, p.channel, p.data[0]), (SIM_PORT, 0, SENSOR_IMU));
        let values: Vec<i16> = (0..6).filter_map(|k| i16_at(&p.data, 1 + 2 * k)).collect();
        assert_eq!(values, [1, -2, 2048, -300, 4, i16::MIN]);
    }

    #[test]
    fn baro_and_pose_layout() {
        let d = baro_datagram(&BaroSample { pressure: 1013.25, temperature: 15.0, altitude: 0.5 });
        assert_eq!(&d[..2], &[0xa0, 2]);
        assert_eq!(f32s_at::<3>(&d, 2), Some([1013.25, 15.0, 0.5]));
        let d = pose_datagram([1.0, -2.0, 0.5], [0.5, 0.1, 0.2, 0.3]);
        assert_eq!(&d[..2], &[0x61, 8]);
        assert_eq!(f32s_at::<7>(&d, 2), Some([1.0, -2.0, 0.5, 0.1, 0.2, 0.3, 0.5]));
    }

    #[test]
    fn motor_packets_are_recognised_and_others_are_not() {
        let mut d = vec![0xa0];
        for v in [1000u16, 2, 65535, 40000] {
            d.extend_from_slice(&v.to_le_bytes());
        }
        assert_eq!(motor_pwm(&d), Some([1000, 2, 65535, 40000]));
        d[0] = 0xac; // link bits set
        assert_eq!(motor_pwm(&d), Some([1000, 2, 65535, 40000]));
        d[0] = 0xa1; // another channel
        assert_eq!(motor_pwm(&d), None);
        assert_eq!(motor_pwm(&d[..8]), None);
        assert_eq!(motor_pwm(&[0xa0, 1]), None);
        assert_eq!(motor_pwm(&[]), None);
    }
}
