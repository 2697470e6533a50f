//! `traffic` navigation targets: corner clearance and keep-right lanes, as properties over random
//! positions, speeds and roads.

use proptest::prelude::*;
use roads::{
    CLEARANCE_MARGIN_M, LANE_GAP_MARGIN_M, MIN_CLEARANCE_MARGIN_M, NavMode, NavState, Navigator, Restriction,
    Road, RoadLayout,
};
use uav::{Params, Vec2};

/// A winding road: a 2 m wide entry, a tight bend of `turn_deg`, a width change, another bend back.
fn winding(turn_deg: f64, width: f64) -> Road {
    let a = turn_deg.to_radians();
    let p2 = [6.0 + 5.0 * a.cos(), 5.0 * a.sin()];
    let p3 = [p2[0] + 6.0, p2[1]];
    Road::new(RoadLayout::from_centerline(&[[0.0, 0.0], [6.0, 0.0], p2, p3], &[2.0, 2.0, width, width]))
        .unwrap()
}

/// Distance from `x` to the nearest wall (the road's own definition).
fn wall_distance(road: &Road, x: &Vec2) -> f64 {
    road.boundary_distance(x)
}

/// The smallest distance from a point of the straight path a→b to any wall vertex or wall.
fn path_distance_to_walls(road: &Road, a: &Vec2, b: &Vec2) -> f64 {
    road.walls().iter().map(|w| roads::segment_distance(a, b, &w.a, &w.b)).fold(f64::INFINITY, f64::min)
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(3000))]

    /// The straight path to a `traffic` target never comes closer to a wall than the clearance
    /// D_s + v²/(2δ) + margin, or than the nearer of its two ends: in particular it never grazes an
    /// inner vertex, which is what left UAVs hovering at bends. Where no path ahead keeps the full
    /// clearance (a UAV at its lane's edge beside an inner vertex) the floor is D_s + the smaller
    /// margin [`MIN_CLEARANCE_MARGIN_M`].
    #[test]
    fn targets_keep_their_clearance_from_walls_and_vertices(
        turn in 20.0f64..130.0, width in 1.0f64..4.0, along in 0.0f64..1.0, across in -1.0f64..1.0,
        speed in 0.0f64..3.0, heading in 0.0f64..std::f64::consts::TAU,
    ) {
        let road = winding(turn, width);
        let params = Params::default();
        let nav = Navigator::new(&road, NavMode::Traffic, &params);
        let line = road.centerline();
        let s = along * line.length();
        let (right, left) = road.profile().at(s);
        let p = line.point_beside(s, if across >= 0.0 { across * left } else { across * right });
        prop_assume!(wall_distance(&road, &p) > params.d_s);
        let goal = line.point_beside(line.length() - 0.5, 0.0);
        let mut state = NavState::new(p);
        state.set_goal(&road, Some(goal), p);
        let v = Vec2::new(heading.cos(), heading.sin()) * speed;
        let t = nav.target_with(&mut state, p, v, &Restriction::default());
        prop_assert!(road.contains(&t), "target {t:?} outside the road");
        let need = params.d_s + speed * speed / (2.0 * params.delta) + CLEARANCE_MARGIN_M;
        let floor = need.min(params.d_s + MIN_CLEARANCE_MARGIN_M);
        let ends = wall_distance(&road, &p).min(wall_distance(&road, &t));
        let path = path_distance_to_walls(&road, &p, &t);
        prop_assert!(path >= floor.min(ends) - 1e-6, "path {p:?} → {t:?} passes {path:.3} m from a wall (need {need:.3}, ends {ends:.3})");
    }

    /// Keeping to the lane (oncoming traffic): from anywhere in its right lane before a sharp left
    /// bend, a UAV's straight path to its target never enters the bend's inside corner (left of
    /// both centre-line pieces that meet at it), which is the oncoming lane; without the rule the
    /// farthest clear lane point cuts that corner.
    #[test]
    fn keeping_the_lane_never_cuts_a_left_bend_through_the_oncoming_lane(
        turn in 25.0f64..130.0, width in 1.2f64..4.0, before in 0.0f64..3.0, across in 0.0f64..1.0,
        speed in 0.0f64..1.0,
    ) {
        let road = winding(turn, width);
        let params = Params::default();
        let nav = Navigator::new(&road, NavMode::Traffic, &params);
        let line = road.centerline();
        let (points, arc) = (line.points(), line.arc());
        let s = arc[1] - before;
        prop_assume!(nav.two_way_at(arc[1]));
        let lane = nav.lane_offset(s, 1.0, -1.0);
        let p = line.point_beside(s, lane * (0.5 + 0.5 * across));
        let goal = line.point_beside(line.length() - 0.5, 0.0);
        let mut state = NavState::new(p);
        state.set_goal(&road, Some(goal), p);
        let v = line.tangent_at(s) * speed;
        let keep = Restriction { keep_lane: true, ..Restriction::default() };
        let t = nav.target_with(&mut state, p, v, &keep);
        let left_of = |a: Vec2, b: Vec2, x: Vec2| (b - a).x * (x - a).y - (b - a).y * (x - a).x > 1e-9;
        let (a, v_, b) = (points[0], points[1], points[2]);
        for k in 0..=100 {
            let x = p + (t - p) * (k as f64 / 100.0);
            prop_assert!(!(left_of(a, v_, x) && left_of(v_, b, x)), "path {p:?} → {t:?} enters the oncoming lane at {x:?}");
        }
        // Not stuck either: the target is ahead of the UAV.
        prop_assert!((t - p).norm() > 0.05, "target {t:?} beside {p:?}");
    }

    /// Lanes: where both exist, opposite lanes are at least D_c + 2·margin apart and each keeps
    /// D_s + margin from its wall, whatever lateral offset the UAVs are at.
    #[test]
    fn opposite_lanes_are_apart_and_inside(turn in 20.0f64..130.0, width in 1.0f64..4.0, along in 0.0f64..1.0,
                                           lat_a in -2.0f64..2.0, lat_b in -2.0f64..2.0) {
        let road = winding(turn, width);
        let params = Params::default();
        let nav = Navigator::new(&road, NavMode::Traffic, &params);
        let s = along * road.centerline().length();
        prop_assume!(nav.two_way_at(s));
        let (east, west) = (nav.lane_offset(s, 1.0, lat_a), nav.lane_offset(s, -1.0, lat_b));
        prop_assert!(west - east >= params.d_c + 2.0 * LANE_GAP_MARGIN_M - 1e-9, "east {east} west {west}");
        let (right, left) = road.profile().at(s);
        prop_assert!(east >= -(right - params.d_s - CLEARANCE_MARGIN_M) - 1e-9);
        prop_assert!(west <= left - params.d_s - CLEARANCE_MARGIN_M + 1e-9);
    }
}

