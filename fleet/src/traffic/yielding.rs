//! Arrived UAVs make way: an arrived UAV that stands in the way of a neighbour still flying to its
//! goal steps aside, then returns to its own goal once the way is clear.
//!
//! Without it, a UAV hovering at its goal can trap another one for good: in a dead-end corner (the
//! lab3 road's closed end, goals 0.4 m from two walls) the CBF rows keep the flying UAV D_c from the
//! hovering one and D_s from the walls, no gap is wide enough, and both stay at rest with every row
//! satisfied (a stationary point of the filtered dynamics, which no barrier can resolve).

use uav::Vec2;

/// Distance (in units of D_c) within which an arrived UAV makes way for a flying neighbour.
pub const YIELD_RADIUS_IN_DC: f64 = 5.0;

/// A neighbour that is still flying: its position and where it is heading now.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Flying {
    /// Position (m).
    pub p: Vec2,
    /// Its temporary target (m): the way it takes along the road, which its goal (across a bend,
    /// say) need not show.
    pub target: Vec2,
}

/// The target of an arrived UAV at `p` (goal `goal`) given flying neighbours `others`: `goal` unless
/// the UAV is within [`YIELD_RADIUS_IN_DC`]·`d_c` of a neighbour whose way to its temporary target
/// points at it (less than 90° off); then a point `d_c` to the side of those neighbours' paths.
pub fn make_way(p: Vec2, goal: Vec2, others: impl Iterator<Item = Flying>, d_c: f64) -> Vec2 {
    let mut side = Vec2::zeros();
    let mut blocking = false;
    for o in others {
        let (to_me, to_target) = (p - o.p, o.target - o.p);
        let (dist, way) = (to_me.norm(), to_target.norm());
        if dist >= YIELD_RADIUS_IN_DC * d_c || dist == 0.0 || way == 0.0 {
            continue;
        }
        let heading = to_target / way;
        let along = to_me.dot(&heading);
        if along <= 0.0 {
            continue;
        }
        blocking = true;
        // Off the neighbour's path, on the side the UAV already is (left of it when exactly on it).
        let off = to_me - heading * along;
        side += if off.norm() > 1e-9 { off / off.norm() } else { Vec2::new(-heading.y, heading.x) };
    }
    if !blocking || side.norm() < 1e-9 {
        return goal;
    }
    p + side * (d_c / side.norm())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn steps_aside_only_for_a_neighbour_heading_past_it() {
        let (p, goal, d_c) = (Vec2::new(0.0, 0.0), Vec2::new(0.0, 0.0), 0.3);
        // A neighbour behind and slightly below, flying to the right through p: step up, off its path.
        let behind = Flying { p: Vec2::new(-0.4, -0.1), target: Vec2::new(0.6, -0.1) };
        let t = make_way(p, goal, [behind].into_iter(), d_c);
        assert!((t - Vec2::new(0.0, d_c)).norm() < 1e-12, "{t:?}");
        // The same neighbour flying away (its target behind it): stay at the goal.
        let away = Flying { target: Vec2::new(-1.4, -0.1), ..behind };
        assert_eq!(make_way(p, goal, [away].into_iter(), d_c), goal);
        // Too far away to matter.
        let far = Flying { p: Vec2::new(-1.6, -0.1), ..behind };
        assert_eq!(make_way(p, goal, [far].into_iter(), d_c), goal);
    }
}
