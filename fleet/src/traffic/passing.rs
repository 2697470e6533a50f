//! Passing parked UAVs: a UAV flying to its goal whose straight way to its temporary target runs
//! into an arrived UAV aims beside it, on the side away from it where the road has room.
//!
//! An arrived UAV makes way ([`crate::traffic::yielding`]) by stepping off the flying UAV's path, on the side
//! it already is. Against a wall it cannot step: the flying UAV, aiming through it, kept D_c from it
//! and stayed behind it (`mixed` seed 13 with `rl`: 55 s behind a UAV parked in its lane, in a road
//! 2.8 m wide). Passing on the side away from the parked UAV agrees with the side the parked UAV
//! steps to, so the two never dodge into each other. The fleet passes only arrived UAVs whose
//! way-making point lacks the clearance of a path (D_s + 0.1 m): where the parked UAV can step
//! aside, swerving as well only cost time (`mixed` with `pd`: 299 → 297 of 300 held-out cases).

use uav::Vec2;

/// How far ahead (in units of D_c) along the way to its target a parked UAV blocks a flying one.
pub const PASS_LOOKAHEAD_IN_DC: f64 = 4.0;

/// Lateral distance (m) beyond D_c at which the flying UAV passes a parked one.
pub const PASS_MARGIN_M: f64 = 0.15;

/// How far ahead (m) a parked foreign UAV ([`crate::traffic::foreign`]) blocks a flying one, and
/// how far beside it (m) the flying one passes: the filter keeps a UAV much farther from a foreign
/// UAV at rest than from one of its own fleet (the foreign one may accelerate at δ towards it at any
/// moment, so its reach disk grows at δ even on a fresh message: 1.5–2 m as a UAV creeps up).
pub const FOREIGN_PASS: Pass = Pass { ahead_m: 3.0, beside_m: 1.5 };

/// How far ahead a parked UAV blocks a flying one, and how far beside it the flying one passes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pass {
    /// Blocking when at most this far ahead (m) along the way.
    pub ahead_m: f64,
    /// Blocking when less than this far (m) off the way; passed this far to its side.
    pub beside_m: f64,
}

/// The point a flying UAV at `p` aims at instead of `target` to pass the nearest of `parked` that
/// blocks its straight way (ahead within [`PASS_LOOKAHEAD_IN_DC`]·`d_c`, less than `d_c` +
/// [`PASS_MARGIN_M`] off it): `d_c` past it and `d_c` + [`PASS_MARGIN_M`] to the side away from it,
/// or to the other side when `clear(from, to)` rejects the way there or on to `target`. `None` when
/// nothing blocks the way or neither side is clear.
pub fn pass_point(
    p: Vec2,
    target: Vec2,
    parked: impl Iterator<Item = Vec2>,
    d_c: f64,
    clear: impl Fn(Vec2, Vec2) -> bool,
) -> Option<Vec2> {
    let pass = Pass { ahead_m: PASS_LOOKAHEAD_IN_DC * d_c, beside_m: d_c + PASS_MARGIN_M };
    pass_point_with(p, target, parked, d_c, pass, clear)
}

