//! The tract runtime: contract checks at load, exact batched inference, golden pairs of shipped models.

use policies::{LoadError, OnnxPolicy, Policy};
use std::path::{Path, PathBuf};
use uav::Vec2;

fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures").join(name)
}

#[test]
fn linear_model_is_evaluated_exactly_for_any_batch_size() {
    let mut policy = OnnxPolicy::load("linear", &fixture("linear_6_2.onnx")).unwrap();
    // u_j = Σ_i obs_i W_ij + b_j with W_ij = (2i + j)/10 and b = (0.5, −0.25).
    let expected = |o: &[f64; 6]| {
        let u = |j: usize| o.iter().enumerate().map(|(i, x)| x * (2 * i + j) as f64 / 10.0).sum::<f64>();
        Vec2::new(u(0) + 0.5, u(1) - 0.25)
    };
    for batch in [1usize, 2, 7, 1000] {
        let obs: Vec<[f64; 6]> =
            (0..batch).map(|k| std::array::from_fn(|i| (k * 6 + i) as f64 * 0.01 - 1.0)).collect();
        let mut actions = Vec::new();
        policy.act(&obs, &mut actions).unwrap();
        assert_eq!(actions.len(), batch);
        for (o, u) in obs.iter().zip(&actions) {
            assert!((u - expected(o)).norm() < 1e-4, "batch {batch}: {u:?} vs {:?}", expected(o));
        }
    }
    let mut none = vec![Vec2::zeros()];
    policy.act(&[], &mut none).unwrap();
    assert!(none.is_empty());
}

#[test]
fn models_breaking_the_contract_are_refused_with_a_clear_error() {
    let err = OnnxPolicy::load("bad", &fixture("linear_5_2.onnx")).unwrap_err();
    assert!(matches!(err, LoadError::Contract { .. }), "{err}");
    assert!(err.to_string().contains("linear_5_2.onnx") && err.to_string().contains("[N, 6]"), "{err}");

    let err = OnnxPolicy::load("bad", &fixture("linear_6_3.onnx")).unwrap_err();
    assert!(matches!(err, LoadError::Contract { .. }), "{err}");
    assert!(err.to_string().contains("[N, 2]"), "{err}");

    let err = OnnxPolicy::load("bad", &fixture("not_onnx.onnx")).unwrap_err();
    assert!(matches!(err, LoadError::Model { .. }), "{err}");

    let err = OnnxPolicy::load("bad", &fixture("missing.onnx")).unwrap_err();
    assert!(matches!(err, LoadError::Io { .. }) && err.to_string().contains("missing.onnx"), "{err}");
}
