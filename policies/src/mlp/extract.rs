//! Recognises an MLP in tract's decluttered model: from the input to the output a single chain of
//! matrix products by constant weights (`EinSum` `mk,nk->mn` or `mk,kn->mn`, what ONNX `Gemm` and
//! `MatMul` become), each followed by any of: the addition of, multiplication by, maximum or minimum
//! with a constant (per column or scalar), and `Tanh`. Anything else is not such an MLP.

use super::{ColumnOp, Dense, Mlp, PAD};
use tract_onnx::prelude::*;
use tract_onnx::tract_core::ops::binary::TypedBinOp;
use tract_onnx::tract_core::ops::einsum::EinSum;
use tract_onnx::tract_core::ops::element_wise::ElementWiseOp;

impl Mlp {
    /// The MLP that `model` (decluttered, one `[N, inputs]` f32 input, one output) computes, or
    /// `None` if it is not a chain of the operations above.
    pub fn from_model(model: &TypedModel, inputs: usize) -> Option<Self> {
        let (&[source], &[sink]) = (model.input_outlets().ok()?, model.output_outlets().ok()?) else {
            return None;
        };
        let mut mlp = Self {
            inputs,
            outputs: inputs,
            input_ops: Vec::new(),
            layers: Vec::new(),
            max_width: inputs,
            arch: pulp::Arch::new(),
        };
        let mut at = source;
        while at != sink {
            let &[next] = model.outlet_successors(at) else { return None };
            let node = &model.nodes[next.node];
            if node.outputs.len() != 1 || node.inputs.iter().filter(|&&i| i == at).count() != 1 {
                return None;
            }
            let constants: Vec<Arc<Tensor>> = node
                .inputs
                .iter()
                .filter(|&&i| i != at)
                .map(|&i| model.outlet_fact(i).ok().and_then(|f| f.konst.clone()))
                .collect::<Option<_>>()?;
            mlp.push(node, next.slot, &constants)?;
            at = OutletId::new(node.id, 0);
        }
        let fact = model.outlet_fact(sink).ok()?;
        let width_ok = fact.shape.last().is_some_and(|n| *n == mlp.outputs.to_dim());
        (fact.datum_type == f32::datum_type() && width_ok && !mlp.layers.is_empty()).then_some(mlp)
    }

    /// Appends the operation of `node` (the chain enters at input `slot`; `constants` are its
    /// other inputs), or `None` if it has no place in an MLP.
    fn push(&mut self, node: &TypedNode, slot: usize, constants: &[Arc<Tensor>]) -> Option<()> {
        let [constant] = constants else {
            let element_wise = node.op_as::<ElementWiseOp>()?;
            (constants.is_empty() && element_wise.0.name() == "Tanh").then_some(())?;
            return self.push_column_op(ColumnOp::Tanh);
        };
        if let Some(einsum) = node.op_as::<EinSum>() {
            (slot == 0 && einsum.operating_dt == f32::datum_type() && einsum.q_params.is_none())
                .then_some(())?;
            let (ins, outs) = einsum.axes.to_strs();
            let [a, w] = [ins.first()?, ins.get(1)?].map(|s| s.chars().collect::<Vec<_>>());
            let o: Vec<char> = outs.first()?.chars().collect();
            let &[m, k] = a.as_slice() else { return None };
            let &[om, n] = o.as_slice() else { return None };
            let transposed = if w == [n, k] {
                true
            } else if w == [k, n] {
                false
            } else {
                return None;
            };
            (om == m && m != k && n != k && n != m && ins.len() == 2).then_some(())?;
            return self.push_dense(constant, transposed);
        }
        let op = node.op_as::<TypedBinOp>()?;
        let columns = self.columns_padded(constant)?;
        let op = match op.0.name() {
            "Add" => ColumnOp::Add(columns),
            "Mul" => ColumnOp::Mul(columns),
            "Max" => ColumnOp::Max(columns),
            "Min" => ColumnOp::Min(columns),
            _ => return None,
        };
        self.push_column_op(op)
    }

    /// Appends a product by `w` (`[n, k]` if `transposed`, else `[k, n]`), packed `k × width`.
    fn push_dense(&mut self, w: &Tensor, transposed: bool) -> Option<()> {
        let values = f32_values(w)?;
        let &[rows, cols] = w.shape() else { return None };
        let (k, n) = if transposed { (cols, rows) } else { (rows, cols) };
        if k != self.outputs || n == 0 {
            return None;
        }
        let width = n.div_ceil(PAD) * PAD;
        let mut weights = vec![0.0; k * width];
        for (i, row) in weights.chunks_exact_mut(width).enumerate() {
            for (j, w) in row[..n].iter_mut().enumerate() {
                *w = if transposed { values[j * k + i] } else { values[i * n + j] };
            }
        }
        self.layers.push(Dense { inputs: k, width, weights, epilogue: Vec::new() });
        self.outputs = n;
        self.max_width = self.max_width.max(width);
        Some(())
    }

    /// Appends a column operation to the last layer (or to the observations before the first).
    fn push_column_op(&mut self, op: ColumnOp) -> Option<()> {
        match self.layers.last_mut() {
            Some(layer) => layer.epilogue.push(op),
            None => self.input_ops.push(op),
        }
        Some(())
    }

    /// The constant of a column operation on the current `outputs` columns: one value per column or
    /// a single one, of a shape that does not broadcast the batch (`[]`, `[n]`, `[1, n]`, `[1, 1]`);
    /// padded with zeros to the current layer's width.
    fn columns_padded(&self, constant: &Tensor) -> Option<Vec<f32>> {
        let shape = constant.shape();
        let n = self.outputs;
        let per_column = shape.last().is_some_and(|&last| last == n);
        let fits = shape.len() <= 2 && shape.iter().rev().skip(1).all(|&d| d == 1);
        let values = f32_values(constant)?;
        if !fits || !(values.len() == 1 || per_column) {
            return None;
        }
        let width = self.layers.last().map_or(n, |l| l.width);
        let mut columns: Vec<f32> = (0..n).map(|j| values[if values.len() == 1 { 0 } else { j }]).collect();
        columns.resize(width, 0.0);
        Some(columns)
    }
}

/// The values of an f32 tensor (`None` for another type).
fn f32_values(t: &Tensor) -> Option<Vec<f32>> {
    if t.datum_type() != f32::datum_type() {
        return None;
    }
    Some(t.try_as_plain_ram().ok()?.as_slice::<f32>().ok()?.to_vec())
}
