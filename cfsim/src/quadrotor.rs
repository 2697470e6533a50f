//! A rigid-body model of the Crazyflie 2.1 for the real firmware to fly: position, velocity,
//! attitude quaternion, body rates and four rotors with first-order motor lag, driven by the
//! firmware's motor PWM, resting on a floor at z = 0.
//!
//! Frames: the world frame has z up; the body frame has x forward, y left, z up, as the
//! firmware's. The attitude quaternion `[w, x, y, z]` rotates body vectors into the world frame.
//! Motors are numbered as on the Crazyflie: M1 front right, M2 back right, M3 back left, M4 front
//! left; M1 and M3 turn counter-clockwise seen from above, M2 and M4 clockwise.
//!
//! The figures ([`QuadParams::CRAZYFLIE_2_1`]) are those of CrazySim's Gazebo model of the
//! Crazyflie 2.1, whose inertia is J. Förster's identification of the Crazyflie 2.0 ("System
//! Identification of the Crazyflie 2.0 Nano Quadrocopter", ETH Zürich, 2015).

mod sensors;
#[cfg(test)]
mod tests;

pub use sensors::{BaroSample, ImuNoise, ImuSample, accel_to_raw, gyro_to_raw, pressure_at_altitude};

use crate::dynamics::G;

/// Longest integration sub-step (s): a 1 ms step is integrated in sub-steps of at most this.
pub const MAX_SUBSTEP: f64 = 0.25e-3;

/// Physical parameters of a quadrotor.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct QuadParams {
    /// Total mass (kg).
    pub mass: f64,
    /// Principal moments of inertia about body x, y and z (kg·m²).
    pub inertia: [f64; 3],
    /// Rotor hub positions `[x, y]` in the body frame (m), M1..M4.
    pub rotor_position: [[f64; 2]; 4],
    /// Spin direction of each rotor seen from above: +1 counter-clockwise, -1 clockwise.
    pub rotor_direction: [f64; 4],
    /// Thrust coefficient k_f (N·s²/rad²): a rotor's thrust is k_f ω².
    pub thrust_coefficient: f64,
    /// Moment constant k_m (m): a rotor's drag torque about its axis is k_m × its thrust.
    pub moment_constant: f64,
    /// Rotor drag k_d (N·s²/(m·rad)): the body-horizontal force is −k_d (Σω) v_body.
    pub rotor_drag: f64,
    /// Motor time constant while speeding up (s).
    pub motor_tau_up: f64,
    /// Motor time constant while slowing down (s).
    pub motor_tau_down: f64,
    /// Slope of the commanded rotor speed (rad/s per PWM unit of 0..65535).
    pub pwm_slope: f64,
    /// Commanded rotor speed at zero PWM once the motor spins (rad/s).
    pub pwm_offset: f64,
    /// PWM below which a motor does not spin (PWM units of 0..65535).
    pub pwm_min: u16,
    /// Largest rotor speed (rad/s).
    pub max_rotor_speed: f64,
    /// Gravitational acceleration (m/s²).
    pub gravity: f64,
}

impl QuadParams {
    /// The Crazyflie 2.1 of CrazySim's Gazebo model (see the module documentation).
    pub const CRAZYFLIE_2_1: Self = Self {
        // 25 g body and four 0.8 g rotors.
        mass: 0.025 + 4.0 * 0.0008,
        inertia: [1.6572e-5, 1.6656e-5, 2.9262e-5],
        rotor_position: [[0.031, -0.031], [-0.031, -0.031], [-0.031, 0.031], [0.031, 0.031]],
        rotor_direction: [1.0, -1.0, 1.0, -1.0],
        thrust_coefficient: 1.7965e-8,
        moment_constant: 0.005964552,
        rotor_drag: 9.1785e-7,
        motor_tau_up: 0.0125,
        motor_tau_down: 0.025,
        pwm_slope: 0.04076521,
        pwm_offset: 380.8359,
        pwm_min: 1000,
        max_rotor_speed: 3052.0,
        gravity: G,
    };

    /// The rotor speed (rad/s) a motor settles at under `pwm`.
    pub fn rotor_speed_command(&self, pwm: u16) -> f64 {
        if pwm < self.pwm_min {
            return 0.0;
        }
        (self.pwm_slope * f64::from(pwm) + self.pwm_offset).min(self.max_rotor_speed)
    }

    /// The PWM (0..65535, fractional) at which four equal rotors carry the weight.
    pub fn hover_pwm(&self) -> f64 {
        let speed = (self.mass * self.gravity / (4.0 * self.thrust_coefficient)).sqrt();
        (speed - self.pwm_offset) / self.pwm_slope
    }
}

impl Default for QuadParams {
    fn default() -> Self {
        Self::CRAZYFLIE_2_1
    }
}

