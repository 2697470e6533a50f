//! What the log port can log: the variables of the log TOC, their types, and the value each one
//! reads from the simulated vehicle.

use crate::dynamics::G;
use crate::estimator::Estimator;
use crate::flight::Flight;
use crate::supervisor::Supervisor;

/// Log type codes (low nibble of the type byte).
pub(crate) const UINT8: u8 = 1;
pub(crate) const UINT16: u8 = 2;
pub(crate) const UINT32: u8 = 3;
pub(crate) const INT8: u8 = 4;
pub(crate) const INT16: u8 = 5;
pub(crate) const INT32: u8 = 6;
pub(crate) const FLOAT: u8 = 7;
pub(crate) const FP16: u8 = 8;

/// Bytes of a log type, `None` for an unknown code.
pub(crate) fn type_len(t: u8) -> Option<usize> {
    match t {
        UINT8 | INT8 => Some(1),
        UINT16 | INT16 | FP16 => Some(2),
        UINT32 | INT32 | FLOAT => Some(4),
        _ => None,
    }
}

/// A loggable quantity of the simulated Crazyflie.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LogVar {
    /// Estimated position x (m).
    X,
    /// Estimated position y (m).
    Y,
    /// Estimated position z (m).
    Z,
    /// Estimated velocity x (m/s).
    Vx,
    /// Estimated velocity y (m/s).
    Vy,
    /// Estimated velocity z (m/s).
    Vz,
    /// Estimated acceleration x (m/s²).
    Ax,
    /// Estimated acceleration y (m/s²).
    Ay,
    /// Estimated acceleration z (m/s²).
    Az,
    /// Roll (deg).
    Roll,
    /// Pitch (deg).
    Pitch,
    /// Yaw (deg).
    Yaw,
    /// Battery voltage (V).
    Vbat,
    /// Power state (0 = on battery).
    PmState,
    /// Supervisor state bitfield.
    SupervisorInfo,
    /// 1 if the system can fly.
    CanFly,
    /// 1 while flying.
    IsFlying,
    /// 1 if tumbled.
    IsTumbled,
    /// Last external position x (m).
    ExtX,
    /// Last external position y (m).
    ExtY,
    /// Last external position z (m).
    ExtZ,
    /// Collective thrust command (PWM units, 0..65535).
    Thrust,
    /// Kalman position variance, axis 0..3 (m²).
    VarPosition(usize),
    /// Kalman (body-frame) velocity variance, axis 0..3 ((m/s)²).
    VarVelocity(usize),
}

/// The log TOC: (group, name, type, quantity). Ids are the positions.
pub(crate) const VARIABLES: &[(&str, &str, u8, LogVar)] = &[
    ("stateEstimate", "x", FLOAT, LogVar::X),
    ("stateEstimate", "y", FLOAT, LogVar::Y),
    ("stateEstimate", "z", FLOAT, LogVar::Z),
    ("stateEstimate", "vx", FLOAT, LogVar::Vx),
    ("stateEstimate", "vy", FLOAT, LogVar::Vy),
    ("stateEstimate", "vz", FLOAT, LogVar::Vz),
    ("stateEstimate", "ax", FLOAT, LogVar::Ax),
    ("stateEstimate", "ay", FLOAT, LogVar::Ay),
    ("stateEstimate", "az", FLOAT, LogVar::Az),
    ("stateEstimate", "roll", FLOAT, LogVar::Roll),
    ("stateEstimate", "pitch", FLOAT, LogVar::Pitch),
    ("stateEstimate", "yaw", FLOAT, LogVar::Yaw),
    ("pm", "vbat", FLOAT, LogVar::Vbat),
    ("pm", "state", INT8, LogVar::PmState),
    ("supervisor", "info", UINT16, LogVar::SupervisorInfo),
    ("sys", "canfly", UINT8, LogVar::CanFly),
    ("sys", "isFlying", UINT8, LogVar::IsFlying),
    ("sys", "isTumbled", UINT8, LogVar::IsTumbled),
    ("ext_pos", "X", FLOAT, LogVar::ExtX),
    ("ext_pos", "Y", FLOAT, LogVar::ExtY),
    ("ext_pos", "Z", FLOAT, LogVar::ExtZ),
    ("stabilizer", "thrust", FLOAT, LogVar::Thrust),
    ("kalman", "varX", FLOAT, LogVar::VarPosition(0)),
    ("kalman", "varY", FLOAT, LogVar::VarPosition(1)),
    ("kalman", "varZ", FLOAT, LogVar::VarPosition(2)),
    ("kalman", "varPX", FLOAT, LogVar::VarVelocity(0)),
    ("kalman", "varPY", FLOAT, LogVar::VarVelocity(1)),
    ("kalman", "varPZ", FLOAT, LogVar::VarVelocity(2)),
];

/// What the log variables read: the vehicle's parts at one instant.
#[derive(Debug, Clone, Copy)]
pub struct Sources<'a> {
    /// Flight control and dynamics.
    pub flight: &'a Flight,
    /// The supervisor.
    pub supervisor: &'a Supervisor,
    /// The estimator's covariance.
    pub estimator: &'a Estimator,
    /// The high-level commander's supervisor bits.
    pub hl_bits: u16,
}

impl Sources<'_> {
    /// The supervisor bitfield (`supervisor.info`).
    pub fn supervisor_bits(&self) -> u16 {
        self.supervisor.bits(self.hl_bits)
    }

    /// The current value of `var`.
    pub fn sample(&self, var: LogVar) -> f64 {
        let f = self.flight;
        let b = &f.body;
        let ext = |k: usize| f.external.map_or(0.0, |p| f64::from(p[k]));
        let flag = |x: bool| if x { 1.0 } else { 0.0 };
        let axis = |v: [f64; 3], k: usize| v.get(k).copied().unwrap_or(0.0);
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
            LogVar::SupervisorInfo => f64::from(self.supervisor_bits()),
            LogVar::CanFly => flag(self.supervisor.motors_allowed()),
            LogVar::IsFlying => flag(self.supervisor.state() == crate::supervisor::SupervisorState::Flying),
            LogVar::IsTumbled => 0.0,
            LogVar::ExtX => ext(0),
            LogVar::ExtY => ext(1),
            LogVar::ExtZ => ext(2),
            LogVar::Thrust if f.motors_on => (36000.0 * (1.0 + b.a[2] / G)).clamp(0.0, 65535.0),
            LogVar::Thrust => 0.0,
            LogVar::VarPosition(k) => axis(self.estimator.position_variance(), k),
            LogVar::VarVelocity(k) => axis(self.estimator.velocity_variance(), k),
        }
    }
}
