//! Policy runtime: the observation `[p − p_r, v − v_r, v]` of the paper, the [`Policy`] trait for
//! batched inference (one call per model per tick), the saturated PD baseline, ONNX models run with
//! tract (the shipped RL model is embedded), and a registry that gives any UAV any policy by name.
//!
//! Knows nothing of roads, barriers or fleets: a policy maps observations to nominal accelerations.

mod cost;
mod mlp;
mod onnx;
mod pd;
mod registry;
mod reward;
mod roofline;

pub use cost::flops_per_observation;
pub use mlp::{BLOCK_ROWS, Mlp, PARALLEL_ROWS};
pub use onnx::{LoadError, OnnxPolicy};
pub use pd::PdPolicy;
pub use registry::{PolicyRegistry, UnknownPolicy};
pub use reward::{RewardWeights, tracking_reward};
pub use roofline::{GemmRoofline, HIDDEN, gemm_roofline};
use uav::{UavState, Vec2};

/// Registry name of the shipped RL tracking policy.
pub const SHIPPED_MODEL: &str = "rl";

/// The shipped model (`policies/models/tracker.onnx`, trained by `policies/train`), embedded in the
/// binary so that nothing is read or downloaded at run time.
pub const SHIPPED_MODEL_ONNX: &[u8] = include_bytes!("../models/tracker.onnx");

/// Loads the shipped RL model.
pub fn shipped_model() -> Result<OnnxPolicy, LoadError> {
    OnnxPolicy::from_bytes(SHIPPED_MODEL, "policies/models/tracker.onnx (embedded)", SHIPPED_MODEL_ONNX)
}

/// The observation s = [p − p_r, v − v_r, v] (6 numbers, SI units).
pub type Observation = [f64; 6];

/// Builds the observation of a UAV in `state` tracking target position `p_r` with target velocity `v_r`.
pub fn observation(state: &UavState, p_r: Vec2, v_r: Vec2) -> Observation {
    let (e, ev) = (state.p - p_r, state.v - v_r);
    [e.x, e.y, ev.x, ev.y, state.v.x, state.v.y]
}

/// A policy failed to produce actions for a batch.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("policy {policy}: {reason}")]
pub struct PolicyError {
    /// The policy's name.
    pub policy: String,
    /// What went wrong.
    pub reason: String,
}

/// A tracking policy evaluated on a batch of observations at once.
pub trait Policy: Send {
    /// Computes one nominal acceleration (m/s², not yet saturated) per observation into `actions`
    /// (cleared first). Outputs may be non-finite; the caller checks them.
    fn act(&mut self, observations: &[Observation], actions: &mut Vec<Vec2>) -> Result<(), PolicyError>;
}
