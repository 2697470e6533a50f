//! What one observation costs a model, as tract counts it: the roofline of `airroads bench scale`
//! divides a policy stage's floating-point work by the machine's GEMM rate.

use crate::LoadError;
use tract_onnx::prelude::*;
use tract_onnx::tract_core::ops::Cost;

/// Floating-point operations of one observation through the ONNX model in `bytes` (a multiply-add
/// counts two, a division one): tract's own cost of each node of the decluttered model for a batch
/// of one, its activations' approximations included (tract counts a tanh as 11 multiply-adds and a
/// division). `origin` names the model in errors.
pub fn flops_per_observation(origin: &str, bytes: &[u8]) -> Result<f64, LoadError> {
    let model_err = |e: TractError| LoadError::Model { path: origin.to_string(), reason: format!("{e:#}") };
    let fact = InferenceFact::dt_shape(f32::datum_type(), tvec![1, 6]);
    let model = tract_onnx::onnx()
        .model_for_read(&mut &bytes[..])
        .and_then(|m| m.with_input_fact(0, fact))
        .and_then(|m| m.into_typed())
        .and_then(|m| m.into_decluttered())
        .map_err(model_err)?;
    let mut flops = 0.0;
    for node in model.nodes() {
        let inputs = model.node_input_facts(node.id).map_err(model_err)?;
        for (cost, count) in node.op.cost(&inputs).map_err(model_err)? {
            let weight = match cost {
                Cost::FMA(_) => 2.0,
                Cost::Div(_) => 1.0,
                _ => 0.0,
            };
            let count = count.to_i64().map_err(|e| model_err(e.into()))?;
            flops += weight * count as f64;
        }
    }
    Ok(flops)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The shipped 6→128→128→2 MLP: its three products (6·128 + 128·128 + 128·2 multiply-adds), two
    /// layers of 128 tanh (11 multiply-adds and a division each), the input's and output's scaling
    /// (6 and 2 products).
    #[test]
    fn the_shipped_mlp_costs_its_products_and_activations() {
        let flops = flops_per_observation("tracker", crate::SHIPPED_MODEL_ONNX).unwrap();
        let products = 2 * (6 * 128 + 128 * 128 + 128 * 2);
        let tanh = 2 * 128 * (2 * 11 + 1);
        let scaling = 2 * (6 + 2);
        assert_eq!(flops, f64::from(products + tanh + scaling));
    }
}
