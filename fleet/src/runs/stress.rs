//! Random valid scenarios for stress runs: roads with bends of 20–120°, widths of 1–5 m, short
//! segments and hairpins that bring the road back near itself, and fleets of 2–30 UAVs. Case i of a
//! run with seed S uses seed S + i, so `--scenarios 1 --seed S+i` replays it.

use crate::scenario::{Scenario, ScenarioUav};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use roads::{Road, RoadLayout};
use uav::{Params, Vec2};

/// Simulated time limit of a stress case (s).
pub const STRESS_T_MAX_S: f64 = 60.0;

/// Generates the scenario of one stress case from its seed.
pub fn random_scenario(seed: u64) -> Scenario {
    let mut rng = StdRng::seed_from_u64(seed);
    let params = Params { t_max: STRESS_T_MAX_S, ..Params::default() };
    loop {
        let (layout, road) = random_road(&mut rng);
        let wanted = rng.random_range(2..=30usize);
        let uavs = random_fleet(&mut rng, &road, &params, wanted);
        if uavs.len() >= 2 {
            return Scenario::on_road(format!("stress-{seed}"), params, layout.segments, uavs);
        }
    }
}

/// A random valid road (retries until validation passes).
fn random_road(rng: &mut StdRng) -> (RoadLayout, Road) {
    loop {
        let pieces = rng.random_range(3..=12usize);
        let width: f64 = rng.random_range(1.0..=5.0);
        let mut heading: f64 = rng.random_range(0.0..std::f64::consts::TAU);
        let mut p = Vec2::zeros();
        let mut points = vec![[p.x, p.y]];
        let mut widths = vec![width];
        // A hairpin: consecutive turns of the same sign, bringing the road back beside itself.
        let hairpin_sign =
            if rng.random_bool(0.3) { Some(if rng.random_bool(0.5) { 1.0 } else { -1.0 }) } else { None };
        for k in 0..pieces {
            if k > 0 {
                let turn =
                    if rng.random_bool(0.25) { 0.0 } else { rng.random_range(20f64..=120.0).to_radians() };
                let sign = hairpin_sign.unwrap_or_else(|| if rng.random_bool(0.5) { 1.0 } else { -1.0 });
                heading += sign * turn;
            }
            let length =
                if rng.random_bool(0.2) { rng.random_range(1.0..2.5) } else { rng.random_range(2.5..10.0) };
            p += Vec2::new(heading.cos(), heading.sin()) * length;
            points.push([p.x, p.y]);
            widths.push((width * rng.random_range(0.8..1.25f64)).clamp(1.0, 5.0));
        }
        let layout = RoadLayout::from_centerline(&points, &widths);
        if let Ok(road) = Road::new(layout.clone()) {
            return (layout, road);
        }
    }
}

/// Up to `wanted` UAVs with starts and goals spread over the road (starts ≥ D_s + 0.2 m from walls
/// and ≥ D_c + 0.3 m apart; goals likewise apart, so all can arrive).
fn random_fleet(rng: &mut StdRng, road: &Road, params: &Params, wanted: usize) -> Vec<ScenarioUav> {
    let (clearance, spacing) = (params.d_s + 0.2, params.d_c + 0.3);
    let (lo, hi) = road
        .quads()
        .iter()
        .flat_map(|q| q.p)
        .fold((Vec2::repeat(f64::INFINITY), Vec2::repeat(f64::NEG_INFINITY)), |(lo, hi), v| {
            (lo.inf(&v), hi.sup(&v))
        });
    let sample = |taken: &[Vec2], rng: &mut StdRng| {
        (0..500).find_map(|_| {
            let x = Vec2::new(rng.random_range(lo.x..=hi.x), rng.random_range(lo.y..=hi.y));
            let free = taken.iter().all(|t| (t - x).norm() >= spacing);
            (road.boundary_distance(&x) >= clearance && free).then_some(x)
        })
    };
    let (mut starts, mut goals) = (Vec::new(), Vec::new());
    for _ in 0..wanted {
        let Some(s) = sample(&starts, rng) else { break };
        let Some(g) = sample(&goals, rng) else { break };
        starts.push(s);
        goals.push(g);
    }
    starts
        .iter()
        .zip(&goals)
        .enumerate()
        .map(|(i, (s, g))| ScenarioUav {
            id: format!("u{i}"),
            start: [s.x, s.y],
            goal: [g.x, g.y],
            link: None,
        })
        .collect()
}

/// A dense two-way crowd of `n` UAVs (BENCHMARKS.md, "Admission" and "Fleet stages";
/// `airroads bench server --crowd N`, `airroads bench fleet`): a straight road 12 m wide, two
/// blocks on a 1.2 m grid 30 m apart, each flying through the other to the far side.
pub fn crowd_scenario(n: usize) -> Scenario {
    let (width, rows, spacing) = (12.0, 9usize, 1.2);
    let per_block = n.div_ceil(2).max(1);
    let cols = per_block.div_ceil(rows);
    let length = 2.0 * cols as f64 * spacing + 80.0;
    let step = 10.0;
    let mut segments = Vec::new();
    let mut x: f64 = 0.0;
    while x < length {
        let x1 = (x + step).min(length);
        let half = width / 2.0;
        segments.push([[x1, -half], [x, -half], [x1, half], [x, half]]);
        x = x1;
    }
    let reach = cols as f64 * spacing + 30.0;
    let uavs = (0..n)
        .map(|i| {
            let (block, k) = (i / per_block, i % per_block);
            let (col, row) = (k / rows, k % rows);
            let y = -4.8 + row as f64 * spacing;
            let (start, goal) = if block == 0 {
                let start = 5.0 + col as f64 * spacing;
                (start, start + reach)
            } else {
                let start = length - 5.0 - col as f64 * spacing;
                (start, start - reach)
            };
            ScenarioUav { id: format!("u{i}"), start: [start, y], goal: [goal, y], link: None }
        })
        .collect();
    let params = Params { t_max: 120.0, ..Params::default() };
    Scenario::on_road(format!("crowd{n}"), params, segments, uavs)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn generated_scenarios_are_valid_and_reproducible() {
        for seed in 0..40 {
            let s = random_scenario(seed);
            assert!(s.validate().is_ok(), "seed {seed}: {:?}", s.validate().err());
            assert_eq!(s, random_scenario(seed));
            assert!((2..=30).contains(&s.uavs.len()));
        }
    }

    #[test]
    fn crowds_are_valid() {
        for n in [2, 17, 300] {
            let s = crowd_scenario(n);
            assert_eq!(s.uavs.len(), n);
            assert!(s.validate().is_ok(), "{n}: {:?}", s.validate().err());
        }
    }
}
