//! Families of random stress scenarios (`airroads stress --family`): `mixed` (the general generator
//! of [`crate::runs::stress`]), `bends` (one-way traffic along winding roads with tight bends: the
//! inner-vertex stall), `bottleneck` (two-way traffic through one narrow section), `headon` (two
//! groups swapping ends through a long part 0.5–5 m wide), `hairpin` (opposite traffic through a
//! U-turn) and `crowd` (two dense blocks flying through each other); and on road networks
//! ([`crate::runs::networks`]) `tee`, `wye`, `crossing`, `merge`, `roundabout`, `grid` and `ring`.
//! Case i of a run with seed S uses seed S + i in every family.

use crate::runs::networks;
use crate::runs::stress::{STRESS_T_MAX_S, random_scenario};
use crate::scenario::{Scenario, ScenarioUav};
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
    /// Two groups (2–60 UAVs in all) swapping ends through a gently bending part 0.5–5 m wide and
    /// 10–30 m long between waiting areas 5 m wide.
    HeadOn,
    /// A road 1.5–4 m wide that turns back on itself (a U-turn of 150–180° in three short pieces);
    /// 2–10 UAVs from each end to the other.
    Hairpin,
    /// A straight road 4–10 m wide; two blocks of 10–30 UAVs each, packed D_c + 0.3 m apart, fly
    /// through each other to the far side.
    Crowd,
    /// A network: a rectangular junction with three roads (a T); 2–16 UAVs between their ends.
    Tee,
    /// A network: a triangular junction with three roads (a Y); 2–16 UAVs between their ends.
    Wye,
    /// A network: a 4-way crossing; 2–16 UAVs between the ends of its roads.
    Crossing,
    /// A network: two one-way roads merging into one; 2–12 UAVs from both into the one.
    Merge,
    /// A network: a one-way ring of 3–5 entries, each with a spoke; 3–16 UAVs between the spokes.
    Roundabout,
    /// A network: a street grid of 2–4 × 2–4 junctions; 4–24 UAVs between random points.
    Grid,
    /// A network: a two-way ring of 5–8 entries with spokes; 3–24 UAVs between the spokes.
    Ring,
}

/// The families on road networks ([`crate::runs::networks`]).
pub const NETWORK_FAMILIES: [Family; 7] = [
    Family::Tee,
    Family::Wye,
    Family::Crossing,
    Family::Merge,
    Family::Roundabout,
    Family::Grid,
    Family::Ring,
];

/// Every family, in the order of the CLI's list.
pub const FAMILIES: [Family; 13] = [
    Family::Mixed,
    Family::Bends,
    Family::Bottleneck,
    Family::HeadOn,
    Family::Hairpin,
    Family::Crowd,
    Family::Tee,
    Family::Wye,
    Family::Crossing,
    Family::Merge,
    Family::Roundabout,
    Family::Grid,
    Family::Ring,
];

impl Family {
    /// The CLI name.
    pub fn name(&self) -> &'static str {
        match self {
            Family::Mixed => "mixed",
            Family::Bends => "bends",
            Family::Bottleneck => "bottleneck",
            Family::HeadOn => "headon",
            Family::Hairpin => "hairpin",
            Family::Crowd => "crowd",
            Family::Tee => "tee",
            Family::Wye => "wye",
            Family::Crossing => "crossing",
            Family::Merge => "merge",
            Family::Roundabout => "roundabout",
            Family::Grid => "grid",
            Family::Ring => "ring",
        }
    }

    /// The scenario of case `seed`.
    pub fn scenario(&self, seed: u64) -> Scenario {
        match self {
            Family::Mixed => random_scenario(seed),
            Family::Bends => bends(seed),
            Family::Bottleneck => bottleneck(seed),
            Family::HeadOn => head_on(seed),
            Family::Hairpin => hairpin(seed),
            Family::Crowd => crowd(seed),
            // The families not matched above are the network families.
            network => networks::scenario(*network, seed).expect("a network family"),
        }
    }
}