/// The state of the rigid body and its rotors.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct QuadState {
    /// Position in the world frame (m).
    pub position: [f64; 3],
    /// Velocity in the world frame (m/s).
    pub velocity: [f64; 3],
    /// Attitude `[w, x, y, z]`, body to world, unit norm.
    pub attitude: [f64; 4],
    /// Angular velocity in the body frame (rad/s).
    pub body_rates: [f64; 3],
    /// Rotor speeds M1..M4 (rad/s).
    pub rotor_speeds: [f64; 4],
    /// Resting on the floor (held there by it).
    pub on_floor: bool,
}

impl QuadState {
    /// At rest and level at `position`; on the floor if `position[2] <= 0`.
    pub fn at_rest(position: [f64; 3]) -> Self {
        let on_floor = position[2] <= 0.0;
        let position = [position[0], position[1], position[2].max(0.0)];
        Self {
            position,
            velocity: [0.0; 3],
            attitude: [1.0, 0.0, 0.0, 0.0],
            body_rates: [0.0; 3],
            rotor_speeds: [0.0; 4],
            on_floor,
        }
    }

    /// Roll, pitch and yaw (rad, Z-Y-X Euler angles) of the attitude.
    pub fn euler(&self) -> [f64; 3] {
        let [w, x, y, z] = self.attitude;
        let roll = (2.0 * (w * x + y * z)).atan2(1.0 - 2.0 * (x * x + y * y));
        let pitch = (2.0 * (w * y - z * x)).clamp(-1.0, 1.0).asin();
        let yaw = (2.0 * (w * z + x * y)).atan2(1.0 - 2.0 * (y * y + z * z));
        [roll, pitch, yaw]
    }
}

/// What the simulator knows for sure about one drone at one instant.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GroundTruth {
    /// Simulated time since the model was made (s).
    pub time: f64,
    /// Position in the world frame (m).
    pub position: [f64; 3],
    /// Velocity in the world frame (m/s).
    pub velocity: [f64; 3],
    /// Attitude `[w, x, y, z]`, body to world.
    pub attitude: [f64; 4],
    /// Roll, pitch and yaw (rad).
    pub euler: [f64; 3],
    /// Angular velocity in the body frame (rad/s).
    pub body_rates: [f64; 3],
    /// Rotor speeds M1..M4 (rad/s).
    pub rotor_speeds: [f64; 4],
    /// The motor PWM the model is driven by, M1..M4.
    pub pwm: [u16; 4],
    /// Resting on the floor.
    pub on_floor: bool,
}

/// One simulated quadrotor: parameters, state, inputs and the last step's specific force.
#[derive(Debug, Clone)]
pub struct Quadrotor {
    /// Physical parameters.
    pub params: QuadParams,
    /// Current state.
    pub state: QuadState,
    /// External force in the world frame (N), e.g. a wind gust; zero unless the caller sets it.
    pub external_force: [f64; 3],
    pwm: [u16; 4],
    specific_force: [f64; 3],
    time: f64,
}

impl Quadrotor {
    /// A quadrotor at rest and level at `position` with its motors off.
    pub fn new(params: QuadParams, position: [f64; 3]) -> Self {
        let state = QuadState::at_rest(position);
        // At rest the accelerometer feels the floor (or whatever holds it) push up by 1 g.
        let specific_force = [0.0, 0.0, params.gravity];
        Self { params, state, external_force: [0.0; 3], pwm: [0; 4], specific_force, time: 0.0 }
    }

    /// Set the motor PWM (0..65535 each, M1..M4), held until the next call.
    pub fn set_pwm(&mut self, pwm: [u16; 4]) {
        self.pwm = pwm;
    }

    /// The motor PWM in force.
    pub fn pwm(&self) -> [u16; 4] {
        self.pwm
    }

    /// Simulated time since the model was made (s).
    pub fn time(&self) -> f64 {
        self.time
    }

    /// Body-frame specific force (m/s²) of the last step: what an ideal accelerometer reads.
    pub fn specific_force(&self) -> [f64; 3] {
        self.specific_force
    }

    /// Advance by `dt` seconds, in equal sub-steps of at most [`MAX_SUBSTEP`].
    pub fn step(&mut self, dt: f64) {
        if dt.is_nan() || dt <= 0.0 {
            return;
        }
        let n = (dt / MAX_SUBSTEP).ceil().max(1.0);
        let h = dt / n;
        for _ in 0..n as u32 {
            self.substep(h);
        }
        self.time += dt;
    }

    /// The ground truth now.
    pub fn truth(&self) -> GroundTruth {
        let s = &self.state;
        GroundTruth {
            time: self.time,
            position: s.position,
            velocity: s.velocity,
            attitude: s.attitude,
            euler: s.euler(),
            body_rates: s.body_rates,
            rotor_speeds: s.rotor_speeds,
            pwm: self.pwm,
            on_floor: s.on_floor,
        }
    }

