//! The Rust simulator, observation, saturation and reward write the parity fixture that
//! `policies/train/tests/test_parity.py` replays with the Python environment (to 1e-9).
//! This test regenerates the rollouts and fails if the committed fixture differs;
//! `AIRROADS_WRITE_FIXTURE=1 cargo test -p policies --test parity_fixture` rewrites it.

use policies::{PdPolicy, RewardWeights, observation, tracking_reward};
use serde_json::{Value, json};
use uav::{UavState, Vec2, saturate};

const DT: f64 = 0.05;
const DELTA: f64 = 5.0;

/// A reference sample: position and velocity.
type Reference = (Vec2, Vec2);

fn arr(v: Vec2) -> Value {
    json!([v.x, v.y])
}

/// One rollout from `start`: per step the reference (p_r, v_r), the reference one step later, and a raw input.
fn rollout(
    start: UavState,
    refs: &[(Reference, Reference)],
    mut control: impl FnMut(&[f64; 6], usize) -> Vec2,
) -> Value {
    let w = RewardWeights::default();
    let mut s = start;
    let mut steps = Vec::new();
    for (k, &(now, next)) in refs.iter().enumerate() {
        let obs = observation(&s, now.0, now.1);
        let u_raw = control(&obs, k);
        let u = saturate(u_raw, DELTA);
        let after = s.stepped(u, DT);
        let r = tracking_reward(&s, &after, now, next, &w);
        steps.push(json!({
            "p_r": arr(now.0), "v_r": arr(now.1), "p_r_next": arr(next.0), "v_r_next": arr(next.1),
            "u_raw": arr(u_raw), "u": arr(u), "p": arr(after.p), "v": arr(after.v), "obs": obs, "reward": r,
        }));
        s = after;
    }
    json!({"p0": arr(start.p), "v0": arr(start.v), "steps": steps})
}

fn fixture() -> Value {
    let pd = PdPolicy { kp: 20.0, kd: 8.0, delta: 1e9 };
    // A point target that jumps after 12 steps (the jump shows only in the next step's p_r).
    let (a, b, zero) = (Vec2::new(3.0, 4.0), Vec2::new(-2.0, 1.5), Vec2::zeros());
    let jump: Vec<_> =
        (0..24).map(|k| if k < 12 { ((a, zero), (a, zero)) } else { ((b, zero), (b, zero)) }).collect();
    // The ellipse [10 cos(πt/25), 7.5 sin(πt/25)] from rest at its start.
    let w = std::f64::consts::PI / 25.0;
    let ell = |t: f64| {
        (
            Vec2::new(10.0 * (w * t).cos(), 7.5 * (w * t).sin()),
            Vec2::new(-10.0 * w * (w * t).sin(), 7.5 * w * (w * t).cos()),
        )
    };
    let track: Vec<_> = (0..30).map(|k| (ell(k as f64 * DT), ell((k + 1) as f64 * DT))).collect();
    // A moving line reference with raw inputs far beyond δ (exercises the saturation), deterministic.
    let line = |t: f64| (Vec2::new(1.0 + 0.8 * t, -2.0 + 0.3 * t), Vec2::new(0.8, 0.3));
    let moving: Vec<_> = (0..20).map(|k| (line(k as f64 * DT), line((k + 1) as f64 * DT))).collect();
    let wild =
        |_: &[f64; 6], k: usize| Vec2::new(20.0 * ((k as f64) * 1.7).sin(), -15.0 * ((k as f64) * 0.9).cos());
    json!({
        "dt": DT, "delta": DELTA,
        "reward": {"lambda_s1": 5.0, "lambda_s2": 0.7, "lambda_o": 0.1},
        "source": "policies/tests/parity_fixture.rs (Rust simulator)",
        "rollouts": [
            rollout(UavState { p: zero, v: Vec2::new(1.0, -0.5) }, &jump, |o, _| pd.law(o)),
            rollout(UavState::at_rest(ell(0.0).0), &track, |o, _| PdPolicy { kp: 200.0, kd: 25.0, delta: 1e9 }.law(o)),
            rollout(UavState { p: Vec2::new(1.2, -1.9), v: Vec2::new(0.0, 0.5) }, &moving, wild),
        ],
    })
}

#[test]
fn committed_parity_fixture_is_what_the_rust_simulator_writes() {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("train/fixtures/rollouts.json");
    let fresh = fixture();
    if std::env::var_os("AIRROADS_WRITE_FIXTURE").is_some() {
        std::fs::write(&path, serde_json::to_string(&fresh).unwrap() + "\n").unwrap();
    }
    let committed: Value = serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
    if let Err(at) = same(&committed, &fresh, "") {
        panic!("{} is stale at {at}: rerun with AIRROADS_WRITE_FIXTURE=1", path.display());
    }
}

/// Structural equality with numbers equal to 1e-12 relative (JSON text round-trips floats to ~1 ulp).
fn same(a: &Value, b: &Value, at: &str) -> Result<(), String> {
    match (a, b) {
        (Value::Number(x), Value::Number(y)) => {
            let (x, y) = (x.as_f64().unwrap(), y.as_f64().unwrap());
            if (x - y).abs() <= 1e-12 * x.abs().max(y.abs()).max(1.0) {
                Ok(())
            } else {
                Err(format!("{at}: {x} vs {y}"))
            }
        }
        (Value::Array(x), Value::Array(y)) if x.len() == y.len() => {
            x.iter().zip(y).enumerate().try_for_each(|(i, (x, y))| same(x, y, &format!("{at}[{i}]")))
        }
        (Value::Object(x), Value::Object(y)) if x.len() == y.len() => x.iter().try_for_each(|(k, v)| {
            y.get(k).ok_or(format!("{at}.{k} missing")).and_then(|w| same(v, w, &format!("{at}.{k}")))
        }),
        _ if a == b => Ok(()),
        _ => Err(format!("{at}: {a} vs {b}")),
    }
}
