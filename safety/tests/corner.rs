//! Proves the corner result of docs/safety.md §5 (E6): a UAV pushed straight into the outer wall of a
//! left bend leaves the road under the paper's segment rule (R1) for every turn and speed tried, while
//! the finite-walls rule (R2, default) and the halfplanes rule (R3) keep it inside, R2 at
//! ≥ D_s − 1 mm.

use roads::{Road, RoadLayout, SegmentTracker};
use safety::{RoadRule, Row, SafetyFilter, road_rows};
use uav::{Params, UavState, Vec2};

const WIDTH: f64 = 4.0;
const FIRST_LEG: f64 = 12.0;
const SECOND_LEG: f64 = 15.0;
/// Start: this far before the joint, this far from the outer (right) wall.
const BEFORE_JOINT: f64 = 3.0;
const FROM_OUTER_WALL: f64 = 0.5;
const DURATION_S: f64 = 6.0;
const TURNS_DEG: [f64; 4] = [30.0, 60.0, 90.0, 120.0];
const SPEEDS: [f64; 3] = [2.0, 4.0, 6.0];
const RULES: [RoadRule; 3] = [RoadRule::Walls, RoadRule::Halfplanes, RoadRule::Paper];
/// Every run must come this close (m) to the second leg's outer wall (the wall behind the convex corner).
const CORNER_REACH_M: f64 = 0.5;
/// How far below D_s the walls rule may dip (sampling at dt = 0.05 s).
const WALLS_SLACK_M: f64 = 0.001;

/// A straight leg along +x ending at the origin, then a left bend by `turn_deg` (mitre joint).
fn bend(turn_deg: f64) -> Road {
    let t = turn_deg.to_radians();
    let points = [[-FIRST_LEG, 0.0], [0.0, 0.0], [SECOND_LEG * t.cos(), SECOND_LEG * t.sin()]];
    Road::new(RoadLayout::from_centerline(&points, &[WIDTH; 3])).expect("the bend is a valid road")
}

/// What one run did.
#[derive(Debug, Clone, Copy)]
struct Run {
    /// Minimum of `road.boundary_distance(p)` over all ticks (negative: outside).
    min_distance: f64,
    /// True when the UAV was outside the road at some tick.
    left_road: bool,
    /// Ticks whose filter result was a failure (braking fallback).
    failures: usize,
    /// Largest slack of any solve.
    max_slack: f64,
    /// Time (s) and position of the first tick outside the road.
    first_exit: Option<(f64, Vec2)>,
    /// Closest approach (m) to the second leg's outer wall: the corner was really tested.
    closest_to_outer_wall: f64,
}

fn run(road: &Road, rule: RoadRule, speed: f64) -> Run {
    let params = Params::default();
    let (delta, dt) = (params.delta, params.dt);
    let mut state =
        UavState { p: Vec2::new(-BEFORE_JOINT, -WIDTH / 2.0 + FROM_OUTER_WALL), v: Vec2::new(speed, 0.0) };
    let u_ref = Vec2::new(delta / 2.0, 0.0);
    let outer = road.walls()[road.segment_walls(1)[0]];
    assert_eq!(outer.a, road.quads()[1].p[0], "wall j = 21 (right, outer) of the second leg");
    let mut tracker = SegmentTracker::default();
    let mut filter = SafetyFilter::default();
    let mut rows: Vec<Row> = Vec::new();
    let mut out = Run {
        min_distance: f64::INFINITY,
        left_road: false,
        failures: 0,
        max_slack: 0.0,
        first_exit: None,
        closest_to_outer_wall: f64::INFINITY,
    };
    let ticks = (DURATION_S / dt).round() as usize;
    for tick in 0..=ticks {
        let d = road.boundary_distance(&state.p);
        out.min_distance = out.min_distance.min(d);
        out.left_road |= d < 0.0;
        out.closest_to_outer_wall =
            out.closest_to_outer_wall.min((outer.nearest(&state.p).0 - state.p).norm());
        if d < 0.0 && out.first_exit.is_none() {
            out.first_exit = Some((tick as f64 * dt, state.p));
        }
        if tick == ticks {
            break;
        }
        let segment = tracker.update(road, &state.p);
        rows.clear();
        road_rows(road, rule, state.p, state.v, segment, &params, &mut rows);
        let f = filter.filter(u_ref, state.v, &rows, delta, dt);
        assert!(f.u.norm() <= delta * (1.0 + 1e-9), "input bound violated: {f:?}");
        out.failures += usize::from(f.failed);
        out.max_slack = out.max_slack.max(f.max_slack);
        state = state.stepped(f.u, dt);
        assert!(state.is_finite(), "state diverged at tick {tick}");
    }
    out
}

#[test]
fn corner_test() {
    let d_s = Params::default().d_s;
    let mut table = Vec::new();
    for turn in TURNS_DEG {
        let road = bend(turn);
        for speed in SPEEDS {
            let runs = RULES.map(|rule| run(&road, rule, speed));
            table.push((turn, speed, runs));
        }
    }
    eprintln!("corner test: minimum signed boundary distance (m), OUT = left the road; D_s = {d_s} m");
    eprintln!(
        "{:>5} {:>8} | {:>14} | {:>14} | {:>14}",
        "turn", "speed", "walls (R2)", "halfplanes", "paper (R1)"
    );
    for (turn, speed, runs) in &table {
        let cell = |r: &Run| format!("{:+8.3}{}", r.min_distance, if r.left_road { " OUT" } else { "    " });
        eprintln!(
            "{turn:>4}° {speed:>4} m/s | {:>14} | {:>14} | {:>14}",
            cell(&runs[0]),
            cell(&runs[1]),
            cell(&runs[2])
        );
    }
    for (turn, speed, runs) in &table {
        eprintln!(
            "  {turn:>3}°, {speed} m/s: failures/max slack walls {}/{:.0e}, halfplanes {}/{:.0e}, paper {}/{:.0e}; \
             paper left at {}",
            runs[0].failures,
            runs[0].max_slack,
            runs[1].failures,
            runs[1].max_slack,
            runs[2].failures,
            runs[2].max_slack,
            runs[2]
                .first_exit
                .map_or("-".into(), |(t, p)| format!("t = {t:.2} s, p = ({:.2}, {:.2})", p.x, p.y)),
        );
    }
    assert_eq!(table.len(), 12, "every turn × speed combination ran");
    for (turn, speed, [walls, halfplanes, paper]) in &table {
        let case = format!("{turn}° at {speed} m/s");
        let near = [walls, halfplanes, paper].iter().all(|r| r.closest_to_outer_wall <= CORNER_REACH_M);
        assert!(
            near,
            "{case}: the UAV never met the second leg's outer wall: {walls:?} {halfplanes:?} {paper:?}"
        );
        assert!(
            paper.left_road,
            "{case}: the paper's rule (R1) should leave the road (E6), min {}",
            paper.min_distance
        );
        assert!(!walls.left_road, "{case}: walls (R2) left the road, min {}", walls.min_distance);
        assert!(
            walls.min_distance >= d_s - WALLS_SLACK_M,
            "{case}: walls (R2) came within {} m of the boundary (D_s = {d_s})",
            walls.min_distance
        );
        assert!(
            !halfplanes.left_road,
            "{case}: halfplanes (R3) left the road, min {}",
            halfplanes.min_distance
        );
    }
}
