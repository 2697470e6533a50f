//! The speed limit of the traffic rules: narrower road, slower flight. A queue braking at full δ
//! cannot also give the UAV behind it its share of their pair row (docs/safety.md §10.3), and the
//! `bends` and `bottleneck` stress families showed collision margins a few millimetres below D_c
//! from that; flying slower where the road is narrow keeps the braking terms small enough.
//! The second limit is the distance kept: a UAV closes on each neighbour no faster than it could
//! stop from, braking at δ, well before D_c (the `crowd` family showed blocks pressing into each
//! other at full δ until the filter ran out of input and used slack).

use crate::traffic::following::CROWD_RADIUS_M;
use roads::{ClearanceProfile, PROFILE_STEP_M};
use uav::Vec2;

/// Speed limit (m/s) on a road part of width 0 (the floor of [`speed_limit`]).
pub const BASE_SPEED_MPS: f64 = 0.6;

/// Speed limit added per metre of width (1/s), up to [`FREE_WIDTH_M`].
pub const SPEED_PER_WIDTH: f64 = 0.6;

/// Width (m) from which the limit no longer grows (3 m/s).
pub const FREE_WIDTH_M: f64 = 4.0;

/// The speed limit (m/s) where the road is `width` metres wide.
pub fn speed_limit(width: f64) -> f64 {
    BASE_SPEED_MPS + SPEED_PER_WIDTH * width.clamp(0.0, FREE_WIDTH_M)
}

/// Speed limit (m/s) in dense traffic: where the following rule applies and [`CROWD_AROUND`] or
/// more neighbours are within [`CROWD_RADIUS_M`] (the following rule's crowd radius). Blocks of 40–60 UAVs packed D_c + 0.3 m apart that set off together at the
/// width's limit (up to 3 m/s) pressed into each other where they funnelled, 1–3 cm inside D_c
/// (`headon` family, 4 of 300 cases with `pd`, 11 with `rl`; none with `pd` and 3 with `rl` at this
/// limit, BENCHMARKS.md).
pub const CROWD_SPEED_MPS: f64 = 0.5;

/// Neighbours within [`CROWD_RADIUS_M`] that make a crowd for [`CROWD_SPEED_MPS`].
pub const CROWD_AROUND: usize = 4;

/// The speed limit `limit` of a UAV at `p`, lowered to [`CROWD_SPEED_MPS`] when [`CROWD_AROUND`]
/// of the neighbours at `others` are within [`CROWD_RADIUS_M`].
pub fn crowd_limit(limit: f64, p: Vec2, others: impl Iterator<Item = Vec2>) -> f64 {
    // Counted without stopping at CROWD_AROUND, nor a branch per neighbour (whether one is within
    // the radius is as good as random from neighbour to neighbour): the same answer.
    let close: usize = others.map(|o| usize::from((o - p).norm() < CROWD_RADIUS_M)).sum();
    if close >= CROWD_AROUND { limit.min(CROWD_SPEED_MPS) } else { limit }
}

/// Deceleration (m/s²) at which the look-ahead of [`SpeedProfile`] slows a UAV down before a
/// narrower part: a quarter of δ = 5, so that a queue slowing down together keeps most of δ for
/// its collision rows (docs/safety.md §10.3).
pub const LOOKAHEAD_DECEL: f64 = 1.25;

/// The speed limit along the road for each direction of travel, looking ahead: at every sample it
/// is at most [`speed_limit`] of the width there and of every narrower part ahead, minus what
/// braking at [`LOOKAHEAD_DECEL`] takes off on the way (v² ≤ v_ahead² + 2·a·distance). A block of
/// UAVs flying into a funnel slows down before it, not inside it at full δ (the `headon` family
/// showed queues braking in the funnel, out of input for their pair rows).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct SpeedProfile {
    /// Towards increasing s.
    forward: Vec<f64>,
    /// Towards decreasing s.
    backward: Vec<f64>,
}

