//! The scale benchmark's scenario (`airroads bench scale`, BENCHMARKS.md "Fleet engine at scale"):
//! a long winding two-way trunk road, 12 m wide in 20 m segments, 1.2 km of road per 1,000 UAVs,
//! with the UAVs spread along it and flying both ways to goals 60–150 m away along the road.

use crate::scenario::{Scenario, ScenarioUav};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use roads::{Road, RoadError, RoadLayout};
use uav::Params;

/// Width (m) of the trunk road.
pub const TRUNK_WIDTH_M: f64 = 12.0;
/// Length (m) of one segment.
pub const TRUNK_SEGMENT_M: f64 = 20.0;
/// Road length (m) per UAV: 1.2 km per 1,000.
pub const TRUNK_M_PER_UAV: f64 = 1.2;

/// The trunk scenario with `n` UAVs (at least 2), reproducible from `seed`; an error when its road
/// would exceed the segment limit (beyond about 166,000 UAVs).
pub fn trunk_scenario(n: usize, seed: u64) -> Result<Scenario, RoadError> {
    let n = n.max(2);
    let mut rng = StdRng::seed_from_u64(seed);
    let pieces = ((n as f64 * TRUNK_M_PER_UAV / TRUNK_SEGMENT_M).ceil() as usize).max(8);
    // Gentle bends that swing back (a heading within ±0.6 rad of east), so the road never meets itself.
    let (mut heading, mut points) = (0.0f64, vec![[0.0, 0.0]]);
    for _ in 0..pieces {
        heading = (heading + rng.random_range(-0.25..0.25)).clamp(-0.6, 0.6);
        let [x, y] = points[points.len() - 1];
        points.push([x + TRUNK_SEGMENT_M * heading.cos(), y + TRUNK_SEGMENT_M * heading.sin()]);
    }
    let layout = RoadLayout::from_centerline(&points, &vec![TRUNK_WIDTH_M; points.len()]);
    // 20 m pieces turning by at most 0.25 rad within ±0.6 rad of east: convex quads that only meet
    // at their joins; only the segment limit can fail.
    let road = Road::new(layout.clone())?;
    let line = road.centerline();
    let length = line.length();
    // Two UAVs per 2.4 m of road, one in each half, 0.5–5 m from the centre line (at most 0.25 rad
    // of turn per 20 m, rows 2.4 m apart stay more than 2 m apart on the inner side).
    let lateral = |rng: &mut StdRng, side: f64| side * rng.random_range(0.5..5.0);
    let spacing = (length - 4.0) / n.div_ceil(2) as f64;
    let uavs = (0..n)
        .map(|i| {
            let s = 2.0 + spacing * ((i / 2) as f64 + 0.5);
            let side = if i % 2 == 0 { -1.0 } else { 1.0 };
            let start = line.point_beside(s, lateral(&mut rng, side));
            let mut reach = rng.random_range(60.0..150.0) * if rng.random_bool(0.5) { 1.0 } else { -1.0 };
            if !(2.0..=length - 2.0).contains(&(s + reach)) {
                reach = -reach;
            }
            let goal_s = (s + reach).clamp(2.0, length - 2.0);
            let goal_side = if rng.random_bool(0.5) { 1.0 } else { -1.0 };
            let goal = line.point_beside(goal_s, lateral(&mut rng, goal_side));
            ScenarioUav { id: format!("u{i}"), start: [start.x, start.y], goal: [goal.x, goal.y], link: None }
        })
        .collect();
    let params = Params { t_max: 300.0, ..Params::default() };
    Ok(Scenario::on_road(format!("trunk{n}"), params, layout.segments, uavs))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn trunk_scenarios_are_valid_and_reproducible() {
        for (n, seed) in [(2, 1), (100, 2), (1000, 3), (10_000, 4)] {
            let s = trunk_scenario(n, seed).unwrap();
            assert_eq!(s.uavs.len(), n);
            let valid = s.validate().unwrap_or_else(|e| panic!("trunk {n}: {e}"));
            let length = valid.road.road().expect("a trunk is one road").centerline().length();
            assert!(length >= n as f64 * TRUNK_M_PER_UAV * 0.95, "{n} UAVs on {length} m");
            assert_eq!(s, trunk_scenario(n, seed).unwrap());
        }
    }
}