/// [`pass_point`] with the blocking distances and the distance beside of `pass`.
pub fn pass_point_with(
    p: Vec2,
    target: Vec2,
    parked: impl Iterator<Item = Vec2>,
    d_c: f64,
    pass: Pass,
    clear: impl Fn(Vec2, Vec2) -> bool,
) -> Option<Vec2> {
    let way = target - p;
    let length = way.norm();
    if length < 1e-9 {
        return None;
    }
    let heading = way / length;
    let lateral = pass.beside_m;
    let reach = pass.ahead_m.min(length + d_c);
    let (mut nearest, mut blocker) = (f64::INFINITY, None);
    for q in parked {
        let to_q = q - p;
        let along = to_q.dot(&heading);
        let off = to_q - heading * along;
        if along > 0.0 && along <= reach && off.norm() < lateral && along < nearest {
            (nearest, blocker) = (along, Some((q, off)));
        }
    }
    let (q, off) = blocker?;
    // Away from the parked UAV: the side opposite its offset (right of the way when it sits on it).
    let away = if off.norm() > 1e-9 { -off / off.norm() } else { Vec2::new(heading.y, -heading.x) };
    for side in [away, -away] {
        let c = q + side * lateral + heading * d_c;
        if !(clear(p, c) && clear(c, target)) {
            continue;
        }
        // As far out as the target was, so the policy does not slow down for a near point.
        let to_c = c - p;
        let far = p + to_c * (length / to_c.norm()).max(1.0);
        return Some(if clear(p, far) && clear(far, target) { far } else { c });
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    const D_C: f64 = 0.3;

    fn open(_: Vec2, _: Vec2) -> bool {
        true
    }

    #[test]
    fn passes_on_the_side_away_from_a_parked_uav_in_the_way() {
        let (p, target) = (Vec2::new(0.0, 0.0), Vec2::new(0.0, 3.0));
        let parked = Vec2::new(0.05, 0.6);
        let c = pass_point(p, target, [parked].into_iter(), D_C, open).expect("blocked");
        assert!(c.x < parked.x - D_C, "passes on the left, away from it: {c:?}");
        assert!(c.y > parked.y, "aims past it: {c:?}");
    }

    #[test]
    fn takes_the_other_side_when_the_first_has_no_room() {
        let (p, target) = (Vec2::new(0.0, 0.0), Vec2::new(0.0, 3.0));
        let parked = Vec2::new(0.05, 0.6);
        let wall_on_the_left = |a: Vec2, b: Vec2| a.x > -0.2 && b.x > -0.2;
        let c =
            pass_point(p, target, [parked].into_iter(), D_C, wall_on_the_left).expect("right side is clear");
        assert!(c.x > parked.x + D_C, "{c:?}");
        let walls_both_sides = |a: Vec2, b: Vec2| a.x.abs() < 0.2 && b.x.abs() < 0.2;
        assert_eq!(pass_point(p, target, [parked].into_iter(), D_C, walls_both_sides), None);
    }

    #[test]
    fn ignores_uavs_behind_beside_or_far_ahead() {
        let (p, target) = (Vec2::new(0.0, 0.0), Vec2::new(0.0, 3.0));
        let others = [Vec2::new(0.0, -0.5), Vec2::new(0.6, 0.5), Vec2::new(0.0, 2.0)];
        assert_eq!(pass_point(p, target, others.into_iter(), D_C, open), None);
    }

    #[test]
    fn passes_the_nearest_of_several() {
        let (p, target) = (Vec2::new(0.0, 0.0), Vec2::new(0.0, 3.0));
        let (near, far) = (Vec2::new(-0.1, 0.5), Vec2::new(0.1, 1.0));
        let c = pass_point(p, target, [far, near].into_iter(), D_C, open).expect("blocked");
        // Towards D_c past the nearer one, to its right, as far out as the target was.
        let beside = near + Vec2::new(D_C + PASS_MARGIN_M, D_C);
        assert!((c.normalize() - beside.normalize()).norm() < 1e-12, "{c:?}");
        assert!((c.norm() - target.norm()).abs() < 1e-12, "{c:?}");
    }

    #[test]
    fn aims_at_the_point_beside_when_the_farther_way_is_not_clear() {
        let (p, target) = (Vec2::new(0.0, 0.0), Vec2::new(0.0, 3.0));
        let parked = Vec2::new(0.05, 0.6);
        let short = |a: Vec2, b: Vec2| a.norm().max(b.norm()) < 1.5 || (b - target).norm() < 1e-12;
        let c = pass_point(p, target, [parked].into_iter(), D_C, short).expect("the near point is clear");
        assert!((c - (parked + Vec2::new(-(D_C + PASS_MARGIN_M), D_C))).norm() < 1e-9, "{c:?}");
    }
}