#[test]
fn a_hold_keeps_the_target_before_the_hold_point() {
    let road = Road::new(RoadLayout::from_centerline(&[[0.0, 0.0], [20.0, 0.0]], &[3.0, 3.0])).unwrap();
    let nav = Navigator::new(&road, NavMode::Traffic, &Params::default());
    let p = Vec2::new(2.0, -0.5);
    let mut state = NavState::new(p);
    state.set_goal(&road, Some(Vec2::new(18.0, 0.0)), p);
    let free = nav.target_with(&mut state, p, Vec2::zeros(), &Restriction::default());
    assert!(free.x > 6.5, "{free:?}");
    // Traffic keeps right: eastbound targets lie south of the centre line.
    assert!(free.y < -0.15 - 0.1 + 1e-9, "{free:?}");
    let held = Restriction { hold_at: Some(4.0), ..Restriction::default() };
    let t = nav.target_with(&mut state, p, Vec2::zeros(), &held);
    assert!((t.x - 4.0).abs() < 1e-9, "{t:?}");
    let away = Vec2::new(1.0, 1.0);
    let backing = Restriction { back_off: Some(away), ..Restriction::default() };
    assert_eq!(nav.target_with(&mut state, p, Vec2::zeros(), &backing), away);
}

#[test]
fn level_with_a_goal_across_a_wide_road_the_target_heads_for_it() {
    // A 12 m wide road: the goal at the far side lies more than r_s across from the lane.
    let road = Road::new(RoadLayout::from_centerline(&[[0.0, 0.0], [20.0, 0.0]], &[12.0, 12.0])).unwrap();
    let params = Params::default();
    let nav = Navigator::new(&road, NavMode::Traffic, &params);
    let (p, goal) = (Vec2::new(10.0, -4.0), Vec2::new(10.05, 4.5));
    let mut state = NavState::new(p);
    state.set_goal(&road, Some(goal), p);
    let t = nav.target_with(&mut state, p, Vec2::zeros(), &Restriction::default());
    // r_s straight towards the goal, not the lane point beside the UAV (where it would hover).
    assert!(((t - p).norm() - nav.r_s).abs() < 1e-9, "{t:?}");
    assert!((t - p).normalize().dot(&(goal - p).normalize()) > 1.0 - 1e-9, "{t:?}");
}