impl std::str::FromStr for Family {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        FAMILIES.iter().copied().find(|f| f.name() == s).ok_or_else(|| {
            let names: Vec<&str> = FAMILIES.iter().map(|f| f.name()).collect();
            format!("unknown family `{s}` (expected one of {})", names.join(", "))
        })
    }
}

/// Simulated time limit (s) of a `bottleneck` case: up to 16 UAVs go through the section one at a
/// time, and the funnels slow each one down (the road barrier lets a UAV approach converging walls
/// only as fast as it can still brake away from them), so a crowd needs longer than the 60 s of the
/// other families; the same limit as the narrow-section scenario (scenarios/narrow16.json).
pub const BOTTLENECK_T_MAX_S: f64 = 120.0;

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
        let scenario = Scenario::on_road(format!("bends-{seed}"), p, layout.segments, uavs);
        if scenario.validate().is_ok() {
            return scenario;
        }
    }
}

fn bottleneck(seed: u64) -> Scenario {
    let mut rng = StdRng::seed_from_u64(seed);
    let p = Params { t_max: BOTTLENECK_T_MAX_S, ..params() };
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
        let (west, east) = (rng.random_range(2..=8usize), rng.random_range(2..=8usize));
        let Some(uavs) = swap_ends(&road, west, east, &p) else { continue };
        if let Some(s) = valid(format!("bottleneck-{seed}"), p, layout, uavs) {
            return s;
        }
    }
}

/// Simulated time limit (s) of a `headon` case with `n` UAVs: 60 s, and 3 s more per UAV, the time
/// one UAV takes to clear a single-file part (its funnel crawl included) while the others wait.
pub fn head_on_t_max(n: usize) -> f64 {
    60.0 + 3.0 * n as f64
}

/// Two groups swapping ends; each side's goals are where the other side starts.
fn swap_ends(road: &Road, west: usize, east: usize, p: &Params) -> Option<Vec<ScenarioUav>> {
    let total = road.centerline().length();
    let spacing = p.d_c + 0.3;
    let west_starts = rows(road, 1.0, spacing, west, p);
    let east_starts = rows(road, total - 1.0, -spacing, east, p);
    let west_goals = rows(road, total - 1.0, -spacing, west_starts.len(), p);
    let east_goals = rows(road, 1.0, spacing, east_starts.len(), p);
    if west_goals.len() < west_starts.len() || east_goals.len() < east_starts.len() {
        return None;
    }
    let mut uavs: Vec<ScenarioUav> =
        west_starts.iter().zip(&west_goals).enumerate().map(|(i, (s, g))| uav(i, "w", *s, *g)).collect();
    uavs.extend(east_starts.iter().zip(&east_goals).enumerate().map(|(i, (s, g))| uav(i, "e", *s, *g)));
    Some(uavs)
}

/// The scenario if it validates with at least two UAVs.
fn valid(name: String, params: Params, layout: RoadLayout, uavs: Vec<ScenarioUav>) -> Option<Scenario> {
    let scenario = Scenario::on_road(name, params, layout.segments, uavs);
    (scenario.uavs.len() >= 2 && scenario.validate().is_ok()).then_some(scenario)
}

