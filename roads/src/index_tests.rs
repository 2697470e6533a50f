//! The indexed queries of [`Road`] give exactly what the linear scans give (bit for bit, ties
//! included), and the indexed overlap check and R3 wall sets match the all-pairs versions, on
//! thousands of random roads and points: inside, outside, far away, on walls, on vertices and
//! within rounding distance of them.

use crate::geometry::Quad;
use crate::layout::RoadLayout;
use crate::road::{Road, halfplane_set_scan};
use crate::validate::{check_joins, check_overlaps, check_overlaps_pairwise, check_quads};
use proptest::prelude::*;
use uav::Vec2;

/// A random road: a polyline of `pieces` (length, turn, width) from `origin` heading `heading`.
fn layout(origin: (f64, f64), heading: f64, pieces: &[(f64, f64, f64)]) -> RoadLayout {
    let mut points = vec![[origin.0, origin.1]];
    let mut widths = vec![pieces.first().map_or(1.0, |p| p.2)];
    let mut angle = heading;
    for &(len, turn, width) in pieces {
        angle += turn;
        let last = points[points.len() - 1];
        points.push([last[0] + len * angle.cos(), last[1] + len * angle.sin()]);
        widths.push(width);
    }
    RoadLayout::from_centerline(&points, &widths)
}

/// Up to `max` pieces (length, turn, width) with turns below `max_turn`: a road width of 0.2 to 4 m
/// varying by up to ±20 % per vertex, pieces 0.6 to 6 widths long, so that most roads are valid.
fn pieces(max: usize, max_turn: f64) -> impl Strategy<Value = Vec<(f64, f64, f64)>> {
    let piece = (0.6f64..6.0, -max_turn..max_turn, 0.8f64..1.2);
    (0.2f64..4.0, proptest::collection::vec(piece, 1..max))
        .prop_map(|(w, v)| v.into_iter().map(|(len, turn, f)| (len * w, turn, f * w)).collect())
}

/// Query points around `road`: (kind, u, v, tiny) pick a point in its bounding box, on a wall, at
/// a vertex, or far away, nudged by `tiny` (down to rounding distance).
fn point(road: &Road, kind: u8, u: f64, v: f64, tiny: f64) -> Vec2 {
    let quads = road.quads();
    let walls = road.walls();
    let (lo, hi) = quads
        .iter()
        .flat_map(|q| q.p)
        .fold((Vec2::repeat(f64::INFINITY), Vec2::repeat(f64::NEG_INFINITY)), |(lo, hi), p| {
            (lo.inf(&p), hi.sup(&p))
        });
    let nudge = Vec2::new(tiny * (v - 0.5).signum(), tiny * (u - 0.5).signum());
    match kind % 6 {
        0 | 1 => {
            let margin = (hi - lo) * 0.2 + Vec2::repeat(1.0);
            let (a, b) = (lo - margin, hi + margin);
            Vec2::new(a.x + (b.x - a.x) * u, a.y + (b.y - a.y) * v)
        }
        2 => {
            let w = &walls[((u * walls.len() as f64) as usize).min(walls.len() - 1)];
            w.a + (w.b - w.a) * v + nudge
        }
        3 => {
            let q = &quads[((u * quads.len() as f64) as usize).min(quads.len() - 1)];
            q.p[((v * 4.0) as usize).min(3)] + nudge
        }
        4 => {
            let q = &quads[((u * quads.len() as f64) as usize).min(quads.len() - 1)];
            q.centroid() + (q.p[((v * 4.0) as usize).min(3)] - q.centroid()) * (0.5 + v) + nudge
        }
        _ => lo + (Vec2::new(u, v) - Vec2::repeat(0.5)) * 1e4 * (1.0 + tiny * 1e9),
    }
}

/// Every query equals its scan at `x`.
fn same_answers(road: &Road, x: &Vec2) -> Result<(), TestCaseError> {
    prop_assert_eq!(road.contains(x), road.contains_scan(x), "contains at {:?}", x);
    prop_assert_eq!(road.locate(x, None), road.best_margin_scan(x), "locate at {:?}", x);
    prop_assert_eq!(road.nearest_wall(x), road.nearest_wall_scan(x), "nearest wall at {:?}", x);
    let d = road.wall_distance_scan(x);
    let reference = if road.contains_scan(x) { d } else { -d };
    prop_assert_eq!(road.boundary_distance(x).to_bits(), reference.to_bits(), "boundary distance at {:?}", x);
    // The walls near x hold every wall within the radius, ascending; visibility equals the scan.
    let walls = road.walls();
    let hints = [0, road.quads().len() / 2, road.locate(x, None)];
    for radius in [0.0, 0.05, 0.7, 3.0, 7.9] {
        let lists = std::iter::once(road.walls_near(x, radius))
            .chain(hints.map(|h| road.walls_near_in(h, x, radius)));
        for near in lists {
            let near: Vec<usize> = near.collect();
            prop_assert!(near.windows(2).all(|w| w[0] < w[1]), "not ascending: {:?}", near);
            for (k, w) in walls.iter().enumerate() {
                if (w.nearest(x).0 - x).norm() <= radius {
                    prop_assert!(near.contains(&k), "wall {} within {} of {:?} missing", k, radius, x);
                }
            }
        }
    }
    for hint in hints {
        let (got, want) = (road.boundary_distance_in(hint, x), reference);
        prop_assert_eq!(got.to_bits(), want.to_bits(), "boundary distance with hint {} at {:?}", hint, x);
    }
    for hint in hints.into_iter().chain([road.quads().len()]) {
        prop_assert_eq!(
            road.contains_in(hint, x),
            road.contains_scan(x),
            "contains with hint {} at {:?}",
            hint,
            x
        );
    }
    let some = [0, walls.len() / 3, walls.len() / 2, walls.len() - 1];
    for w in some.iter().map(|&k| &walls[k]) {
        for y in [w.a, (w.a + w.b) / 2.0, road.quads()[w.segment].centroid()] {
            prop_assert_eq!(road.visible(x, &y), road.visible_scan(x, &y), "visible {:?} -> {:?}", x, y);
        }
    }
    Ok(())
}

