//! The policies' MLP kernel against tract's own plan: the shipped model is recognised as an MLP and
//! its outputs match tract's within 1e-5 on thousands of random batches (any size, large and
//! non-finite observations included); a model that is not an MLP still runs on tract's plan.

use policies::{OnnxPolicy, Policy, shipped_model};
use proptest::prelude::*;
use std::path::Path;
use uav::Vec2;

/// Largest difference allowed between the kernel's and tract's outputs.
const TOLERANCE: f32 = 1e-5;

/// Compares the kernel and tract on `obs`: equal within [`TOLERANCE`], or both NaN.
fn kernel_matches_tract(policy: &mut OnnxPolicy, obs: &[[f64; 6]]) -> Result<(), String> {
    let kernel = policy.infer(obs).map_err(|e| e.to_string())?;
    let tract = policy.infer_with_tract(obs).map_err(|e| e.to_string())?;
    if kernel.len() != tract.len() || kernel.len() != 2 * obs.len() {
        return Err(format!(
            "{} kernel outputs, {} from tract, batch {}",
            kernel.len(),
            tract.len(),
            obs.len()
        ));
    }
    for (i, (k, t)) in kernel.iter().zip(&tract).enumerate() {
        let same = (k - t).abs() <= TOLERANCE || (k.is_nan() && t.is_nan());
        if !same {
            return Err(format!(
                "row {} output {}: kernel {k}, tract {t} (obs {:?})",
                i / 2,
                i % 2,
                obs[i / 2]
            ));
        }
    }
    Ok(())
}

/// An observation: mostly flight-like values, sometimes large ones (up to ±1e6) in some entries.
fn observation() -> impl Strategy<Value = [f64; 6]> {
    let entry = prop_oneof![
        8 => -20.0..20.0f64,
        1 => -1e3..1e3f64,
        1 => -1e6..1e6f64,
    ];
    prop::array::uniform6(entry)
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 2000, ..ProptestConfig::default() })]

    #[test]
    fn kernel_matches_tract_on_random_batches(obs in prop::collection::vec(observation(), 1..3000)) {
        let mut policy = shipped_model().expect("the shipped model loads");
        prop_assert!(policy.mlp().is_some(), "the shipped model is an MLP");
        kernel_matches_tract(&mut policy, &obs).map_err(TestCaseError::fail)?;
    }
}

/// Observations that are not finite as f32 give NaN actions (which the caller refuses: the UAV
/// brakes) or tract's; a NaN observation gives NaN actions (tract's plan gives finite ones).
#[test]
fn non_finite_observations_give_nan_or_what_tract_gives_and_never_panic() {
    let mut policy = shipped_model().expect("the shipped model loads");
    let specials = [f64::NAN, f64::INFINITY, f64::NEG_INFINITY, 1e39, -1e39, f64::MAX, 0.0];
    let obs: Vec<[f64; 6]> = (0..specials.len() * 6)
        .map(|k| std::array::from_fn(|i| if i == k % 6 { specials[k / 6] } else { 0.3 * i as f64 - 0.7 }))
        .collect();
    let kernel = policy.infer(&obs).expect("the kernel does not fail");
    let tract = policy.infer_with_tract(&obs).expect("tract runs");
    for (r, o) in obs.iter().enumerate() {
        let finite = o.iter().all(|&x| (x as f32).is_finite());
        for j in 0..2 {
            let (k, t) = (kernel[2 * r + j], tract[2 * r + j]);
            let same = (k - t).abs() <= TOLERANCE;
            assert!(same || (!finite && k.is_nan()), "row {r} ({o:?}) output {j}: kernel {k}, tract {t}");
            assert!(!o.iter().any(|x| x.is_nan()) || k.is_nan(), "row {r} ({o:?}): NaN in, {k} out");
        }
    }
    let mut actions = Vec::new();
    policy.act(&obs, &mut actions).expect("the kernel does not fail");
    assert_eq!(actions.len(), obs.len());
}

/// Writes an ONNX model `u = |obs · W|` (a `MatMul` then `Abs`): not an MLP of the kernel's kind.
fn abs_model() -> Vec<u8> {
    use prost::Message;
    use tract_onnx::pb;
    let w: Vec<f32> = (0..12).map(|k| k as f32 / 10.0 - 0.5).collect();
    let dims = |d: &[&str]| pb::TensorShapeProto {
        dim: d
            .iter()
            .map(|s| pb::tensor_shape_proto::Dimension {
                value: Some(match s.parse::<i64>() {
                    Ok(n) => pb::tensor_shape_proto::dimension::Value::DimValue(n),
                    Err(_) => pb::tensor_shape_proto::dimension::Value::DimParam(s.to_string()),
                }),
                ..Default::default()
            })
            .collect(),
    };
    let value = |name: &str, d: &[&str]| pb::ValueInfoProto {
        name: name.into(),
        r#type: Some(pb::TypeProto {
            value: Some(pb::type_proto::Value::TensorType(pb::type_proto::Tensor {
                elem_type: pb::tensor_proto::DataType::Float as i32,
                shape: Some(dims(d)),
            })),
            ..Default::default()
        }),
        ..Default::default()
    };
    let node = |op: &str, inputs: &[&str], output: &str| pb::NodeProto {
        op_type: op.into(),
        input: inputs.iter().map(|s| s.to_string()).collect(),
        output: vec![output.into()],
        ..Default::default()
    };
    let graph = pb::GraphProto {
        name: "abs".into(),
        node: vec![node("MatMul", &["obs", "W"], "x"), node("Abs", &["x"], "u")],
        initializer: vec![pb::TensorProto {
            name: "W".into(),
            dims: vec![6, 2],
            data_type: pb::tensor_proto::DataType::Float as i32,
            float_data: w,
            ..Default::default()
        }],
        input: vec![value("obs", &["N", "6"])],
        output: vec![value("u", &["N", "2"])],
        ..Default::default()
    };
    let model = pb::ModelProto {
        ir_version: 8,
        opset_import: vec![pb::OperatorSetIdProto { domain: String::new(), version: 17 }],
        graph: Some(graph),
        ..Default::default()
    };
    model.encode_to_vec()
}

#[test]
fn a_model_that_is_not_an_mlp_runs_on_tracts_plan() {
    let mut policy = OnnxPolicy::from_bytes("abs", "abs model (test)", &abs_model()).expect("a valid model");
    assert!(policy.mlp().is_none(), "MatMul then Abs is not taken for an MLP");
    // u_j = |Σ_i obs_i W_ij| with W_ij = (2i + j)/10 − 0.5.
    let obs: Vec<[f64; 6]> =
        (0..700).map(|k| std::array::from_fn(|i| (k * 6 + i) as f64 * 0.01 - 2.0)).collect();
    let mut actions = Vec::new();
    policy.act(&obs, &mut actions).expect("tract runs it");
    for (o, u) in obs.iter().zip(&actions) {
        let dot =
            |j: usize| o.iter().enumerate().map(|(i, x)| x * ((2 * i + j) as f64 / 10.0 - 0.5)).sum::<f64>();
        let want = Vec2::new(dot(0).abs(), dot(1).abs());
        assert!((u - want).norm() < 1e-4, "{u:?} vs {want:?}");
    }
    let linear = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/linear_6_2.onnx");
    let linear = OnnxPolicy::load("linear", &linear).expect("the linear fixture loads");
    assert!(linear.mlp().is_some(), "a single Gemm with bias is an MLP of one layer");
}
