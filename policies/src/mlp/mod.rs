//! A multilayer perceptron taken out of an ONNX model (`extract`) and evaluated by the policies' own
//! kernel (`kernel`): weights packed once at load, the batch cut into blocks of [`BLOCK_ROWS`] rows
//! that go through every layer while their activations stay in cache, the blocks spread over the
//! caller's rayon pool. No allocation per call once each thread's scratch has its working size.

mod extract;
mod kernel;

use crate::Observation;
use rayon::prelude::*;
use std::cell::RefCell;

/// Rows of a block: its two activation buffers (`BLOCK_ROWS × 128` f32, 24 KiB each for the
/// shipped model) stay in L1/L2 while the block goes through every layer.
pub const BLOCK_ROWS: usize = 48;

/// Batches at least this large spread their blocks over the caller's rayon pool (smaller ones cost
/// less on the caller's thread than the hand-over).
pub const PARALLEL_ROWS: usize = 256;

/// Columns of every packed layer are padded to a multiple of this (the widest SIMD vector, 16 f32).
const PAD: usize = 16;

/// An operation on each column of a layer's output, with one constant per column (padded to the
/// layer's width; a scalar constant repeated).
#[derive(Debug, Clone, PartialEq)]
enum ColumnOp {
    /// `x + c_j` (a bias).
    Add(Vec<f32>),
    /// `x · c_j`.
    Mul(Vec<f32>),
    /// `max(x, c_j)` (the lower side of a clip); NaN stays NaN.
    Max(Vec<f32>),
    /// `min(x, c_j)` (the upper side of a clip); NaN stays NaN.
    Min(Vec<f32>),
    /// tanh, as tract computes it.
    Tanh,
}

impl ColumnOp {
    /// The operation on the number `x` of column `j`.
    fn apply_scalar(&self, j: usize, x: f32) -> f32 {
        match self {
            Self::Add(c) => x + c[j],
            Self::Mul(c) => x * c[j],
            Self::Max(c) if !x.is_nan() => x.max(c[j]),
            Self::Min(c) if !x.is_nan() => x.min(c[j]),
            Self::Max(_) | Self::Min(_) => x,
            Self::Tanh => kernel::tanh_scalar(x),
        }
    }
}

/// A fully connected layer, `x ↦ ops(x · W)`.
#[derive(Debug, Clone, PartialEq)]
struct Dense {
    /// Inputs (rows of `W`).
    inputs: usize,
    /// Outputs padded to a multiple of [`PAD`] (the padding columns hold zero weights).
    width: usize,
    /// `W` row-major, `inputs × width`.
    weights: Vec<f32>,
    /// The column operations that follow the product, in order.
    epilogue: Vec<ColumnOp>,
}

/// The net: column operations on the observations, then the layers.
#[derive(Debug, Clone)]
pub struct Mlp {
    /// Observation size.
    inputs: usize,
    /// Output size (the last layer's true width).
    outputs: usize,
    /// Column operations on the observations before the first layer (unpadded).
    input_ops: Vec<ColumnOp>,
    /// The layers, in order (at least one).
    layers: Vec<Dense>,
    /// The widest row of activations (input or layer), for the scratch buffers.
    max_width: usize,
    /// The SIMD instruction set found on this CPU.
    arch: pulp::Arch,
}

thread_local! {
    /// Each thread's activation buffers, kept between calls (they grow to the widest net once).
    static SCRATCH: RefCell<Vec<f32>> = const { RefCell::new(Vec::new()) };
}

impl Mlp {
    /// Output size per observation.
    pub fn outputs(&self) -> usize {
        self.outputs
    }

    /// Multiply-adds per observation (the products only; column operations not counted).
    pub fn macs_per_row(&self) -> usize {
        let mut k = self.inputs;
        let mut macs = 0;
        for (i, layer) in self.layers.iter().enumerate() {
            let n = if i + 1 == self.layers.len() { self.outputs } else { layer.width };
            macs += k * n;
            k = n;
        }
        macs
    }

    /// Evaluates the net on every observation into `outputs` (resized to `outputs() × batch`).
    /// Blocks are spread over the current rayon pool when the batch has [`PARALLEL_ROWS`] rows
    /// or more; each row's outputs are the same bits on any number of threads.
    pub fn forward(&self, observations: &[Observation], outputs: &mut Vec<f32>) {
        outputs.resize(observations.len() * self.outputs, 0.0);
        let blocks = observations.chunks(BLOCK_ROWS).zip(outputs.chunks_mut(BLOCK_ROWS * self.outputs));
        if observations.len() >= PARALLEL_ROWS && rayon::current_num_threads() > 1 {
            observations
                .par_chunks(BLOCK_ROWS)
                .zip(outputs.par_chunks_mut(BLOCK_ROWS * self.outputs))
                .for_each(|(obs, out)| self.forward_block(obs, out));
        } else {
            blocks.for_each(|(obs, out)| self.forward_block(obs, out));
        }
    }

    /// One block of at most [`BLOCK_ROWS`] rows, in the calling thread's scratch.
    fn forward_block(&self, observations: &[Observation], outputs: &mut [f32]) {
        let need = 2 * BLOCK_ROWS * self.max_width;
        SCRATCH.with_borrow_mut(|scratch| {
            if scratch.len() < need {
                scratch.resize(need, 0.0);
            }
            let scratch = &mut scratch[..2 * observations.len() * self.max_width];
            self.arch.dispatch(kernel::ForwardBlock { mlp: self, observations, outputs, scratch });
        });
    }
}
