//! The safety margins a run reports: eq. (2) and eq. (6) left sides with the corrected sign (E1).

use crate::tick::rows::RowBuilder;
use roads::{Boundary, Wall};
use safety::barrier::braking_margin;
use safety::wall_braking_margin;
use uav::UavState;

/// S_kd = ‖p_kd‖ − min(v̄_kd, 0)²/(2(δ_k+δ_d)): the closest two UAVs get if both brake now.
pub fn collision_margin(k: &UavState, d: &UavState, delta_sum: f64) -> f64 {
    let p = k.p - d.p;
    let n = p.norm();
    let rate = if n > 0.0 { p.dot(&(k.v - d.v)) / n } else { 0.0 };
    braking_margin(n, rate, delta_sum)
}

/// min over the finite walls of `dist − min(ḋist, 0)²/(2δ)`: the closest the UAV gets to the road
/// boundary if it brakes now. Walls are measured as the filter enforces them (rule R2): a wall's
/// line distance in its slab from either side, its end points as points. Negative distance when outside.
pub fn road_margin(road: &impl Boundary, s: &UavState, delta: f64) -> f64 {
    road_margin_at(road, None, s, delta, road.signed_distance_in(0, &s.p))
}

/// [`road_margin`] for a UAV tracked in segment `hint`, if any: the segment's list of nearby walls
/// instead of the road's tree where it answers (the same value, a fraction of the cost).
pub fn road_margin_in(road: &impl Boundary, hint: Option<usize>, s: &UavState, delta: f64) -> f64 {
    let boundary = road.signed_distance_in(hint.unwrap_or(0), &s.p);
    road_margin_at(road, hint, s, delta, boundary)
}

/// [`road_margin`] given the UAV's signed distance to the boundary `boundary` (the metrics need
/// both) and perhaps the segment or cell it is tracked in (a hint that saves a tree query; same
/// result).
pub fn road_margin_at(
    road: &impl Boundary,
    hint: Option<usize>,
    s: &UavState,
    delta: f64,
    boundary: f64,
) -> f64 {
    // A positive distance is only ever returned inside; at 0 the sign does not tell.
    let inside = boundary > 0.0 || (boundary == 0.0 && road.inside_in(hint.unwrap_or(0), &s.p));
    if !inside {
        return boundary;
    }
    // Walls farther than the reach cannot hold the minimum.
    let walls = road.wall_list();
    let radius = road_margin_reach(s, delta, boundary);
    let mut best = f64::INFINITY;
    for k in road.walls_within(hint.unwrap_or(0), &s.p, radius) {
        best = best.min(wall_margin(&walls[k], s, delta));
    }
    best
}

/// The braking margin of one finite wall as rule R2 enforces it: its line distance in its slab (from
/// either side), its end points as points.
fn wall_margin(w: &Wall, s: &UavState, delta: f64) -> f64 {
    wall_braking_margin(w, w.nearest(&s.p), s.p, s.v, delta)
}

/// Each UAV's margins at the states the last tick read, as its rows stage measured them
/// ([`crate::Fleet::tick_margins`]), by the UAV's index.
#[derive(Clone, Copy)]
pub struct TickMargins<'a> {
    pub(crate) rows: &'a RowBuilder,
}

impl TickMargins<'_> {
    /// UAV k's road margin (eq. 6, [`road_margin_in`]'s value; infinite when there is no UAV k).
    pub fn road(&self, k: usize) -> f64 {
        self.rows.margins(k).map_or(f64::INFINITY, |m| m.road_margin)
    }

    /// UAV k's smallest collision margin S_kd to a neighbour in the air when it is in the air itself
    /// (`Some(None)` without one), as [`collision_margin`] gives it; None when the fleet does not
    /// measure it (`FleetConfig::uav_collision_margins` off).
    pub fn collision(&self, k: usize) -> Option<Option<f64>> {
        self.rows.collision_margin(k)
    }
}

/// One UAV's margins in one tick, as the metrics count them.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct UavMargins {
    /// Distance to the nearest wall (negative outside).
    pub wall: f64,
    /// Its road margin S_kij.
    pub road_margin: f64,
    /// The smallest S_kd and distance to a later neighbour (a higher index), if it has one.
    pub closest: Option<(f64, f64)>,
}

impl UavMargins {
    /// The margins of a UAV with no state (none: every minimum ignores it).
    pub const NONE: UavMargins =
        UavMargins { wall: f64::INFINITY, road_margin: f64::INFINITY, closest: None };

    /// The margins of a UAV at `state` tracked in segment or cell `hint` (any hint gives the same),
    /// against `later`, its neighbours of higher index, in their list's order.
    pub fn of<'a>(
        road: &impl Boundary,
        hint: Option<usize>,
        state: &UavState,
        delta: f64,
        later: impl Iterator<Item = &'a UavState>,
    ) -> UavMargins {
        let wall = road.signed_distance_in(hint.unwrap_or(0), &state.p);
        let road_margin = road_margin_at(road, hint, state, delta, wall);
        UavMargins { wall, road_margin, closest: closest_pair(state, delta, later) }
    }
}

