//! Validation rules, each named with its segment, and the derived geometry of valid roads.

use roads::{Road, RoadLayout, RoadRule, WallKind};
use uav::Vec2;

fn l_bend() -> RoadLayout {
    // East 10 m, then north 10 m, 2 m wide, mitre joint at (10, 0).
    RoadLayout::from_centerline(&[[0.0, 0.0], [10.0, 0.0], [10.0, 10.0]], &[2.0, 2.0, 2.0])
}

fn rule_of(layout: RoadLayout) -> (Option<usize>, RoadRule) {
    let e = Road::new(layout).expect_err("layout must be rejected");
    (e.segment, e.rule)
}

#[test]
fn straight_and_bent_roads_are_valid_with_walls_caps_and_centre_line() {
    let road = Road::new(RoadLayout::straight(0.0, 30.0, 3.0, 3)).unwrap();
    assert_eq!(road.walls().len(), 2 * 3 + 2);
    assert_eq!(
        road.walls().iter().filter(|w| matches!(w.kind, WallKind::EntryCap | WallKind::ExitCap)).count(),
        2
    );
    assert!((road.centerline().length() - 30.0).abs() < 1e-12);
    assert!(road.contains(&Vec2::new(15.0, 1.4)));
    assert!(!road.contains(&Vec2::new(15.0, 1.6)));
    assert!(!road.contains(&Vec2::new(-0.1, 0.0)));
    assert!((road.boundary_distance(&Vec2::new(15.0, 1.0)) - 0.5).abs() < 1e-12);
    assert!((road.boundary_distance(&Vec2::new(0.2, 0.0)) - 0.2).abs() < 1e-12, "entry cap is a wall");

    let bend = Road::new(l_bend()).unwrap();
    assert!((bend.centerline().length() - 20.0).abs() < 1e-12);
    assert!(bend.contains(&Vec2::new(10.9, 10.0)));
    assert!(bend.contains(&Vec2::new(10.9, -0.9)), "outer corner of the mitre joint");
    assert!(!bend.contains(&Vec2::new(8.0, 8.0)));
}

#[test]
fn every_rule_names_its_segment() {
    assert_eq!(rule_of(RoadLayout::new(vec![])), (None, RoadRule::Empty));

    let mut nan = RoadLayout::straight(0.0, 30.0, 3.0, 3);
    nan.segments[1][2][0] = f64::NAN;
    assert_eq!(rule_of(nan), (Some(1), RoadRule::NonFinite));

    let mut huge = RoadLayout::straight(0.0, 30.0, 3.0, 3);
    huge.segments[2][0][1] = 1e9;
    assert_eq!(rule_of(huge), (Some(2), RoadRule::AbsurdCoordinate));

    let mut degenerate = RoadLayout::straight(0.0, 30.0, 3.0, 1);
    degenerate.segments[0][0] = degenerate.segments[0][2];
    assert_eq!(rule_of(degenerate), (Some(0), RoadRule::DegenerateEdge));

    // Swapping p3 and p4 turns the quad (p1, p2, p4, p3) into a bow-tie.
    let mut bowtie = RoadLayout::straight(0.0, 30.0, 3.0, 3);
    bowtie.segments[1].swap(2, 3);
    let (seg, rule) = rule_of(bowtie);
    assert_eq!(rule, RoadRule::NotConvex);
    assert_eq!(seg, Some(1));

    let mut broken = RoadLayout::straight(0.0, 30.0, 3.0, 3);
    broken.segments[2][1][0] += 0.01;
    broken.segments[2][3][0] += 0.01;
    assert_eq!(rule_of(broken), (Some(2), RoadRule::SeamlessJoin));

    // Segment 1 mirrored back over the shared edge x = 10.
    let mut folded = RoadLayout::straight(0.0, 20.0, 3.0, 2);
    folded.segments[1][0][0] = 0.0;
    folded.segments[1][2][0] = 0.0;
    assert_eq!(rule_of(folded), (Some(1), RoadRule::FoldsBack));

    // A spiral that runs back across its own start.
    let spiral = RoadLayout::from_centerline(
        &[[0.0, 0.0], [10.0, 0.0], [10.0, 6.0], [4.0, 6.0], [4.0, -6.0]],
        &[2.0, 2.0, 2.0, 2.0, 2.0],
    );
    let (seg, rule) = rule_of(spiral);
    assert_eq!(rule, RoadRule::Overlap);
    assert_eq!(seg, Some(3));
}