fn head_on(seed: u64) -> Scenario {
    let mut rng = StdRng::seed_from_u64(seed);
    loop {
        let width = rng.random_range(0.5..=5.0);
        let n = rng.random_range(2..=60usize);
        let west = rng.random_range(1..n);
        // Waiting areas 5 m wide and 8 m long, funnels of 2 m, the long part in 2–4 gently bending pieces.
        let mut points = vec![[0.0, 0.0], [8.0, 0.0], [10.0, 0.0]];
        let mut widths = vec![5.0, 5.0, width];
        let (mut at, mut heading) = (Vec2::new(10.0, 0.0), 0.0f64);
        let pieces = rng.random_range(2..=4usize);
        let length: f64 = rng.random_range(10.0..30.0);
        for _ in 0..pieces {
            heading += rng.random_range(-0.3..0.3);
            at += Vec2::new(heading.cos(), heading.sin()) * (length / pieces as f64);
            points.push([at.x, at.y]);
            widths.push(width);
        }
        for step in [2.0, 8.0] {
            at += Vec2::new(heading.cos(), heading.sin()) * step;
            points.push([at.x, at.y]);
            widths.push(5.0);
        }
        let layout = RoadLayout::from_centerline(&points, &widths);
        let Ok(road) = Road::new(layout.clone()) else { continue };
        let p = Params { t_max: head_on_t_max(n), ..params() };
        let Some(uavs) = swap_ends(&road, west, n - west, &p) else { continue };
        if let Some(s) = valid(format!("headon-{seed}"), p, layout, uavs) {
            return s;
        }
    }
}

fn hairpin(seed: u64) -> Scenario {
    let mut rng = StdRng::seed_from_u64(seed);
    let p = params();
    loop {
        let width = rng.random_range(1.5..=4.0);
        let (first, back) = (rng.random_range(8.0..12.0), rng.random_range(8.0..12.0));
        let turn: f64 = rng.random_range(150f64..=180.0).to_radians();
        let sign = if rng.random_bool(0.5) { 1.0 } else { -1.0 };
        let (mut at, mut heading) = (Vec2::new(first, 0.0), 0.0f64);
        let mut points = vec![[0.0, 0.0], [at.x, at.y]];
        // The U-turn: three short pieces a road's width or two long, then back beside the way out.
        for _ in 0..3 {
            heading += sign * turn / 3.0;
            at += Vec2::new(heading.cos(), heading.sin()) * rng.random_range(1.0..2.0) * width;
            points.push([at.x, at.y]);
        }
        at += Vec2::new(heading.cos(), heading.sin()) * back;
        points.push([at.x, at.y]);
        let layout = RoadLayout::from_centerline(&points, &vec![width; points.len()]);
        let Ok(road) = Road::new(layout.clone()) else { continue };
        let (west, east) = (rng.random_range(1..=10usize), rng.random_range(1..=10usize));
        let Some(uavs) = swap_ends(&road, west, east, &p) else { continue };
        if let Some(s) = valid(format!("hairpin-{seed}"), p, layout, uavs) {
            return s;
        }
    }
}

fn crowd(seed: u64) -> Scenario {
    let mut rng = StdRng::seed_from_u64(seed);
    let p = Params { t_max: CROWD_T_MAX_S, ..params() };
    loop {
        let width = rng.random_range(4.0..=10.0);
        let (west, east) = (rng.random_range(10..=30usize), rng.random_range(10..=30usize));
        let length = rng.random_range(30.0..50.0);
        let layout =
            RoadLayout::from_centerline(&[[0.0, 0.0], [length / 2.0, 0.0], [length, 0.0]], &[width; 3]);
        let Ok(road) = Road::new(layout.clone()) else { continue };
        let Some(uavs) = swap_ends(&road, west, east, &p) else { continue };
        if let Some(s) = valid(format!("crowd-{seed}"), p, layout, uavs) {
            return s;
        }
    }
}

/// Simulated time limit (s) of a `crowd` case: up to 60 UAVs fly 30–50 m through each other.
pub const CROWD_T_MAX_S: f64 = 90.0;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_family_generates_valid_reproducible_scenarios() {
        for family in FAMILIES {
            for seed in 0..30 {
                let s = family.scenario(seed);
                assert!(s.validate().is_ok(), "{} {seed}: {:?}", family.name(), s.validate().err());
                assert_eq!(s, family.scenario(seed));
                assert!(s.uavs.len() >= 2);
            }
        }
    }
}
