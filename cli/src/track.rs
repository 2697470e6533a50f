//! `airroads track`: flies the paper's reference trajectories for 50 s with a tracking policy and the
//! PD baselines, and prints tracking RMSE and inference time (the RL policy's benchmark, issue 3).
//!
//! Same protocol as `policies/train/evaluate.py`: the UAV starts at rest at the reference's start; at
//! step k it observes [p − p_r(k), v − v_r(k), v]; the action is saturated to ‖u‖ ≤ δ = 5 and the exact
//! step taken; errors are p(k) − p_r(k) for k = 1..1000.

use flights::say;

use crate::cli::TrackArgs;
use policies::{Observation, PdPolicy, Policy, observation};
use std::process::ExitCode;
use std::time::Instant;
use uav::{UavState, Vec2, saturate};

const DT: f64 = 0.05;
const DELTA: f64 = 5.0;
const STEPS: usize = 1000;
/// Gains of the tuned PD baseline (grid search on the three references, policies/train/evaluate.py).
const TUNED: (f64, f64) = (200.0, 25.0);

/// Reference position and velocity at time t of a named trajectory.
fn reference(name: &str, t: f64) -> (Vec2, Vec2) {
    let w = std::f64::consts::PI / 25.0;
    let (c, s) = ((w * t).cos(), (w * t).sin());
    match name {
        "ellipse" => (Vec2::new(10.0 * c, 7.5 * s), Vec2::new(-10.0 * w * s, 7.5 * w * c)),
        "figure8" => (Vec2::new(7.5 * s, 7.5 * s * c), Vec2::new(7.5 * w * c, 7.5 * w * (c * c - s * s))),
        _ => {
            // Rectangle: 12.5 s per side at constant speed along each side, v right-continuous at corners.
            let corners = [[7.5, -5.0], [7.5, 5.0], [-7.5, 5.0], [-7.5, -5.0]].map(|[x, y]| Vec2::new(x, y));
            let side = ((t / 12.5).floor() as usize) % 4;
            let (a, b) = (corners[side], corners[(side + 1) % 4]);
            let vel = (b - a) / 12.5;
            (a + vel * (t - 12.5 * (t / 12.5).floor()), vel)
        }
    }
}

/// A controller under test: a registry policy or a PD with optional acceleration feed-forward.
enum Controller<'a> {
    Learned(&'a mut dyn Policy),
    Pd(PdPolicy, bool),
}

impl Controller<'_> {
    fn act(&mut self, obs: &[Observation], feed_forward: Vec2, out: &mut Vec<Vec2>) -> Result<(), String> {
        match self {
            Controller::Learned(p) => p.act(obs, out).map_err(|e| e.to_string()),
            Controller::Pd(pd, ff) => {
                out.clear();
                out.extend(obs.iter().map(|o| pd.law(o) + if *ff { feed_forward } else { Vec2::zeros() }));
                Ok(())
            }
        }
    }
}

/// One row of the table.
#[derive(serde::Serialize)]
struct TrackRow {
    trajectory: String,
    policy: String,
    rmse_m: f64,
    rmse_x_m: f64,
    rmse_y_m: f64,
    infer_us_batch1: f64,
    infer_us_per_uav_batch1000: f64,
}

fn fly(name: &str, c: &mut Controller) -> Result<(f64, f64, f64), String> {
    let mut s = UavState::at_rest(reference(name, 0.0).0);
    let (mut sx, mut sy) = (0.0, 0.0);
    let mut out = Vec::new();
    for k in 0..STEPS {
        let (p_r, v_r) = reference(name, k as f64 * DT);
        let (p_next, v_next) = reference(name, (k + 1) as f64 * DT);
        c.act(&[observation(&s, p_r, v_r)], (v_next - v_r) / DT, &mut out)?;
        s = s.stepped(saturate(out[0], DELTA), DT);
        let e = s.p - p_next;
        sx += e.x * e.x;
        sy += e.y * e.y;
    }
    let n = STEPS as f64;
    Ok((((sx + sy) / n).sqrt(), (sx / n).sqrt(), (sy / n).sqrt()))
}

