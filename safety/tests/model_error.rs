//! The model-error allowances of docs/safety.md §12 in closed loop: a UAV that is *not* a double
//! integrator (its acceleration follows the filtered input with a first-order lag τ_a, a gust kicks
//! its velocity once, and the filter reads its state through bounded position and velocity errors)
//! keeps its true distance D_s from every wall of random roads, and two such UAVs flying at each
//! other keep D_c, when the filter runs with η_p = the position error bound and
//! η_v = 2δτ_a + the velocity error bound + the gust. Without the allowances the same flights
//! come closer than D_s: the last test shows it.

mod common;

use common::roads::{road, varying_road};
use proptest::prelude::*;
use roads::{Road, SegmentTracker};
use safety::{Neighbour, RoadRule, SafetyFilter, neighbour_rows, road_rows};
use uav::{Params, UavState, Vec2};

/// Sub-steps per tick of the lagged dynamics.
const SUBSTEPS: usize = 20;
/// Rounding and the held-input bound's own slack (as in `road_rows.rs`).
const SAMPLING_SLACK_M: f64 = 0.001;

/// A quadrotor-like UAV: position, velocity and the acceleration it achieves, which follows the
/// commanded one with time constant `tau` (s).
#[derive(Debug, Clone, Copy)]
struct Lagged {
    state: UavState,
    a: Vec2,
    tau: f64,
}

impl Lagged {
    /// Flies `dt` with command `u` held.
    fn step(&mut self, u: Vec2, dt: f64) {
        let h = dt / SUBSTEPS as f64;
        let follow = if self.tau > 0.0 { 1.0 - (-h / self.tau).exp() } else { 1.0 };
        for _ in 0..SUBSTEPS {
            let a0 = self.a;
            self.a += (u - self.a) * follow;
            let a = (a0 + self.a) / 2.0;
            self.state.p += self.state.v * h + a * (0.5 * h * h);
            self.state.v += a * h;
        }
    }
}

/// The model errors of one flight: lag, estimate bounds, one gust.
#[derive(Debug, Clone, Copy)]
struct Errors {
    tau: f64,
    rho_p: f64,
    rho_v: f64,
    gust: f64,
}

impl Errors {
    fn strategy() -> impl Strategy<Value = Self> {
        (0.0..0.08f64, 0.0..0.05f64, 0.0..0.2f64, 0.0..0.3f64).prop_map(|(tau, rho_p, rho_v, gust)| Self {
            tau,
            rho_p,
            rho_v,
            gust,
        })
    }

    /// The allowances §12 derives for these errors.
    fn params(&self) -> Params {
        let mut params = Params::default();
        params.eta_v = 2.0 * params.delta * self.tau + self.rho_v + self.gust;
        params.eta_p = self.rho_p + params.eta_v * params.dt;
        params
    }
}

/// The state the filter reads: the true one off by at most ρ_p and ρ_v, in directions `angles`.
fn read(truth: UavState, e: &Errors, angles: (f64, f64), scale: (f64, f64)) -> UavState {
    let dir = |a: f64| Vec2::new(a.cos(), a.sin());
    UavState {
        p: truth.p + dir(angles.0) * (e.rho_p * scale.0),
        v: truth.v + dir(angles.1) * (e.rho_v * scale.1),
    }
}

/// Per tick: the estimate errors' directions and sizes (fractions of the bounds). Half the flights
/// are read with a bias (one direction per flight, sizes 0.5–1 of the bounds), which can hide an
/// approach for the whole flight; the others with errors in any direction.
fn noise() -> impl Strategy<Value = Vec<(f64, f64, f64, f64)>> {
    let angle = || 0.0..std::f64::consts::TAU;
    let any = prop::collection::vec((angle(), angle(), 0.0..=1.0f64, 0.0..=1.0f64), 60);
    let biased = (angle(), angle(), prop::collection::vec((0.5..=1.0f64, 0.5..=1.0f64), 60))
        .prop_map(|(ap, av, sizes)| sizes.into_iter().map(|(sp, sv)| (ap, av, sp, sv)).collect());
    prop_oneof![any, biased]
}