/// The smallest S_kd and the smallest distance between `state` and the UAVs `others` (None when there
/// are none), the pair margin with braking capability `delta` each.
pub(crate) fn closest_pair<'a>(
    state: &UavState,
    delta: f64,
    others: impl Iterator<Item = &'a UavState>,
) -> Option<(f64, f64)> {
    others.fold(None, |closest: Option<(f64, f64)>, other| {
        let (m, sep) = (collision_margin(state, other, 2.0 * delta), (state.p - other.p).norm());
        Some(closest.map_or((m, sep), |(a, b)| (a.min(m), b.min(sep))))
    })
}

/// [`closest_pair`] of UAV k at `state` over its neighbours of higher index, and with it the smallest
/// S_kd to any neighbour in the air when k is in the air (the snapshot's `collision_margin_m`), in
/// one pass that measures each pair once: `neighbours` gives each one's index, state and whether it
/// is in the air. The smallest of equal zeros is −0 (a total order, as `min_by(f64::total_cmp)`).
pub(crate) fn pair_margins<'a>(
    (k, state, in_the_air): (usize, &UavState, bool),
    delta: f64,
    neighbours: impl Iterator<Item = (usize, &'a UavState, bool)>,
) -> (Option<(f64, f64)>, Option<f64>) {
    let (mut closest, mut nearest): (Option<(f64, f64)>, Option<f64>) = (None, None);
    for (d, other, other_in_the_air) in neighbours {
        let (later, both_in_the_air) = (d > k, in_the_air && other_in_the_air);
        if !later && !both_in_the_air {
            continue;
        }
        let m = collision_margin(state, other, 2.0 * delta);
        if later {
            let sep = (state.p - other.p).norm();
            closest = Some(closest.map_or((m, sep), |(a, b)| (a.min(m), b.min(sep))));
        }
        if both_in_the_air {
            nearest = Some(nearest.map_or(m, |n| std::cmp::min_by(n, m, f64::total_cmp)));
        }
    }
    (closest, nearest)
}

/// The radius beyond which no wall holds the road margin of a UAV at `s` at distance `boundary` > 0
/// from the road's boundary: a wall at distance d has a margin of at least d − v²/(2δ), and the
/// nearest wall's is at most its distance (with room for rounding).
pub(crate) fn road_margin_reach(s: &UavState, delta: f64, boundary: f64) -> f64 {
    boundary + s.v.norm_squared() / (2.0 * delta) + 1e-9 * (1.0 + boundary)
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;
    use roads::Road;
    use uav::Vec2;

    /// `road_margin` as a loop over every wall.
    fn road_margin_scan(road: &Road, s: &UavState, delta: f64) -> f64 {
        if !road.contains(&s.p) {
            return road.boundary_distance(&s.p);
        }
        road.walls().iter().map(|w| wall_margin(w, s, delta)).fold(f64::INFINITY, f64::min)
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(2000))]

        /// The margin over the nearby walls equals the one over every wall, bit for bit, on a winding
        /// road, anywhere around it and at any speed.
        #[test]
        fn road_margin_over_nearby_walls_equals_the_scan(
            turns in proptest::collection::vec(-0.8f64..0.8, 3..30),
            width in 0.5f64..4.0,
            (u, w) in (0.0f64..1.0, 0.0f64..1.0),
            (vx, vy) in (-12.0f64..12.0, -12.0f64..12.0),
        ) {
            let mut points = vec![[0.0, 0.0]];
            let mut heading = 0.0f64;
            for t in &turns {
                heading += t;
                let [x, y] = points[points.len() - 1];
                points.push([x + 4.0 * heading.cos(), y + 4.0 * heading.sin()]);
            }
            let Ok(road) = Road::new(roads::RoadLayout::from_centerline(&points, &vec![width; points.len()])) else {
                return Ok(());
            };
            let q = &road.quads()[((u * road.quads().len() as f64) as usize).min(road.quads().len() - 1)];
            let p = q.centroid() + (q.p[((w * 4.0) as usize).min(3)] - q.centroid()) * (1.2 * w);
            let state = UavState { p, v: Vec2::new(vx, vy) };
            let (got, want) = (road_margin(&road, &state, 5.0), road_margin_scan(&road, &state, 5.0));
            prop_assert_eq!(got.to_bits(), want.to_bits(), "at {:?}: {} vs {}", p, got, want);
            // With any segment as the hint (right or wrong), the same distance and margin.
            let boundary = road.boundary_distance(&p);
            for hint in [0, road.quads().len() / 2, road.locate(&p, None), road.quads().len()] {
                prop_assert_eq!(road.boundary_distance_in(hint, &p).to_bits(), boundary.to_bits());
                let hinted = road_margin_at(&road, Some(hint), &state, 5.0, boundary);
                prop_assert_eq!(hinted.to_bits(), want.to_bits(), "hint {} at {:?}", hint, p);
                prop_assert_eq!(road_margin_in(&road, Some(hint), &state, 5.0).to_bits(), want.to_bits());
            }
        }
    }
}