/// Mean µs per call for a batch of `batch` observations.
fn time_calls(c: &mut Controller, batch: usize, calls: usize) -> Result<f64, String> {
    let obs: Vec<Observation> =
        (0..batch).map(|k| std::array::from_fn(|i| ((k * 7 + i) % 13) as f64 * 0.1 - 0.6)).collect();
    let mut out = Vec::with_capacity(batch);
    c.act(&obs, Vec2::zeros(), &mut out)?;
    let start = Instant::now();
    for _ in 0..calls {
        c.act(&obs, Vec2::zeros(), &mut out)?;
    }
    Ok(start.elapsed().as_secs_f64() * 1e6 / calls as f64)
}

/// Runs the subcommand.
pub fn main(args: TrackArgs) -> ExitCode {
    let mut registry = match args.policies() {
        Ok(r) => r,
        Err(msg) => {
            eprintln!("error: {msg}");
            return ExitCode::from(2);
        }
    };
    let names: Vec<&str> = if args.trajectory == "all" {
        vec!["ellipse", "figure8", "rectangle"]
    } else {
        vec![args.trajectory.as_str()]
    };
    let pd = PdPolicy { delta: DELTA, ..PdPolicy::default() };
    let tuned = PdPolicy { kp: TUNED.0, kd: TUNED.1, delta: f64::INFINITY };
    let mut rows = Vec::new();
    for name in &names {
        let Some(learned) = registry.get_mut(&args.policy) else { return ExitCode::from(2) };
        let mut controllers: Vec<(String, Controller)> = vec![
            (args.policy.clone(), Controller::Learned(learned)),
            ("pd".into(), Controller::Pd(pd, false)),
            ("pd+ff".into(), Controller::Pd(pd, true)),
            ("pd_tuned".into(), Controller::Pd(tuned, false)),
            ("pd_tuned+ff".into(), Controller::Pd(tuned, true)),
        ];
        for (label, c) in &mut controllers {
            let measured = fly(name, c)
                .and_then(|rmse| Ok((rmse, time_calls(c, 1, 5000)?, time_calls(c, 1000, 50)? / 1000.0)));
            match measured {
                Ok(((total, x, y), b1, b1000)) => rows.push(TrackRow {
                    trajectory: name.to_string(),
                    policy: label.clone(),
                    rmse_m: total,
                    rmse_x_m: x,
                    rmse_y_m: y,
                    infer_us_batch1: b1,
                    infer_us_per_uav_batch1000: b1000,
                }),
                Err(e) => {
                    eprintln!("error: policy {label}: {e}");
                    return ExitCode::from(1);
                }
            }
        }
    }
    if args.json {
        say!("{}", serde_json::to_string_pretty(&rows).unwrap_or_default());
        return ExitCode::SUCCESS;
    }
    say!(
        "airroads track: 50 s from rest at the start, dt = {DT} s, ‖u‖ ≤ {DELTA} m/s²; pd: kp 1.5, kd 2 (the fleet's); pd_tuned: kp {}, kd {}; +ff adds the reference acceleration",
        TUNED.0,
        TUNED.1
    );
    say!(
        "{:<10} {:<12} {:>9} {:>9} {:>9} {:>12} {:>16}",
        "trajectory",
        "policy",
        "rmse_m",
        "x_m",
        "y_m",
        "us_batch1",
        "us_per_uav_1000"
    );
    for r in &rows {
        say!(
            "{:<10} {:<12} {:>9.4} {:>9.4} {:>9.4} {:>12.2} {:>16.3}",
            r.trajectory,
            r.policy,
            r.rmse_m,
            r.rmse_x_m,
            r.rmse_y_m,
            r.infer_us_batch1,
            r.infer_us_per_uav_batch1000
        );
    }
    ExitCode::SUCCESS
}
