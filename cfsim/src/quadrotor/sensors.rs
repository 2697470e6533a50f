//! The sensor readings the firmware is fed: the IMU in its raw units, the barometer, and optional
//! IMU noise from a seeded PRNG.

use super::Quadrotor;
use crate::faults::Prng;

/// Accelerometer resolution: 32/65536 g per LSB (±16 g full scale), so 1 g reads 2048.
pub const ACCEL_G_PER_LSB: f64 = 32.0 / 65536.0;
/// Gyro resolution: 4000/65536 °/s per LSB (±2000 °/s full scale).
pub const GYRO_DEG_PER_LSB: f64 = 4000.0 / 65536.0;
/// Sea-level standard pressure (mbar); the floor is at sea level.
pub const SEA_LEVEL_PRESSURE: f64 = 1013.25;
/// Sea-level standard temperature (°C).
pub const SEA_LEVEL_TEMPERATURE: f64 = 15.0;

/// One IMU sample in the firmware's raw units.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ImuSample {
    /// Body-frame specific force, [`ACCEL_G_PER_LSB`] per unit.
    pub accel: [i16; 3],
    /// Body rates, [`GYRO_DEG_PER_LSB`] per unit.
    pub gyro: [i16; 3],
}

/// One barometer sample.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BaroSample {
    /// Static pressure (mbar).
    pub pressure: f32,
    /// Air temperature (°C).
    pub temperature: f32,
    /// Altitude above sea level (m).
    pub altitude: f32,
}

/// White Gaussian IMU noise from a seeded PRNG.
#[derive(Debug, Clone)]
pub struct ImuNoise {
    /// Standard deviation of each accelerometer axis (m/s²).
    pub accel_std: f64,
    /// Standard deviation of each gyro axis (rad/s).
    pub gyro_std: f64,
    rng: Prng,
}

impl ImuNoise {
    /// About a BMI088's datasheet noise densities (175 µg/√Hz, 0.014 °/s/√Hz) over a 500 Hz
    /// bandwidth.
    pub fn bmi088(seed: u64) -> Self {
        Self::new(0.04, 0.005, seed)
    }

    /// Noise of the given standard deviations (m/s², rad/s) drawn from a PRNG seeded with `seed`.
    pub fn new(accel_std: f64, gyro_std: f64, seed: u64) -> Self {
        Self { accel_std, gyro_std, rng: Prng::new(seed) }
    }

    /// A standard normal sample (Box–Muller).
    fn gaussian(&mut self) -> f64 {
        // 1 - [0, 1) is in (0, 1]: the logarithm is finite.
        let u = 1.0 - self.rng.next_f64();
        let v = self.rng.next_f64();
        (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos()
    }
}

/// Specific force (m/s²) in raw accelerometer units, saturating at the full scale.
pub fn accel_to_raw(specific_force: f64, gravity: f64) -> i16 {
    saturate(specific_force / (gravity * ACCEL_G_PER_LSB))
}

/// Angular rate (rad/s) in raw gyro units, saturating at the full scale.
pub fn gyro_to_raw(rate: f64) -> i16 {
    saturate(rate.to_degrees() / GYRO_DEG_PER_LSB)
}

fn saturate(x: f64) -> i16 {
    // `as` saturates at the bounds and maps NaN to 0.
    x.round() as i16
}

/// Pressure (mbar) of the International Standard Atmosphere at `altitude` metres.
pub fn pressure_at_altitude(altitude: f64) -> f64 {
    SEA_LEVEL_PRESSURE * (1.0 - 2.25577e-5 * altitude).powf(5.25588)
}

impl Quadrotor {
    /// The IMU now: specific force and body rates in raw units, with `noise` if given.
    pub fn imu(&self, noise: Option<&mut ImuNoise>) -> ImuSample {
        let mut accel = self.specific_force();
        let mut gyro = self.state.body_rates;
        if let Some(noise) = noise {
            for k in 0..3 {
                accel[k] += noise.accel_std * noise.gaussian();
                gyro[k] += noise.gyro_std * noise.gaussian();
            }
        }
        let g = self.params.gravity;
        ImuSample { accel: accel.map(|a| accel_to_raw(a, g)), gyro: gyro.map(gyro_to_raw) }
    }

    /// The barometer now (standard atmosphere, the floor at sea level).
    pub fn barometer(&self) -> BaroSample {
        let altitude = self.state.position[2];
        BaroSample {
            pressure: pressure_at_altitude(altitude) as f32,
            // The standard lapse rate: 6.5 °C per km.
            temperature: (SEA_LEVEL_TEMPERATURE - 0.0065 * altitude) as f32,
            altitude: altitude as f32,
        }
    }
}
