//! The SIMD kernel of [`Mlp`]: one block of rows through every layer, its activations kept in a
//! per-thread scratch that stays in cache, each product a register-tiled GEMM over the weights
//! packed at load, the layer's column operations (bias, tanh, clip, scale) applied to each tile
//! just stored (in L1).
//!
//! Every output element is `Σ_k a[r][k] · w[k][j]` accumulated by fused multiply-adds from zero in
//! ascending `k` (as tract's kernels do), then the column operations in order: the same bits
//! whatever the tile, the block, the thread or the batch the row is in.

use super::{ColumnOp, Dense, Mlp};
use crate::Observation;
use pulp::{Simd, WithSimd};

/// Rows of a register tile (each row's accumulators are `NR` vectors).
const MR: usize = 6;

/// One block of rows through the whole net: `observations` in, `outputs` (`n_out` per row) out.
pub(super) struct ForwardBlock<'a> {
    /// The net.
    pub mlp: &'a Mlp,
    /// The block's observations.
    pub observations: &'a [Observation],
    /// The block's outputs, row-major.
    pub outputs: &'a mut [f32],
    /// Two activation buffers of `rows × mlp.max_width` each.
    pub scratch: &'a mut [f32],
}

impl WithSimd for ForwardBlock<'_> {
    type Output = ();

    #[inline(always)]
    fn with_simd<S: Simd>(self, simd: S) {
        let Self { mlp, observations, outputs, scratch } = self;
        let rows = observations.len();
        let (mut src, mut dst) = scratch.split_at_mut(rows * mlp.max_width);
        for (r, o) in observations.iter().enumerate() {
            let row = &mut src[r * mlp.inputs..][..mlp.inputs];
            for (j, (x, &o)) in row.iter_mut().zip(o).enumerate() {
                *x = mlp.input_ops.iter().fold(o as f32, |x, op| op.apply_scalar(j, x));
            }
        }
        let mut stride = mlp.inputs;
        for layer in &mlp.layers {
            if S::F32_LANES >= 16 {
                dense::<S, 4>(simd, layer, &src[..rows * stride], stride, dst);
            } else {
                dense::<S, 2>(simd, layer, &src[..rows * stride], stride, dst);
            }
            stride = layer.width;
            std::mem::swap(&mut src, &mut dst);
        }
        for (out, row) in outputs.chunks_exact_mut(mlp.outputs).zip(src.chunks_exact(stride)) {
            out.copy_from_slice(&row[..mlp.outputs]);
        }
    }
}

/// `dst[r][..width] = ops(src[r][..inputs] · W)` for every row of `src` (row stride `stride`).
#[inline(always)]
fn dense<S: Simd, const NR: usize>(simd: S, layer: &Dense, src: &[f32], stride: usize, dst: &mut [f32]) {
    let rows = src.len() / stride;
    let vectors = layer.width / S::F32_LANES;
    let mut r = 0;
    while r + MR <= rows {
        columns::<S, MR, NR>(simd, layer, src, stride, dst, r, vectors);
        r += MR;
    }
    while r < rows {
        columns::<S, 1, NR>(simd, layer, src, stride, dst, r, vectors);
        r += 1;
    }
}

/// Rows `r0..r0 + M` of a layer, all its columns: tiles of `NR` vectors, then single vectors.
#[inline(always)]
fn columns<S: Simd, const M: usize, const NR: usize>(
    simd: S,
    layer: &Dense,
    src: &[f32],
    stride: usize,
    dst: &mut [f32],
    r0: usize,
    vectors: usize,
) {
    let mut v = 0;
    while v + NR <= vectors {
        tile::<S, M, NR>(simd, layer, src, stride, dst, r0, v * S::F32_LANES);
        v += NR;
    }
    while v < vectors {
        tile::<S, M, 1>(simd, layer, src, stride, dst, r0, v * S::F32_LANES);
        v += 1;
    }
}