impl SpeedProfile {
    /// The profile of a road with clearance `profile`.
    pub fn new(profile: &ClearanceProfile) -> Self {
        let plain: Vec<f64> = profile.widths().map(speed_limit).collect();
        let gain = 2.0 * LOOKAHEAD_DECEL * PROFILE_STEP_M;
        let mut forward = plain.clone();
        for k in (0..forward.len().saturating_sub(1)).rev() {
            forward[k] = forward[k].min((forward[k + 1] * forward[k + 1] + gain).sqrt());
        }
        let mut backward = plain;
        for k in 1..backward.len() {
            backward[k] = backward[k].min((backward[k - 1] * backward[k - 1] + gain).sqrt());
        }
        Self { forward, backward }
    }

    /// The limit (m/s) at arc length `s` for a UAV flying towards increasing s (`direction` > 0)
    /// or decreasing s: the smaller of the two samples around s.
    pub fn at(&self, s: f64, direction: f64) -> f64 {
        let samples = if direction > 0.0 { &self.forward } else { &self.backward };
        let Some(last) = samples.len().checked_sub(1) else { return BASE_SPEED_MPS };
        let k = ((s.max(0.0) / PROFILE_STEP_M).floor() as usize).min(last);
        samples[k].min(samples[(k + 1).min(last)])
    }
}

/// The nominal input `u_ref` changed as little as possible so that the next velocity v + u·dt
/// stays within `limit` (or comes back towards it at up to δ): it only ever takes away speed.
pub fn govern(v: Vec2, u_ref: Vec2, limit: f64, delta: f64, dt: f64) -> Vec2 {
    let next = v + u_ref * dt;
    let speed = next.norm();
    if speed <= limit {
        return u_ref;
    }
    // The nearest velocity within the limit, if δ reaches it; otherwise brake along −v (the fastest
    // way back under the limit).
    let change = (next * (limit / speed) - v) / dt;
    if change.norm() <= delta {
        return change;
    }
    let v_norm = v.norm();
    if v_norm == 0.0 {
        return uav::saturate(u_ref, delta);
    }
    -v / v_norm * ((v_norm - limit).max(0.0) / dt).min(delta)
}

/// Distance (m) beyond D_c that the closing-speed limit of [`keep_distance`] aims to stop at.
pub const KEEP_MARGIN_M: f64 = 0.1;

/// The nominal input `u_ref` of a UAV at velocity `v`, changed so that it closes on a neighbour at
/// offset `rel` (from it to the neighbour) moving at `other_v` no faster than [`closing_limit`]
/// allows, gap = ‖rel‖ − D_c − [`KEEP_MARGIN_M`]. Only the velocity component towards the neighbour
/// is limited (the UAV may still pass beside it), and the result stays within δ.
pub fn keep_distance(v: Vec2, u_ref: Vec2, rel: Vec2, other_v: Vec2, d_c: f64, delta: f64, dt: f64) -> Vec2 {
    let distance = rel.norm();
    if distance <= 1e-9 {
        return u_ref;
    }
    let dir = rel / distance;
    let gap = (distance - d_c - KEEP_MARGIN_M).max(0.0);
    let limit = closing_limit(other_v.dot(&dir), gap, delta);
    govern_along(v, u_ref, dir, limit, delta, dt)
}

/// The highest speed (m/s) towards a neighbour `gap` m away whose own speed away from the UAV is
/// `lead`: for a neighbour standing or coming closer, lead + √(δ·gap) (braking at δ alone, the UAV
/// stops within gap/2 relative to it); for one moving away, √(lead² + δ·gap), so that if it brakes
/// at δ and the UAV does too, the UAV still stops within gap/2 of where it stops. (Plain
/// lead + √(δ·gap) let a UAV tailgate one leaving a section at speed; when that one braked for a
/// crowd, the pair row squeezed it between the two: `headon` with `rl`, BENCHMARKS.md.)
pub fn closing_limit(lead: f64, gap: f64, delta: f64) -> f64 {
    // Both cases in one expression, without a branch on the sign of `lead` (it flips from
    // neighbour to neighbour, and a mispredicted branch stalls the square roots and divisions of
    // the neighbours after it): for lead ≤ 0 the root is √(0 + δ·gap) = √(δ·gap) exactly, and for
    // lead > 0 nothing is added to it, so the limit is the same to the bit.
    let away = lead.max(0.0);
    (away * away + delta * gap).sqrt() + lead.min(0.0)
}