    fn substep(&mut self, h: f64) {
        let p = self.params;
        let s = &mut self.state;
        // Motors: first-order lag towards the commanded speed, integrated exactly over `h`.
        for (speed, &pwm) in s.rotor_speeds.iter_mut().zip(&self.pwm) {
            let command = p.rotor_speed_command(pwm);
            let tau = if command > *speed { p.motor_tau_up } else { p.motor_tau_down };
            *speed += (command - *speed) * (1.0 - (-h / tau).exp());
        }
        let mut thrust = 0.0;
        let mut torque = [0.0; 3];
        for i in 0..4 {
            let f = p.thrust_coefficient * s.rotor_speeds[i] * s.rotor_speeds[i];
            let [x, y] = p.rotor_position[i];
            thrust += f;
            torque[0] += y * f;
            torque[1] -= x * f;
            // A rotor turning counter-clockwise drags the body clockwise.
            torque[2] -= p.rotor_direction[i] * p.moment_constant * f;
        }
        // Rotor drag opposes the body-horizontal velocity, growing with the rotor speeds.
        let v_body = rotate_inverse(s.attitude, s.velocity);
        let drag = p.rotor_drag * s.rotor_speeds.iter().sum::<f64>();
        let force_body = [-drag * v_body[0], -drag * v_body[1], thrust];
        let force_world = rotate(s.attitude, force_body);
        let mut accel = [0.0; 3];
        for k in 0..3 {
            accel[k] = (force_world[k] + self.external_force[k]) / p.mass;
        }
        accel[2] -= p.gravity;

        if s.position[2] <= 0.0 && accel[2] <= 0.0 {
            rest_on_floor(s);
            accel = [0.0; 3];
        } else {
            s.on_floor = false;
            for ((v, x), a) in s.velocity.iter_mut().zip(&mut s.position).zip(accel) {
                *v += a * h;
                *x += *v * h;
            }
            if s.position[2] < 0.0 {
                // Touch-down: the floor stops the fall; the next sub-step decides whether it rests.
                s.position[2] = 0.0;
                s.velocity[2] = s.velocity[2].max(0.0);
            }
            integrate_rotation(s, torque, p.inertia, h);
        }
        self.specific_force = rotate_inverse(s.attitude, [accel[0], accel[1], accel[2] + p.gravity]);
    }
}

/// Held by the floor: still, level, keeping its heading.
fn rest_on_floor(s: &mut QuadState) {
    let yaw = s.euler()[2];
    s.position[2] = 0.0;
    s.velocity = [0.0; 3];
    s.body_rates = [0.0; 3];
    s.attitude = [(yaw / 2.0).cos(), 0.0, 0.0, (yaw / 2.0).sin()];
    s.on_floor = true;
}

/// Euler's equations for the body rates, then the attitude turned by the new rates over `h`.
fn integrate_rotation(s: &mut QuadState, torque: [f64; 3], inertia: [f64; 3], h: f64) {
    let w = s.body_rates;
    let momentum = [inertia[0] * w[0], inertia[1] * w[1], inertia[2] * w[2]];
    let gyroscopic = cross(w, momentum);
    for k in 0..3 {
        s.body_rates[k] += h * (torque[k] - gyroscopic[k]) / inertia[k];
    }
    let w = s.body_rates;
    let angle = (w[0] * w[0] + w[1] * w[1] + w[2] * w[2]).sqrt() * h;
    if angle > 0.0 {
        // Exact rotation by `angle` about the rate axis, in the body frame (right multiplication).
        let scale = (angle / 2.0).sin() / (angle / h);
        let turn = [(angle / 2.0).cos(), w[0] * scale, w[1] * scale, w[2] * scale];
        s.attitude = normalise(quat_mul(s.attitude, turn));
    }
}

/// `a × b`.
pub(crate) fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}

/// The Hamilton product `a ⊗ b` of quaternions `[w, x, y, z]`.
fn quat_mul(a: [f64; 4], b: [f64; 4]) -> [f64; 4] {
    [
        a[0] * b[0] - a[1] * b[1] - a[2] * b[2] - a[3] * b[3],
        a[0] * b[1] + a[1] * b[0] + a[2] * b[3] - a[3] * b[2],
        a[0] * b[2] - a[1] * b[3] + a[2] * b[0] + a[3] * b[1],
        a[0] * b[3] + a[1] * b[2] - a[2] * b[1] + a[3] * b[0],
    ]
}

/// `q` scaled to unit norm.
fn normalise(q: [f64; 4]) -> [f64; 4] {
    let n = (q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]).sqrt();
    q.map(|c| c / n)
}

/// `v` rotated by the unit quaternion `q` (body to world).
pub(crate) fn rotate(q: [f64; 4], v: [f64; 3]) -> [f64; 3] {
    // v + 2 w (u × v) + 2 u × (u × v), with u the vector part.
    let u = [q[1], q[2], q[3]];
    let t = cross(u, v).map(|c| 2.0 * c);
    let ut = cross(u, t);
    [v[0] + q[0] * t[0] + ut[0], v[1] + q[0] * t[1] + ut[1], v[2] + q[0] * t[2] + ut[2]]
}

/// `v` rotated by the inverse of the unit quaternion `q` (world to body).
pub(crate) fn rotate_inverse(q: [f64; 4], v: [f64; 3]) -> [f64; 3] {
    rotate([q[0], -q[1], -q[2], -q[3]], v)
}
