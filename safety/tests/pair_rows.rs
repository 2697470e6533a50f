//! The pair row with the linear class-K term (docs/safety.md §10.7) in closed loop: two UAVs pushed
//! at full input δ in random directions (towards each other among them), each filtering its share of
//! the pair row with the real filter, keep D_c; and the term only loosens the paper's row, by
//! nothing below b₀.

use proptest::prelude::*;
use safety::barrier::{CLASS_K_FLOOR, collision_row, pair_row};
use safety::{Neighbour, RowKind, SafetyFilter, neighbour_rows};
use uav::{Params, UavState, Vec2};

/// What the discrete steps may lose against the continuous-time boundary beyond the margin the rows
/// keep (docs/safety.md §4.4): the rows already keep δΣ·dt² beyond D_c.
const SAMPLING_SLACK_M: f64 = 0.005;

fn unit(angle: f64) -> Vec2 {
    Vec2::new(angle.cos(), angle.sin())
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(4000))]

    /// Two UAVs that could still stop short of the rows' D_c + δΣ·dt² (closing speed at most a
    /// fraction of √(2δΣ(distance − D_c − δΣ·dt²))), each pushed at full δ in its own random direction for 3 s and each
    /// filtering its share of their pair row (the rows of `neighbour_rows`, as the fleet builds
    /// them), never come closer than D_c.
    #[test]
    fn pushed_at_full_input_two_uavs_keep_d_c(
        beyond in 0.0..2.7f64,
        bearing in 0.0..std::f64::consts::TAU,
        (fraction, skew) in (0.0..0.9f64, -1.0..1.0f64),
        (push_k, push_d) in (0.0..std::f64::consts::TAU, 0.0..std::f64::consts::TAU),
        towards in any::<bool>(),
    ) {
        let params = Params::default();
        let delta_sum = 2.0 * params.delta;
        let dir = unit(bearing);
        let row_d_c = params.d_c + delta_sum * params.dt * params.dt;
        let distance = row_d_c + 0.001 + beyond;
        let closing = fraction * (2.0 * delta_sum * (distance - row_d_c)).sqrt().min(6.0);
        // d at `distance` along `dir` from k; k flies at d, split unevenly between them by `skew`.
        let k0 = UavState { p: Vec2::zeros(), v: dir * closing * (1.0 + skew) / 2.0 };
        let d0 = UavState { p: dir * distance, v: -dir * closing * (1.0 - skew) / 2.0 };
        // Pushed straight at each other, or each in a random direction.
        let (u_k, u_d) = if towards {
            (dir * params.delta, -dir * params.delta)
        } else {
            (unit(push_k) * params.delta, unit(push_d) * params.delta)
        };
        let (mut k, mut d) = (k0, d0);
        let (mut filter_k, mut filter_d, mut rows) = (SafetyFilter::default(), SafetyFilter::default(), Vec::new());
        for tick in 0..60 {
            rows.clear();
            neighbour_rows(k, [(1, Neighbour::Cooperating(d))].into_iter(), &params, &mut rows);
            let f_k = filter_k.filter(u_k, k.v, &rows, params.delta, params.dt);
            rows.clear();
            neighbour_rows(d, [(0, Neighbour::Cooperating(k))].into_iter(), &params, &mut rows);
            let f_d = filter_d.filter(u_d, d.v, &rows, params.delta, params.dt);
            (k, d) = (k.stepped(f_k.u, params.dt), d.stepped(f_d.u, params.dt));
            let gap = (k.p - d.p).norm();
            prop_assert!(gap >= params.d_c - SAMPLING_SLACK_M, "tick {tick}: {gap:.4} m apart");
        }
    }

    /// The pair row is never tighter than the paper's collision row, equals it while b ≤ b₀, and
    /// full braking away from the neighbour satisfies it whenever b ≥ 0.
    #[test]
    fn the_pair_row_only_loosens_the_papers_row(
        distance in 0.3..4.0f64,
        (bearing, heading) in (0.0..std::f64::consts::TAU, 0.0..std::f64::consts::TAU),
        speed in 0.0..8.0f64,
    ) {
        let params = Params::default();
        let (p_kd, v_kd) = (unit(bearing) * distance, unit(heading) * speed);
        let kind = RowKind::Collision(1);
        let paper = collision_row(p_kd, v_kd, params.delta, params.delta, params.d_c, params.zeta, kind);
        let row = pair_row(p_kd, v_kd, params.delta, params.delta, params.d_c, params.zeta, kind);
        prop_assert_eq!((row.a, row.b), (paper.a, paper.b));
        prop_assert!(row.c >= paper.c);
        if paper.b <= CLASS_K_FLOOR {
            prop_assert_eq!(row.c, paper.c);
        }
        if row.b >= 0.0 {
            let braking = p_kd / distance * params.delta;
            prop_assert!(row.a.dot(&braking) <= row.c + 1e-9 * params.delta);
        }
    }
}