/// The road of a `headon` stress case (seed 166) where a UAV hovered for the rest of the run: it
/// stood at its lane's edge beside an inner vertex, 0.19999 m from the walls, and every lane point
/// ahead passed that vertex a hair closer than the 0.2 m clearance it kept, so its target was its
/// own position.
fn lane_edge_road() -> Road {
    let segments = vec![
        [[8.0, -2.5], [0.0, -2.5], [8.0, 2.5], [0.0, 2.5]],
        [
            [10.037022146093888, -0.4705930807115996],
            [8.0, -2.5],
            [9.962977853906112, 0.4705930807115996],
            [8.0, 2.5],
        ],
        [
            [16.433349317836957, 0.5420886877604669],
            [10.037022146093888, -0.4705930807115996],
            [16.300260329130268, 1.4739267520516406],
            [9.962977853906112, 0.4705930807115996],
        ],
        [
            [22.754537395246373, 1.3473630720719512],
            [16.433349317836957, 0.5420886877604669],
            [22.767927185951415, 2.2978614906289665],
            [16.300260329130268, 1.4739267520516406],
        ],
        [
            [29.117979499255824, 0.3538182841162975],
            [22.754537395246373, 1.3473630720719512],
            [29.142372560467464, 1.3025987264768433],
            [22.767927185951415, 2.2978614906289665],
        ],
        [
            [35.590411305092005, 1.0259488906693426],
            [29.117979499255824, 0.3538182841162975],
            [35.49319646135699, 1.9621009427485514],
            [29.142372560467464, 1.3025987264768433],
        ],
        [
            [37.78933078087593, -0.7860239521386754],
            [35.590411305092005, 1.0259488906693426],
            [37.272882241152345, 4.187232617335433],
            [35.49319646135699, 1.9621009427485514],
        ],
        [
            [45.7465412920345, 0.04029371141905269],
            [37.78933078087593, -0.7860239521386754],
            [45.23009275231092, 5.013550280893162],
            [37.272882241152345, 4.187232617335433],
        ],
    ];
    Road::new(RoadLayout::new(segments)).unwrap()
}

#[test]
fn a_uav_at_its_lane_edge_beside_an_inner_vertex_gets_a_target_ahead() {
    let road = lane_edge_road();
    let params = Params::default();
    let nav = Navigator::new(&road, NavMode::Traffic, &params);
    let goal = Vec2::new(44.72090306575626, 0.23539939764278328);
    for p in [Vec2::new(22.6158, 1.5313), Vec2::new(22.6158, 1.5813), Vec2::new(22.5658, 1.5313)] {
        let mut state = NavState::new(p);
        state.set_goal(&road, Some(goal), p);
        let t = nav.target_with(&mut state, p, Vec2::zeros(), &Restriction::default());
        assert!((t - p).norm() > 0.1, "from {p:?} the target {t:?} is not ahead");
        assert!(
            (goal - t).norm() < (goal - p).norm(),
            "from {p:?} the target {t:?} leads away from the goal"
        );
        let path = path_distance_to_walls(&road, &p, &t);
        assert!(
            path >= params.d_s + MIN_CLEARANCE_MARGIN_M - 1e-6,
            "path {p:?} → {t:?} passes {path:.3} m from a wall"
        );
    }
}