/// A UAV in `road` pushed at full input in direction `push` for 3 s, flown with model errors `e`
/// (gust at tick `gust_tick` in direction `gust_dir`) and a filter with allowances `params`:
/// the closest it truly came to the walls.
#[allow(clippy::too_many_arguments)]
fn pushed_at_a_wall(
    road: &Road,
    start: UavState,
    push: f64,
    e: &Errors,
    params: &Params,
    noise: &[(f64, f64, f64, f64)],
    gust: (usize, f64),
) -> f64 {
    let mut truth = Lagged { state: start, a: Vec2::zeros(), tau: e.tau };
    let (mut tracker, mut rows, mut filter) =
        (SegmentTracker::default(), Vec::new(), SafetyFilter::default());
    let u_ref = Vec2::new(push.cos(), push.sin()) * params.delta;
    let mut closest = f64::INFINITY;
    for (tick, &(ap, av, sp, sv)) in noise.iter().enumerate() {
        let seen = read(truth.state, e, (ap, av), (sp, sv));
        let segment = tracker.update(road, &seen.p);
        rows.clear();
        road_rows(road, RoadRule::Walls, seen.p, seen.v, segment, params, &mut rows);
        let f = filter.filter(u_ref, seen.v, &rows, params.delta, params.dt);
        if tick == gust.0 {
            truth.state.v += Vec2::new(gust.1.cos(), gust.1.sin()) * e.gust;
        }
        truth.step(f.u, params.dt);
        closest = closest.min(road.boundary_distance(&truth.state.p));
    }
    closest
}

/// A start in `road` from which braking stops the true UAV before D_s + η (speed a fraction of
/// that), and not within the position error of the walls.
fn start_in(
    road: &Road,
    t: f64,
    lateral: f64,
    (fraction, angle): (f64, f64),
    params: &Params,
) -> Option<UavState> {
    let line = road.centerline();
    let c = line.point_at(t * line.length());
    let normal = {
        let d = line.tangent_at(t * line.length());
        Vec2::new(-d.y, d.x)
    };
    let p = c + normal * (lateral * road.boundary_distance(&c).max(0.0));
    let room = road.boundary_distance(&p) - params.d_s - params.eta_p;
    let braking = (2.0 * params.delta * room.max(0.0)).sqrt() - params.eta_v;
    (braking > 0.0)
        .then(|| UavState { p, v: Vec2::new(angle.cos(), angle.sin()) * fraction * braking.min(4.0) })
}