/// `u_ref` changed as little as possible so that the next velocity's component along the unit
/// vector `dir` is at most `limit` (or comes down towards it at up to δ); the rest of `u_ref` is
/// kept as far as δ allows.
fn govern_along(v: Vec2, u_ref: Vec2, dir: Vec2, limit: f64, delta: f64, dt: f64) -> Vec2 {
    let excess = (v + u_ref * dt).dot(&dir) - limit;
    if excess <= 0.0 {
        return u_ref;
    }
    let u = u_ref - dir * (excess / dt);
    if u.norm() <= delta {
        return u;
    }
    let along = u.dot(&dir).max(-delta);
    let across = u - dir * u.dot(&dir);
    let room = (delta * delta - along * along).max(0.0).sqrt();
    let across = if across.norm() > room { across * (room / across.norm()) } else { across };
    dir * along + across
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(3000))]

        /// The governed input never exceeds δ, keeps the next speed within the limit whenever that
        /// is reachable, and never speeds a UAV up beyond what the policy asked.
        #[test]
        fn governed_inputs_respect_the_limit_and_delta(
            vx in -4.0f64..4.0, vy in -4.0f64..4.0, ux in -5.0f64..5.0, uy in -5.0f64..5.0, width in 0.5f64..6.0,
        ) {
            let (v, u_ref, delta, dt) = (Vec2::new(vx, vy), uav::saturate(Vec2::new(ux, uy), 5.0), 5.0, 0.05);
            let limit = speed_limit(width);
            let u = govern(v, u_ref, limit, delta, dt);
            prop_assert!(u.norm() <= delta + 1e-9);
            let next = (v + u * dt).norm();
            if v.norm() <= limit + delta * dt {
                prop_assert!(next <= limit + 1e-9, "next speed {next} over {limit}");
            }
            prop_assert!(next <= (v + u_ref * dt).norm().max(limit) + 1e-9);
        }
    }

    #[test]
    fn a_crowd_lowers_the_limit_only_with_enough_neighbours_close() {
        let p = Vec2::new(0.0, 0.0);
        let ring =
            |r: f64, n: usize| (0..n).map(move |k| Vec2::new(r * (k as f64).cos(), r * (k as f64).sin()));
        assert_eq!(crowd_limit(2.4, p, ring(0.6, CROWD_AROUND)), CROWD_SPEED_MPS);
        assert_eq!(crowd_limit(2.4, p, ring(0.6, CROWD_AROUND - 1)), 2.4);
        assert_eq!(crowd_limit(2.4, p, ring(1.2, 10)), 2.4);
        // Never raises a lower limit.
        assert_eq!(crowd_limit(0.3, p, ring(0.6, 10)), 0.3);
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(3000))]

        /// Keeping distance never exceeds δ, never speeds the UAV up towards its neighbour, leaves a
        /// closing speed within the limit whenever δ can reach it in one tick, and changes nothing
        /// when the UAV is not closing in faster than the limit.
        #[test]
        fn keeping_distance_limits_only_the_closing_speed(
            vx in -4.0f64..4.0, vy in -4.0f64..4.0, ux in -5.0f64..5.0, uy in -5.0f64..5.0,
            rx in -3.0f64..3.0, ry in -3.0f64..3.0, ox in -3.0f64..3.0, oy in -3.0f64..3.0,
        ) {
            let (v, u_ref, rel, other) = (Vec2::new(vx, vy), uav::saturate(Vec2::new(ux, uy), 5.0), Vec2::new(rx, ry), Vec2::new(ox, oy));
            prop_assume!(rel.norm() > 1e-3);
            let (d_c, delta, dt) = (0.3, 5.0, 0.05);
            let u = keep_distance(v, u_ref, rel, other, d_c, delta, dt);
            prop_assert!(u.norm() <= delta + 1e-9);
            let (dir, gap) = (rel / rel.norm(), (rel.norm() - d_c - KEEP_MARGIN_M).max(0.0));
            let (lead, limit) = (other.dot(&dir), closing_limit(other.dot(&dir), gap, delta));
            // From the limit, braking at δ (and the neighbour too, if it moves away), the UAV stops
            // within gap/2 of where the neighbour stops (relative to it, if it does not move away).
            let lead_stop = lead.max(0.0).powi(2) / (2.0 * delta);
            let own_stop = if lead > 0.0 { limit * limit } else { (limit - lead).powi(2) } / (2.0 * delta);
            prop_assert!(own_stop <= lead_stop + gap / 2.0 + 1e-9, "{own_stop} beyond {lead_stop} + {gap}/2");
            let (asked, got) = ((v + u_ref * dt).dot(&dir), (v + u * dt).dot(&dir));
            prop_assert!(got <= asked.max(limit) + 1e-9, "faster towards it: {got} > {asked}");
            if asked <= limit {
                prop_assert!((u - u_ref).norm() < 1e-12);
            } else if v.dot(&dir) <= limit + delta * dt {
                prop_assert!(got <= limit + 1e-9, "closing at {got} over {limit}");
            }
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(3000))]

        /// The branch-free closing limit is the two-case formula of its doc to the bit: a neighbour
        /// moving away gives √(lead² + δ·gap), one standing or coming closer lead + √(δ·gap).
        #[test]
        fn the_closing_limit_is_its_two_cases_to_the_bit(
            lead in prop_oneof![-4.0f64..4.0, Just(0.0), Just(-0.0)], gap in prop_oneof![0.0f64..10.0, Just(0.0)],
            delta in 0.5f64..10.0,
        ) {
            let cases = if lead > 0.0 { (lead * lead + delta * gap).sqrt() } else { lead + (delta * gap).sqrt() };
            prop_assert_eq!(closing_limit(lead, gap, delta).to_bits(), cases.to_bits());
        }
    }

    #[test]
    fn the_limit_comes_down_before_a_narrow_part_in_the_direction_of_travel() {
        // 4 m wide to x = 9, narrowing to 1 m at x = 10, 1 m wide to x = 14, 4 m wide from x = 15.
        let layout = roads::RoadLayout::from_centerline(
            &[[0.0, 0.0], [9.0, 0.0], [10.0, 0.0], [14.0, 0.0], [15.0, 0.0], [24.0, 0.0]],
            &[4.0, 4.0, 1.0, 1.0, 4.0, 4.0],
        );
        let road = roads::Road::new(layout).unwrap();
        let profile = SpeedProfile::new(road.profile());
        let narrow = speed_limit(1.0);
        let far = profile.at(2.0, 1.0);
        assert!((far - speed_limit(4.0)).abs() < 1e-9, "far from the narrow part: {far}");
        // Flying towards it the limit falls to the narrow part's, never faster than a·dt per tick.
        let mut previous = far;
        for k in 0..40 {
            let s = 2.0 + 0.2 * k as f64;
            let limit = profile.at(s, 1.0);
            assert!(limit <= previous + 1e-9);
            previous = limit;
        }
        assert!(profile.at(9.5, 1.0) < speed_limit(2.5));
        // Flying away from it (decreasing s, already behind the UAV) it does not.
        assert!(profile.at(8.0, -1.0) > profile.at(8.0, 1.0) + 0.3);
        assert!(profile.at(16.0, 1.0) > profile.at(16.0, -1.0) + 0.3);
        assert!(
            (profile.at(12.0, 1.0) - narrow).abs() < 1e-9 && (profile.at(12.0, -1.0) - narrow).abs() < 1e-9
        );
    }

    #[test]
    fn narrow_parts_are_slower() {
        assert!(speed_limit(0.9) < speed_limit(2.0) && speed_limit(2.0) < speed_limit(5.0));
        assert_eq!(speed_limit(10.0), speed_limit(FREE_WIDTH_M));
    }
}