#[test]
fn error_messages_name_segment_and_rule() {
    let mut nan = RoadLayout::straight(0.0, 30.0, 3.0, 3);
    nan.segments[1][2][0] = f64::INFINITY;
    let msg = Road::new(nan).unwrap_err().to_string();
    assert!(msg.starts_with("segments[1] (non_finite): p3"), "{msg}");
}

#[test]
fn layout_json_rejects_unknown_keys_and_round_trips() {
    let layout = l_bend();
    let json = serde_json::to_string(&layout).unwrap();
    assert_eq!(serde_json::from_str::<RoadLayout>(&json).unwrap(), layout);
    assert!(serde_json::from_str::<RoadLayout>(r#"{"segments": [], "extra": 1}"#).is_err());
}

#[test]
fn membership_keeps_the_previous_segment_on_the_shared_edge() {
    let road = Road::new(RoadLayout::straight(0.0, 20.0, 2.0, 2)).unwrap();
    let on_joint = Vec2::new(10.0, 0.0);
    assert_eq!(road.locate(&on_joint, Some(0)), 0);
    assert_eq!(road.locate(&on_joint, Some(1)), 1);
    assert_eq!(road.locate(&Vec2::new(10.5, 0.0), Some(0)), 1);
    assert_eq!(road.locate(&Vec2::new(25.0, 0.0), None), 1, "outside: largest margin");
}

#[test]
fn visibility_is_blocked_by_the_inner_corner() {
    let road = Road::new(l_bend()).unwrap();
    assert!(road.visible(&Vec2::new(2.0, 0.0), &Vec2::new(9.0, 0.5)));
    assert!(!road.visible(&Vec2::new(2.0, 0.0), &Vec2::new(10.0, 8.0)));
}

#[test]
fn halfplane_rule_adds_only_convex_corner_neighbours() {
    let road = Road::new(l_bend()).unwrap();
    // In segment 0 (eastbound) the outer wall of segment 1 (x = 11) meets it at a convex corner and
    // bounds all of segment 0; the inner wall of segment 1 (x = 9) would cut segment 0 and is excluded.
    let set = road.halfplane_walls(0);
    let xs: Vec<f64> = set
        .iter()
        .map(|&k| road.walls()[k])
        .filter(|w| w.segment == 1 && matches!(w.kind, WallKind::Side21 | WallKind::Side43))
        .map(|w| w.a.x)
        .collect();
    assert_eq!(xs, vec![11.0]);
    assert!(
        set.iter().any(|&k| road.walls()[k].kind == WallKind::ExitCap),
        "the exit cap bounds segment 0 too"
    );
}

/// A road of [`roads::MAX_SEGMENTS`] segments (200 km in 20 m pieces: the trunk of `bench scale` for
/// 100,000 UAVs needs 6,000) is accepted; one more is refused with `too_many_segments`.
#[test]
fn the_longest_road_accepted_has_max_segments() {
    let longest = RoadLayout::straight(0.0, 20.0 * roads::MAX_SEGMENTS as f64, 12.0, roads::MAX_SEGMENTS);
    let road = Road::new(longest).expect("a road of MAX_SEGMENTS segments is valid");
    assert_eq!(road.quads().len(), roads::MAX_SEGMENTS);
    let too_long =
        RoadLayout::straight(0.0, 20.0 * (roads::MAX_SEGMENTS + 1) as f64, 12.0, roads::MAX_SEGMENTS + 1);
    assert_eq!(rule_of(too_long), (None, RoadRule::TooManySegments));
}