proptest! {
    // Starts from which the UAVs could not stop are skipped (about one in four).
    #![proptest_config(ProptestConfig { cases: 3000, max_global_rejects: 1 << 20, ..ProptestConfig::default() })]

    /// With the allowances, a lagging UAV read through errors and kicked by a gust, pushed at full
    /// input at the walls of a random road for 3 s, keeps D_s from every wall by its true position.
    #[test]
    fn with_the_allowances_a_lagging_uav_read_through_errors_keeps_d_s(
        road in prop_oneof![road(), varying_road()],
        t in 0.0..1.0f64,
        lateral in -1.0..1.0f64,
        velocity in (0.0..0.8f64, 0.0..std::f64::consts::TAU),
        push in 0.0..std::f64::consts::TAU,
        e in Errors::strategy(),
        noise in noise(),
        gust in (0..60usize, 0.0..std::f64::consts::TAU),
    ) {
        let params = e.params();
        let start = start_in(&road, t, lateral, velocity, &params);
        prop_assume!(start.is_some());
        let closest = pushed_at_a_wall(&road, start.unwrap(), push, &e, &params, &noise, gust);
        prop_assert!(closest >= params.d_s - SAMPLING_SLACK_M, "{closest:.4} m from the walls, {e:?}");
    }

    /// Two lagging UAVs read through errors fly at each other on open ground at up to 3 m/s, each
    /// pushed at full input towards the other: their true distance stays ≥ D_c.
    #[test]
    fn with_the_allowances_two_lagging_uavs_read_through_errors_keep_d_c(
        gap in 1.0..6.0f64,
        offset in -0.3..0.3f64,
        speeds in (0.0..3.0f64, 0.0..3.0f64),
        e in Errors::strategy(),
        noise in (noise(), noise()),
    ) {
        let params = e.params();
        let mut uavs = [
            Lagged { state: UavState { p: Vec2::new(0.0, 0.0), v: Vec2::new(speeds.0, 0.0) }, a: Vec2::zeros(), tau: e.tau },
            Lagged { state: UavState { p: Vec2::new(gap, offset), v: Vec2::new(-speeds.1, 0.0) }, a: Vec2::zeros(), tau: e.tau },
        ];
        // Only starts from which the pair can stop before D_c + η by braking together.
        let (d, closing) = (gap.hypot(offset) - params.d_c - 2.0 * params.eta_p, speeds.0 + speeds.1);
        prop_assume!((4.0 * params.delta * (d - 0.025).max(0.0)).sqrt() - 2.0 * params.eta_v > closing);
        let mut filters = [SafetyFilter::default(), SafetyFilter::default()];
        let mut closest = f64::INFINITY;
        for tick in 0..60 {
            let seen: Vec<UavState> = (0..2)
                .map(|k| {
                    let (ap, av, sp, sv) = if k == 0 { noise.0[tick] } else { noise.1[tick] };
                    read(uavs[k].state, &e, (ap, av), (sp, sv))
                })
                .collect();
            let mut inputs = [Vec2::zeros(); 2];
            for k in 0..2 {
                let other = 1 - k;
                let mut rows = Vec::new();
                let neighbour = std::iter::once((other, Neighbour::Cooperating(seen[other])));
                neighbour_rows(seen[k], neighbour, &params, &mut rows);
                let towards = (seen[other].p - seen[k].p).normalize() * params.delta;
                inputs[k] = filters[k].filter(towards, seen[k].v, &rows, params.delta, params.dt).u;
            }
            for k in 0..2 {
                uavs[k].step(inputs[k], params.dt);
            }
            closest = closest.min((uavs[0].state.p - uavs[1].state.p).norm());
        }
        prop_assert!(closest >= params.d_c - SAMPLING_SLACK_M, "{closest:.4} m apart, {e:?}");
    }
}

/// Without the allowances the filter trusts the model: the same kind of flight, a UAV lagging by
/// 40 ms and read 30 mm and 0.08 m/s off, pushed at a wall, comes closer than D_s.
#[test]
fn without_the_allowances_model_errors_break_d_s() {
    let road = Road::new(roads::RoadLayout::straight(0.0, 20.0, 2.0, 4)).unwrap();
    let e = Errors { tau: 0.04, rho_p: 0.03, rho_v: 0.08, gust: 0.0 };
    let start = UavState { p: Vec2::new(5.0, 0.0), v: Vec2::zeros() };
    // The errors always hide the approach: read 30 mm farther from the wall (y = 1), 0.08 m/s slower.
    let hidden = vec![(-std::f64::consts::FRAC_PI_2, -std::f64::consts::FRAC_PI_2, 1.0, 1.0); 60];
    let push = std::f64::consts::FRAC_PI_2;
    let exact = pushed_at_a_wall(&road, start, push, &e, &Params::default(), &hidden, (0, 0.0));
    assert!(exact < Params::default().d_s - 0.01, "without allowances: {exact:.4} m");
    let allowed = pushed_at_a_wall(&road, start, push, &e, &e.params(), &hidden, (0, 0.0));
    assert!(allowed >= Params::default().d_s - SAMPLING_SLACK_M, "with allowances: {allowed:.4} m");
}
