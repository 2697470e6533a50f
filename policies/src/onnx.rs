//! ONNX policies: loaded and checked against the contract by tract (input `[N, 6]` f32
//! observations, output `[N, 2]` f32 accelerations), evaluated in batches by the policies' own MLP
//! kernel ([`Mlp`]) when the model is an MLP, else by tract's optimised plan.

use crate::mlp::Mlp;
use crate::{Observation, Policy, PolicyError};
use std::path::Path;
use std::sync::Arc;
use tract_linalg::multithread::{Executor, multithread_tract_scope};
use tract_onnx::prelude::*;
use tract_onnx::tract_hir::infer::Factoid;
use uav::Vec2;

/// Why an ONNX file was refused.
#[derive(Debug, thiserror::Error)]
pub enum LoadError {
    /// The file could not be read.
    #[error("{path}: cannot read: {source}")]
    Io {
        /// The file.
        path: String,
        /// The I/O error.
        source: std::io::Error,
    },
    /// The bytes are not an ONNX model tract can load and optimise.
    #[error("{path}: not a loadable ONNX model: {reason}")]
    Model {
        /// The file.
        path: String,
        /// tract's explanation.
        reason: String,
    },
    /// The model loads but does not map `[N, 6]` f32 observations to `[N, 2]` f32 accelerations.
    #[error("{path}: breaks the policy contract: {reason}")]
    Contract {
        /// The file.
        path: String,
        /// What differs.
        reason: String,
    },
}

/// Batches at least this large run their matrix products on all of the caller's worker threads
/// (smaller ones cost less on one thread than the hand-over).
pub const PARALLEL_BATCH: usize = 256;

/// A tracking policy from an ONNX file, evaluated on whole batches.
pub struct OnnxPolicy {
    name: String,
    /// The model's MLP, evaluated by the policies' kernel (`None`: the model is not an MLP).
    mlp: Option<Mlp>,
    /// tract's optimised plan's run state, kept between calls (no per-call set-up): the runtime of
    /// a model that is not an MLP, and the reference the MLP kernel is tested against.
    state: TypedSimpleState,
    input: Vec<f32>,
    /// The kernel's outputs, kept between calls.
    outputs: Vec<f32>,
}

impl std::fmt::Debug for OnnxPolicy {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("OnnxPolicy").field("name", &self.name).finish_non_exhaustive()
    }
}

impl OnnxPolicy {
    /// Loads, checks and optimises the model at `path`; `name` labels errors at run time.
    pub fn load(name: &str, path: &Path) -> Result<Self, LoadError> {
        let shown = path.display().to_string();
        let bytes = std::fs::read(path).map_err(|source| LoadError::Io { path: shown.clone(), source })?;
        Self::from_bytes(name, &shown, &bytes)
    }

    /// Loads, checks and optimises a model held in memory; `origin` names it in errors.
    pub fn from_bytes(name: &str, origin: &str, bytes: &[u8]) -> Result<Self, LoadError> {
        let model_err =
            |e: TractError| LoadError::Model { path: origin.to_string(), reason: format!("{e:#}") };
        let contract = |reason: String| LoadError::Contract { path: origin.to_string(), reason };
        let model = tract_onnx::onnx().model_for_read(&mut &bytes[..]).map_err(model_err)?;
        if model.inputs.len() != 1 || model.outputs.len() != 1 {
            let (i, o) = (model.inputs.len(), model.outputs.len());
            return Err(contract(format!("{i} inputs and {o} outputs, expected 1 and 1")));
        }
        let batch = model.sym("N");
        let fact = InferenceFact::dt_shape(f32::datum_type(), tvec![batch.to_dim(), 6.to_dim()]);
        let declared = model.input_fact(0).map_err(model_err)?.clone();
        if declared.unify(&fact).is_err() {
            return Err(contract(format!("input is {declared:?}, expected f32 [N, 6] observations")));
        }
        let decluttered = model
            .with_input_fact(0, fact)
            .and_then(|m| m.into_typed())
            .and_then(|m| m.into_decluttered())
            .map_err(|e| contract(format!("cannot be typed for a [N, 6] f32 input: {e:#}")))?;
        let mlp = Mlp::from_model(&decluttered, 6);
        let typed = decluttered
            .into_optimized()
            .map_err(|e| contract(format!("cannot be optimised for a [N, 6] f32 input: {e:#}")))?;
        let out = typed.output_fact(0).map_err(model_err)?;
        let out_ok = out.datum_type == f32::datum_type()
            && out.rank() == 2
            && out.shape[0] == batch.to_dim()
            && out.shape[1] == 2.to_dim();
        if !out_ok {
            return Err(contract(format!("output is {out:?}, expected f32 [N, 2] accelerations")));
        }
        let plan: Arc<TypedRunnableModel> = typed.into_runnable().map_err(model_err)?;
        let state = plan.spawn().map_err(model_err)?;
        Ok(Self { name: name.to_string(), mlp, state, input: Vec::new(), outputs: Vec::new() })
    }