type Sample = (u8, f64, f64, f64);

fn samples() -> impl Strategy<Value = Vec<Sample>> {
    let tiny = prop_oneof![Just(0.0), 1e-15f64..1e-12, 1e-10f64..1e-8, 1e-6f64..1e-3];
    proptest::collection::vec((any::<u8>(), 0.0f64..=1.0, 0.0f64..=1.0, tiny), 60)
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(3000))]

    #[test]
    fn indexed_queries_equal_the_scans(
        origin in (-1e3f64..1e3, -1e3f64..1e3),
        heading in -3.2f64..3.2,
        pieces in pieces(40, 1.4),
        points in samples(),
    ) {
        let Ok(road) = Road::new(layout(origin, heading, &pieces)) else { return Ok(()) };
        for (kind, u, v, tiny) in points {
            same_answers(&road, &point(&road, kind, u, v, tiny))?;
        }
        for i in 0..road.quads().len() {
            prop_assert_eq!(road.halfplane_walls(i), &halfplane_set_scan(road.quads(), road.walls(), i)[..]);
        }
    }

    #[test]
    fn indexed_queries_equal_the_scans_far_from_the_origin(
        origin in (-9.9e5f64..9.9e5, -9.9e5f64..9.9e5),
        heading in -3.2f64..3.2,
        pieces in pieces(12, 1.2),
        points in samples(),
    ) {
        let Ok(road) = Road::new(layout(origin, heading, &pieces)) else { return Ok(()) };
        for (kind, u, v, tiny) in points {
            same_answers(&road, &point(&road, kind, u, v, tiny))?;
        }
    }

    #[test]
    fn indexed_overlap_check_equals_all_pairs(
        heading in -3.2f64..3.2,
        pieces in pieces(60, 2.0),
    ) {
        let layout = layout((0.0, 0.0), heading, &pieces);
        let Ok(quads) = check_quads(&layout.segments) else { return Ok(()) };
        if check_joins(&quads).is_err() {
            return Ok(());
        }
        prop_assert_eq!(check_overlaps(&quads), check_overlaps_pairwise(&quads));
    }
}

/// Spirals overlap themselves after a turn; both checks name the same first pair.
#[test]
fn overlapping_spirals_are_reported_alike() {
    let mut overlaps = 0;
    for turns in 3..40 {
        let pieces: Vec<(f64, f64, f64)> =
            (0..60).map(|k| (2.0, 0.1 * turns as f64 + 0.001 * k as f64, 1.5)).collect();
        let layout = layout((0.0, 0.0), 0.0, &pieces);
        let Ok(quads) = check_quads(&layout.segments) else { continue };
        let indexed = check_overlaps(&quads);
        overlaps += usize::from(indexed.is_err());
        assert_eq!(indexed, check_overlaps_pairwise(&quads), "{turns}");
    }
    assert!(overlaps > 10, "{overlaps} spirals overlapped");
}

/// The largest road accepted, queried on a grid and on every vertex.
#[test]
fn a_road_of_two_thousand_segments_answers_like_the_scans() {
    let pieces: Vec<(f64, f64, f64)> =
        (0..2000).map(|k| (3.0 + (k % 7) as f64 * 0.3, if k % 2 == 0 { 0.5 } else { -0.5 }, 2.0)).collect();
    let road = Road::new(layout((0.0, 0.0), 0.0, &pieces)).expect("a valid zigzag");
    assert_eq!(road.quads().len(), 2000);
    let mut points: Vec<Vec2> = road.quads().iter().flat_map(|q: &Quad| q.p).collect();
    for k in 0..4000 {
        let q = &road.quads()[k % 2000];
        points.push(q.centroid() + Vec2::new((k % 13) as f64 * 0.2 - 1.3, (k % 11) as f64 * 0.3 - 1.5));
    }
    points.extend([Vec2::new(1e13, 0.0), Vec2::new(f64::NAN, 0.0), Vec2::new(f64::INFINITY, f64::INFINITY)]);
    for x in &points {
        same_answers(&road, x).unwrap();
    }
}
