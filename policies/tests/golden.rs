//! Every model shipped in `policies/models` reproduces its golden input/output pairs through tract,
//! matches its manifest's sha256, and the embedded default model is `tracker.onnx`.

use policies::{OnnxPolicy, SHIPPED_MODEL_ONNX};
use std::path::Path;

fn models_dir() -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("models")
}

#[test]
fn shipped_models_reproduce_their_golden_pairs() {
    let mut checked = 0;
    let dir = models_dir();
    for entry in std::fs::read_dir(&dir).unwrap_or_else(|e| panic!("{}: {e}", dir.display())) {
        let path = entry.unwrap_or_else(|e| panic!("{}: {e}", dir.display())).path();
        let Some(stem) =
            path.file_name().and_then(|n| n.to_str()).and_then(|n| n.strip_suffix(".golden.json"))
        else {
            continue;
        };
        let golden: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
        let model = models_dir().join(golden["model"].as_str().unwrap());
        let tolerance = golden["tolerance"].as_f64().unwrap();
        assert!(tolerance <= 1e-5, "{stem}: golden tolerance {tolerance} is looser than 1e-5");
        let mut policy = OnnxPolicy::load(stem, &model).unwrap();
        let pairs = golden["pairs"].as_array().unwrap();
        let obs: Vec<[f64; 6]> =
            pairs.iter().map(|p| std::array::from_fn(|i| p["obs"][i].as_f64().unwrap())).collect();
        // One batch of all pairs, then each pair alone: batching must not change any output.
        let batched = policy.infer(&obs).unwrap();
        for (k, pair) in pairs.iter().enumerate() {
            let single = policy.infer(&obs[k..=k]).unwrap();
            for j in 0..2 {
                let want = pair["u"][j].as_f64().unwrap();
                for got in [batched[2 * k + j], single[j]] {
                    assert!((f64::from(got) - want).abs() <= tolerance, "{stem} pair {k}: {got} vs {want}");
                }
            }
        }
        let manifest: serde_json::Value = serde_json::from_str(
            &std::fs::read_to_string(models_dir().join(format!("{stem}.json"))).unwrap(),
        )
        .unwrap();
        assert_eq!(
            manifest["sha256"], golden["sha256"],
            "{stem}: manifest and golden pairs name different files"
        );
        assert!(pairs.len() >= 16, "{stem}: only {} golden pairs", pairs.len());
        checked += 1;
    }
    assert!(checked >= 1, "no model with golden pairs in policies/models");
    assert_eq!(SHIPPED_MODEL_ONNX, std::fs::read(models_dir().join("tracker.onnx")).unwrap().as_slice());
}

/// A batch large enough for tract to split its matrix products over the worker threads gives the
/// same bits on one, two and four threads, and the same as each observation evaluated alone.
#[test]
fn large_batches_are_identical_on_any_number_of_threads() {
    let mut policy = OnnxPolicy::load("tracker", &models_dir().join("tracker.onnx")).unwrap();
    // Deterministic spread of observations: offsets up to ±6 m, velocities up to ±2 m/s.
    let obs: Vec<[f64; 6]> = (0..4096)
        .map(|k| std::array::from_fn(|i| ((k * 7 + i * 13) % 97) as f64 / 97.0 * 4.0 - 2.0))
        .collect();
    let on = |threads: usize, policy: &mut OnnxPolicy| {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
        pool.install(|| policy.infer(&obs).unwrap())
    };
    let one = on(1, &mut policy);
    assert_eq!(one.len(), 2 * obs.len());
    for threads in [2, 4] {
        assert!(on(threads, &mut policy) == one, "{threads} threads give other outputs than one");
    }
    for k in [0, 1, 2047, 4095] {
        let single = policy.infer(&obs[k..=k]).unwrap();
        assert_eq!(single[..], one[2 * k..2 * k + 2], "observation {k} alone differs from its batch");
    }
}