    /// The model as an MLP run by the policies' kernel, or `None` if tract's plan runs it.
    pub fn mlp(&self) -> Option<&Mlp> {
        self.mlp.as_ref()
    }

    /// Evaluates the network on a batch and returns its raw outputs, `2 × batch` f32 values (the
    /// MLP kernel if the model is an MLP, else tract's plan).
    pub fn infer(&mut self, observations: &[Observation]) -> TractResult<Vec<f32>> {
        let mut raw = Vec::with_capacity(2 * observations.len());
        match &self.mlp {
            Some(mlp) => mlp.forward(observations, &mut raw),
            None => self.run(observations, |out| raw.extend_from_slice(out))?,
        }
        Ok(raw)
    }

    /// Evaluates the network on a batch with tract's optimised plan, whatever the model (the
    /// reference for the MLP kernel), and returns its `2 × batch` outputs.
    pub fn infer_with_tract(&mut self, observations: &[Observation]) -> TractResult<Vec<f32>> {
        let mut raw = Vec::with_capacity(2 * observations.len());
        self.run(observations, |out| raw.extend_from_slice(out))?;
        Ok(raw)
    }

    /// Runs the network on a batch and hands its `2 × batch` outputs to `read` (no copy).
    ///
    /// Batches of [`PARALLEL_BATCH`] observations or more split their matrix products over the
    /// caller's rayon pool (tract's `RayonGlobal` executor: the pool a `ThreadPool::install` set up,
    /// or the global one). tract splits only between output panels, each computed by the same
    /// kernel, so the outputs are the same bits on any number of threads.
    fn run(&mut self, observations: &[Observation], read: impl FnOnce(&[f32])) -> TractResult<()> {
        self.input.clear();
        self.input.extend(observations.iter().flat_map(|o| o.iter().map(|&x| x as f32)));
        let input = Tensor::from_shape(&[observations.len(), 6], &self.input)?;
        let state = &mut self.state;
        let outputs = if observations.len() >= PARALLEL_BATCH {
            multithread_tract_scope(Executor::RayonGlobal, || state.run(tvec![input.into()]))?
        } else {
            state.run(tvec![input.into()])?
        };
        read(outputs[0].try_as_plain_ram()?.as_slice::<f32>()?);
        Ok(())
    }
}

impl Policy for OnnxPolicy {
    fn act(&mut self, observations: &[Observation], actions: &mut Vec<Vec2>) -> Result<(), PolicyError> {
        actions.clear();
        if observations.is_empty() {
            return Ok(());
        }
        let mut to_actions = |raw: &[f32]| {
            actions.extend(raw.chunks_exact(2).map(|u| Vec2::new(f64::from(u[0]), f64::from(u[1]))));
        };
        if let Some(mlp) = &self.mlp {
            mlp.forward(observations, &mut self.outputs);
            to_actions(&self.outputs);
            return Ok(());
        }
        self.run(observations, to_actions)
            .map_err(|e| PolicyError { policy: self.name.clone(), reason: format!("{e:#}") })
    }
}