/// The `M × N` vectors tile of rows `r0..`, columns `col0..`: products, column operations, store.
#[inline(always)]
// Index loops on purpose: a slice copy or iterator borrow of `acc` puts it in memory.
#[allow(clippy::needless_range_loop, clippy::manual_memcpy)]
fn tile<S: Simd, const M: usize, const N: usize>(
    simd: S,
    layer: &Dense,
    src: &[f32],
    stride: usize,
    dst: &mut [f32],
    r0: usize,
    col0: usize,
) {
    let (lanes, k_len, width) = (S::F32_LANES, layer.inputs, layer.width);
    let a: [&[f32]; M] = std::array::from_fn(|i| &src[(r0 + i) * stride..][..k_len]);
    let mut acc = [[simd.splat_f32s(0.0); N]; M];
    // Loops with constant bounds and indices only (no iterator borrows of `acc`), so that the
    // accumulators live in registers.
    for k in 0..k_len {
        let (w, _) = S::as_simd_f32s(&layer.weights[k * width + col0..][..N * lanes]);
        let w: [S::f32s; N] = std::array::from_fn(|j| w[j]);
        for i in 0..M {
            let x = simd.splat_f32s(a[i][k]);
            for j in 0..N {
                acc[i][j] = simd.mul_add_f32s(x, w[j], acc[i][j]);
            }
        }
    }
    for i in 0..M {
        let (out, _) = S::as_mut_simd_f32s(&mut dst[(r0 + i) * width + col0..][..N * lanes]);
        for j in 0..N {
            out[j] = acc[i][j];
        }
    }
    // The column operations on the stored tile (in L1), not on `acc`: their loops index
    // dynamically (tanh is long, they do not unroll), which would keep `acc` in memory and store it
    // at every `k` above. No closures nor function pointers: one not inlined would make each SIMD
    // operation a call.
    macro_rules! each_column {
        ($out:expr, $constants:expr, $op:ident) => {{
            let (c, _) = S::as_simd_f32s(&$constants[col0..][..N * lanes]);
            for (x, &c) in $out.iter_mut().zip(c) {
                *x = $op(simd, *x, c);
            }
        }};
    }
    for i in 0..M {
        let (out, _) = S::as_mut_simd_f32s(&mut dst[(r0 + i) * width + col0..][..N * lanes]);
        for op in &layer.epilogue {
            match op {
                ColumnOp::Tanh => {
                    for x in out.iter_mut() {
                        *x = tanh(simd, *x);
                    }
                }
                ColumnOp::Add(v) => each_column!(out, v, add),
                ColumnOp::Mul(v) => each_column!(out, v, mul),
                ColumnOp::Max(v) => each_column!(out, v, max),
                ColumnOp::Min(v) => each_column!(out, v, min),
            }
        }
    }
}

/// `x + c`.
#[inline(always)]
fn add<S: Simd>(simd: S, x: S::f32s, c: S::f32s) -> S::f32s {
    simd.add_f32s(x, c)
}

/// `x · c`.
#[inline(always)]
fn mul<S: Simd>(simd: S, x: S::f32s, c: S::f32s) -> S::f32s {
    simd.mul_f32s(x, c)
}

/// `max(x, c)`, NaN if `x` is NaN (a NaN observation gives NaN actions, which the caller refuses).
#[inline(always)]
fn max<S: Simd>(simd: S, x: S::f32s, c: S::f32s) -> S::f32s {
    simd.select_f32s(simd.equal_f32s(x, x), simd.max_f32s(x, c), x)
}

/// `min(x, c)`, NaN if `x` is NaN.
#[inline(always)]
fn min<S: Simd>(simd: S, x: S::f32s, c: S::f32s) -> S::f32s {
    simd.select_f32s(simd.equal_f32s(x, x), simd.min_f32s(x, c), x)
}

/// Clamp of [`tanh`]'s input: `1 − tanh(7.5)` is under f32's rounding (see tract's `stanh`).
const TANH_CLAMP: f32 = 7.5;
/// Odd coefficients of the numerator of [`tanh`]'s rational fit, highest first (tract's `stanh`).
#[allow(clippy::excessive_precision)]
const TANH_NUMERATOR: [f32; 7] = [
    -8.488492677e-14,
    5.277853000e-11,
    -2.022500419e-8,
    0.00001115424833,
    0.003103950131,
    0.1308400453,
    0.9999999934,
];
/// Even coefficients of the denominator of [`tanh`]'s rational fit, highest first (tract's `stanh`).
#[allow(clippy::excessive_precision)]
const TANH_DENOMINATOR: [f32; 4] = [0.0002546136580, 0.02449515379, 0.4641733162, 1.0];

/// tanh by tract's `stanh` fit (a rational minimax fit on the input clamped to ±7.5), its two
/// polynomials evaluated by fused multiply-adds: half the operations of `stanh`'s separate
/// multiplies and adds (about a third of the kernel's operations on AVX2, by count). No longer
/// tract's bits: the outputs are checked against tract's within 1e-5. NaN stays NaN.
#[inline(always)]
fn tanh<S: Simd>(simd: S, x: S::f32s) -> S::f32s {
    let (low, high) = (simd.splat_f32s(-TANH_CLAMP), simd.splat_f32s(TANH_CLAMP));
    let c = simd.min_f32s(simd.max_f32s(x, low), high);
    let x2 = simd.mul_f32s(c, c);
    let [a13, a11, a9, a7, a5, a3, a1] = TANH_NUMERATOR;
    let mut p = simd.splat_f32s(a13);
    for a in [a11, a9, a7, a5, a3, a1] {
        p = simd.mul_add_f32s(x2, p, simd.splat_f32s(a));
    }
    let p = simd.mul_f32s(p, c);
    let [b6, b4, b2, b0] = TANH_DENOMINATOR;
    let mut q = simd.splat_f32s(b6);
    for b in [b4, b2, b0] {
        q = simd.mul_add_f32s(x2, q, simd.splat_f32s(b));
    }
    let t = simd.div_f32s(p, q);
    simd.select_f32s(simd.equal_f32s(x, x), t, x)
}

/// [`tanh`] on one number, the same operations (column operations on the input, before the first
/// product).
pub(super) fn tanh_scalar(x: f32) -> f32 {
    let c = x.clamp(-TANH_CLAMP, TANH_CLAMP);
    let x2 = c * c;
    let horner =
        |coefficients: &[f32]| coefficients[1..].iter().fold(coefficients[0], |p, &a| x2.mul_add(p, a));
    horner(&TANH_NUMERATOR) * c / horner(&TANH_DENOMINATOR)
}
