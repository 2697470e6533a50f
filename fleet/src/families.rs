//! Families of random stress scenarios (`airroads stress --family`): `mixed` (the general generator
//! of [`crate::stress`]), `bends` (one-way traffic along winding roads with tight bends: the
//! inner-vertex stall) and `bottleneck` (two-way traffic through one narrow section). Case i of a
//! run with seed S uses seed S + i in every family.

use crate::scenario::{Scenario, ScenarioUav};
use crate::stress::{STRESS_T_MAX_S, random_scenario};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use roads::{Road, RoadLayout};
use uav::{Params, Vec2};

/// A family of random scenarios.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Family {
    /// Roads with bends of 20–120°, widths of 1–5 m, hairpins; 2–30 UAVs with random starts and goals.
    #[default]
    Mixed,
    /// Winding roads 1.5–3 m wide with 6–10 bends of 60–130°; 4–12 UAVs from the entry to the far end.
    Bends,
    /// A straight-ish road 3–5 m wide with one section 0.5–1.2 m wide and 2–6 m long in its middle;
    /// 2–8 UAVs on each side flying through it to the other.
    Bottleneck,
}

impl Family {
    /// The CLI name.
    pub fn name(&self) -> &'static str {
        match self {
            Family::Mixed => "mixed",
            Family::Bends => "bends",
            Family::Bottleneck => "bottleneck",
        }
    }

    /// The scenario of case `seed`.
    pub fn scenario(&self, seed: u64) -> Scenario {
        match self {
            Family::Mixed => random_scenario(seed),
            Family::Bends => bends(seed),
            Family::Bottleneck => bottleneck(seed),
        }
    }
}

impl std::str::FromStr for Family {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "mixed" => Ok(Family::Mixed),
            "bends" => Ok(Family::Bends),
            "bottleneck" => Ok(Family::Bottleneck),
            other => Err(format!("unknown family `{other}` (expected mixed, bends or bottleneck)")),
        }
    }
}

fn params() -> Params {
    Params { t_max: STRESS_T_MAX_S, ..Params::default() }
}

fn uav(i: usize, prefix: &str, start: Vec2, goal: Vec2) -> ScenarioUav {
    ScenarioUav { id: format!("{prefix}{i}"), start: [start.x, start.y], goal: [goal.x, goal.y], link: None }
}

/// Points across the road at arc length `s`: up to `count`, D_c + 0.3 m apart, D_s + 0.2 m from
/// the walls.
fn row(road: &Road, s: f64, count: usize, p: &Params) -> Vec<Vec2> {
    let line = road.centerline();
    let (right, left) = road.profile().at(s);
    let keep = p.d_s + 0.2;
    let spacing = p.d_c + 0.3;
    let room = (right + left - 2.0 * keep).max(0.0);
    let fit = ((room / spacing).floor() as usize + 1).min(count);
    (0..fit).map(|k| line.point_beside(s, -right + keep + k as f64 * spacing)).collect()
}

/// Starts or goals of `n` UAVs in rows from arc length `from` towards `step`'s sign, valid ones only.
fn rows(road: &Road, from: f64, step: f64, n: usize, p: &Params) -> Vec<Vec2> {
    let mut out = Vec::new();
    let mut s = from;
    while out.len() < n && s > 0.0 && s < road.centerline().length() {
        let here = row(road, s, n - out.len(), p);
        out.extend(here.into_iter().filter(|x| road.boundary_distance(x) >= p.d_s + 0.2));
        s += step;
    }
    out
}

fn bends(seed: u64) -> Scenario {
    let mut rng = StdRng::seed_from_u64(seed);
    let p = params();
    loop {
        let width = rng.random_range(1.5..=3.0);
        let pieces = rng.random_range(6..=10usize);
        let mut heading: f64 = rng.random_range(0.0..std::f64::consts::TAU);
        let (mut at, mut points) = (Vec2::zeros(), vec![[0.0, 0.0]]);
        for k in 0..pieces {
            if k > 0 {
                let sign = if k % 2 == 0 { 1.0 } else { -1.0 };
                heading += sign * rng.random_range(60f64..=130.0).to_radians();
            }
            at += Vec2::new(heading.cos(), heading.sin()) * rng.random_range(4.0..8.0);
            points.push([at.x, at.y]);
        }
        let layout = RoadLayout::from_centerline(&points, &vec![width; points.len()]);
        let Ok(road) = Road::new(layout.clone()) else { continue };
        let n = rng.random_range(4..=12usize);
        let length = road.centerline().length();
        let spacing = p.d_c + 0.3;
        let starts = rows(&road, 1.0, spacing, n, &p);
        let goals = rows(&road, length - 1.0, -spacing, starts.len(), &p);
        if starts.len() < 2 || goals.len() < starts.len() {
            continue;
        }
        let uavs = starts.iter().zip(&goals).enumerate().map(|(i, (s, g))| uav(i, "u", *s, *g)).collect();
        let scenario = Scenario { name: format!("bends-{seed}"), params: p, segments: layout.segments, uavs };
        if scenario.validate().is_ok() {
            return scenario;
        }
    }
}

fn bottleneck(seed: u64) -> Scenario {
    let mut rng = StdRng::seed_from_u64(seed);
    let p = params();
    loop {
        let (wide, narrow) = (rng.random_range(3.0..=5.0), rng.random_range(0.5..=1.2));
        let (approach, length) = (rng.random_range(8.0..12.0), rng.random_range(2.0..6.0));
        let funnel = rng.random_range(1.0..3.0);
        let bend = rng.random_range(-0.3..0.3f64);
        let xs =
            [0.0, approach, approach + funnel, approach + funnel + length, approach + 2.0 * funnel + length];
        let end = xs[4] + approach;
        let mut points: Vec<[f64; 2]> = xs.iter().map(|&x| [x, bend * x]).collect();
        points.push([end, bend * end]);
        let widths = [wide, wide, narrow, narrow, wide, wide];
        let layout = RoadLayout::from_centerline(&points, &widths);
        let Ok(road) = Road::new(layout.clone()) else { continue };
        let total = road.centerline().length();
        let spacing = p.d_c + 0.3;
        let (west, east) = (rng.random_range(2..=8usize), rng.random_range(2..=8usize));
        let west_starts = rows(&road, 1.0, spacing, west, &p);
        let east_starts = rows(&road, total - 1.0, -spacing, east, &p);
        let west_goals = rows(&road, total - 1.0, -spacing, west_starts.len(), &p);
        let east_goals = rows(&road, 1.0, spacing, east_starts.len(), &p);
        if west_goals.len() < west_starts.len() || east_goals.len() < east_starts.len() {
            continue;
        }
        let mut uavs: Vec<ScenarioUav> =
            west_starts.iter().zip(&west_goals).enumerate().map(|(i, (s, g))| uav(i, "w", *s, *g)).collect();
        // Each side's goals are where the other side starts: the groups swap ends.
        uavs.extend(east_starts.iter().zip(&east_goals).enumerate().map(|(i, (s, g))| uav(i, "e", *s, *g)));
        let scenario =
            Scenario { name: format!("bottleneck-{seed}"), params: p, segments: layout.segments, uavs };
        if scenario.validate().is_ok() {
            return scenario;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_family_generates_valid_reproducible_scenarios() {
        for family in [Family::Mixed, Family::Bends, Family::Bottleneck] {
            for seed in 0..30 {
                let s = family.scenario(seed);
                assert!(s.validate().is_ok(), "{} {seed}: {:?}", family.name(), s.validate().err());
                assert_eq!(s, family.scenario(seed));
                assert!(s.uavs.len() >= 2);
            }
        }
    }
}
