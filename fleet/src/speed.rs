//! The speed limit of the traffic rules: narrower road, slower flight. A queue braking at full δ
//! cannot also give the UAV behind it its share of their pair row (docs/safety.md §10.3), and the
//! `bends` and `bottleneck` stress families showed collision margins a few millimetres below D_c
//! from that; flying slower where the road is narrow keeps the braking terms small enough.

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
    fn narrow_parts_are_slower() {
        assert!(speed_limit(0.9) < speed_limit(2.0) && speed_limit(2.0) < speed_limit(5.0));
        assert_eq!(speed_limit(10.0), speed_limit(FREE_WIDTH_M));
    }
}
