//! Navigation targets: route (road-aware) reaches goals around bends where literal Algorithm 1 stalls.

use roads::{NavMode, NavState, Navigator, Road, RoadLayout};
use uav::Vec2;

fn u_turn() -> Road {
    Road::new(RoadLayout::from_centerline(
        &[[0.0, 0.0], [12.0, 0.0], [12.0, 8.0], [0.0, 8.0]],
        &[3.0, 3.0, 3.0, 3.0],
    ))
    .unwrap()
}

/// Moves a point at most `speed·dt` towards its target each step, refusing any step that would leave the
/// road (a crude stand-in for the safety filter); returns the steps taken to reach the goal, if ever.
fn fly(road: &Road, mode: NavMode, start: Vec2, goal: Vec2) -> Option<usize> {
    let nav = Navigator::new(road, mode, &uav::Params::default());
    let mut state = NavState::new(start);
    state.set_goal(road, Some(goal), start);
    let mut p = start;
    for step in 0..4000 {
        let target = nav.target(&mut state, p);
        if state.arrived {
            return Some(step);
        }
        let d = target - p;
        let next = p + d * (0.1 / d.norm().max(0.1));
        if road.boundary_distance(&next) > 0.0 {
            p = next;
        }
    }
    None
}

#[test]
fn route_reaches_a_goal_around_two_bends() {
    let road = u_turn();
    let steps = fly(&road, NavMode::Route, Vec2::new(1.0, -0.5), Vec2::new(1.0, 8.5));
    assert!(steps.is_some(), "route navigation must reach the goal");
}

#[test]
fn literal_alg1_dead_locks_against_the_wall_erratum_e8() {
    let road = u_turn();
    assert_eq!(fly(&road, NavMode::Alg1, Vec2::new(1.0, -0.5), Vec2::new(1.0, 8.5)), None);
}

#[test]
fn route_target_is_visible_and_within_r_s() {
    let road = u_turn();
    let nav = Navigator::new(&road, NavMode::Route, &uav::Params::default());
    for x in [0.5, 3.0, 6.0, 9.0, 11.5] {
        let p = Vec2::new(x, 0.7);
        let mut state = NavState::new(p);
        state.set_goal(&road, Some(Vec2::new(1.0, 8.0)), p);
        let t = nav.target(&mut state, p);
        assert!(road.visible(&p, &t), "target {t:?} from {p:?} must be visible");
        assert!(
            (t - p).norm() <= 5.0 + 1.5 + 1e-9,
            "target at most r_s of arc ahead (plus the lateral offset)"
        );
        assert!(t.x > p.x || t.y > 0.0, "target moves along the road towards the goal");
    }
}

#[test]
fn arrived_uav_hovers_at_its_goal_and_clearing_the_goal_hovers_in_place() {
    let road = u_turn();
    let nav = Navigator::new(&road, NavMode::Route, &uav::Params::default());
    let goal = Vec2::new(5.0, 0.0);
    let mut state = NavState::new(Vec2::new(4.95, 0.0));
    state.set_goal(&road, Some(goal), Vec2::new(4.95, 0.0));
    assert_eq!(nav.target(&mut state, Vec2::new(4.95, 0.0)), goal);
    assert!(state.arrived);
    // Pushed away by a neighbour: still arrived, still hovering at the goal.
    assert_eq!(nav.target(&mut state, Vec2::new(6.0, 1.0)), goal);
    state.set_goal(&road, None, Vec2::new(6.0, 1.0));
    assert_eq!(nav.target(&mut state, Vec2::new(6.2, 1.0)), Vec2::new(6.0, 1.0));
}
