//! Proves the safety properties of rows and filter (docs/safety.md §2, §4, §6, §10.2): full braking
//! satisfies every row with b ≥ 0 (also next to the singularities), the h_min clamp only tightens rows,
//! the filter respects ‖u‖ ≤ δ, keeps every slack at 0 on feasible rows (exact penalty), brakes on
//! non-finite data, and returns a safe nominal input unchanged without solving.

mod common;

use clarabel::solver::SolverStatus;
use common::hard_qp;
use proptest::prelude::*;
use safety::barrier::{H_MIN, collision_row, line_row, point_row};
use safety::{FilterSettings, Row, RowKind, SafetyFilter};
use std::cell::RefCell;
use std::f64::consts::TAU;
use uav::{Vec2, braking_input};

const D_C: f64 = 0.3;
const D_S: f64 = 0.1;
const ZETA: f64 = 0.05;
const DT: f64 = 0.05;
/// Round-off allowed when full braking meets a row exactly (b = 0), in units of δ.
const ROUND_OFF: f64 = 1e-12;
/// Row satisfaction and slack tolerance of the filter's output (solver tolerances 1e-9, docs/safety.md §6).
const QP_TOL: f64 = 1e-6;

/// Clarabel's reduced gap tolerance (`reduced_tol_gap_rel`), met by an `AlmostSolved` answer.
const REDUCED_TOL: f64 = 5e-5;

thread_local! {
    /// One warm filter per test thread, so its cached solvers are updated across cases as in a run.
    static FILTER: RefCell<SafetyFilter> = RefCell::new(SafetyFilter::default());
}

fn unit(angle: f64) -> Vec2 {
    Vec2::new(angle.cos(), angle.sin())
}

fn perp(x: Vec2) -> Vec2 {
    Vec2::new(-x.y, x.x)
}

/// Distance beyond the safe distance: away from the singularity, or right next to it.
fn regular_gap() -> impl Strategy<Value = f64> {
    0.05..5.0f64
}

fn near_singular_gap() -> impl Strategy<Value = f64> {
    1e-9..1e-5f64
}

/// Fraction placing the closing rate in [−h, 10]; 0 (b = 0, the boundary) is drawn often.
fn rate_fraction() -> impl Strategy<Value = f64> {
    prop_oneof![1 => Just(0.0), 4 => 0.0..1.0f64]
}

/// A rate ≥ −h (so b = h + rate ≥ 0) for distance `gap` beyond the safe distance and braking δ.
fn rate(gap: f64, delta: f64, fraction: f64) -> f64 {
    let h = (2.0 * delta * gap).sqrt();
    -h + fraction * (h + 10.0)
}

/// Collision (δ_d > 0) or end-point (δ_d = 0, D_s) row with b ≥ 0; `u_k = δ_k p̂` must satisfy it.
fn check_full_braking(
    (angle, gap, fraction, tangential): (f64, f64, f64, f64),
    (delta_k, delta_d): (f64, f64),
) -> Result<(), TestCaseError> {
    let p_hat = unit(angle);
    let sum = delta_k + delta_d;
    let (row, dist) = if delta_d > 0.0 {
        let p = p_hat * (D_C + gap);
        let v = p_hat * rate(gap, sum, fraction) + perp(p_hat) * tangential;
        (collision_row(p, v, delta_k, delta_d, D_C, ZETA, RowKind::Collision(1)), p)
    } else {
        let vertex = Vec2::new(3.0, -2.0);
        let w = p_hat * (D_S + gap);
        let v = p_hat * rate(gap, delta_k, fraction) + perp(p_hat) * tangential;
        (point_row(vertex + w, v, vertex, delta_k, D_S, ZETA, RowKind::Road(0)), w)
    };
    prop_assume!(row.b >= 0.0);
    let u = dist / dist.norm() * delta_k;
    prop_assert!(row.a.dot(&u) <= row.c + ROUND_OFF * delta_k, "full braking violates {:?}", row);
    Ok(())
}

fn check_line_full_braking((angle, gap, fraction, delta): (f64, f64, f64, f64)) -> Result<(), TestCaseError> {
    let n_in = unit(angle);
    let row = line_row(D_S + gap, rate(gap, delta, fraction), n_in, delta, D_S, ZETA, RowKind::Road(0));
    prop_assume!(row.b >= 0.0);
    prop_assert!(row.a.dot(&(n_in * delta)) <= row.c + ROUND_OFF * delta, "full braking violates {:?}", row);
    Ok(())
}

fn state() -> impl Strategy<Value = (f64, f64, f64, f64)> {
    (0.0..TAU, regular_gap(), rate_fraction(), -5.0..5.0f64)
}

fn near_singular_state() -> impl Strategy<Value = (f64, f64, f64, f64)> {
    (0.0..TAU, near_singular_gap(), rate_fraction(), -5.0..5.0f64)
}

/// δ_k and δ_d (0 for the end-point barrier, a static obstacle).
fn deltas() -> impl Strategy<Value = (f64, f64)> {
    (1.0..8.0f64, prop_oneof![1 => Just(0.0), 3 => 1.0..8.0f64])
}

/// A unit row direction.
fn direction() -> impl Strategy<Value = Vec2> {
    (0.0..TAU).prop_map(unit)
}

fn kind() -> impl Strategy<Value = RowKind> {
    prop_oneof![(0..8usize).prop_map(RowKind::Road), (0..8usize).prop_map(RowKind::Collision)]
}

/// Rows `aᵀu ≤ aᵀu* + margin` that u* satisfies (margin 0: the row passes through u*).
fn rows_through(u_star: Vec2) -> impl Strategy<Value = Vec<Row>> {
    let row = (direction(), prop_oneof![1 => Just(0.0), 3 => 0.0..2.0f64], -1.0..12.0f64, kind());
    prop::collection::vec(row, 1..8).prop_map(move |rows| {
        rows.into_iter().map(|(a, margin, b, kind)| Row { a, c: a.dot(&u_star) + margin, b, kind }).collect()
    })
}

/// A point of the ‖u‖ ≤ δ ball, on its boundary one time in four.
fn in_ball(delta: f64) -> impl Strategy<Value = Vec2> {
    (0.0..TAU, prop_oneof![1 => Just(1.0), 3 => 0.0..1.0f64]).prop_map(move |(a, r)| unit(a) * (r * delta))
}

fn vec2(scale: f64) -> impl Strategy<Value = Vec2> {
    (-scale..scale, -scale..scale).prop_map(|(x, y)| Vec2::new(x, y))
}

/// The ρ the filter gives a row (`FilterSettings`: road priority, urgency 1/clamp(b, floor, 10)).
fn rho(s: &FilterSettings, r: &Row) -> f64 {
    s.slack_weights(r).0
}

fn filter(u_ref: Vec2, v: Vec2, rows: &[Row], delta: f64) -> safety::FilterOutcome {
    FILTER.with(|f| f.borrow_mut().filter(u_ref, v, rows, delta, DT))
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(2000))]

    #[test]
    fn full_braking_satisfies_collision_and_point_rows(s in state(), d in deltas()) {
        check_full_braking(s, d)?;
    }

    #[test]
    fn full_braking_satisfies_collision_and_point_rows_near_singular(
        s in near_singular_state(),
        d in deltas(),
    ) {
        check_full_braking(s, d)?;
    }

    #[test]
    fn full_braking_satisfies_line_rows((angle, gap, fraction, _) in state(), delta in 1.0..8.0f64) {
        check_line_full_braking((angle, gap, fraction, delta))?;
    }

    #[test]
    fn full_braking_satisfies_line_rows_near_singular(
        (angle, gap, fraction, _) in near_singular_state(),
        delta in 1.0..8.0f64,
    ) {
        check_line_full_braking((angle, gap, fraction, delta))?;
    }

    /// h < h_min and b ≥ 0: the clamped row's c is at most the exact c (collision and end-point rows).
    #[test]
    fn clamp_never_loosens_collision_and_point_rows(
        (angle, h_target, fraction, tangential) in (0.0..TAU, 1e-6..H_MIN, rate_fraction(), -5.0..5.0f64),
        (delta_k, delta_d) in deltas(),
    ) {
        let sum = delta_k + delta_d;
        let d = if delta_d > 0.0 { D_C } else { D_S };
        let p = unit(angle) * (d + h_target * h_target / (2.0 * sum));
        let gap = h_target * h_target / (2.0 * sum);
        let v = unit(angle) * rate(gap, sum, fraction) + perp(unit(angle)) * tangential;
        let row = if delta_d > 0.0 {
            collision_row(p, v, delta_k, delta_d, D_C, ZETA, RowKind::Collision(1))
        } else {
            point_row(p, v, Vec2::zeros(), delta_k, D_S, ZETA, RowKind::Road(0))
        };
        // The exact row, evaluated as docs/safety.md §1 writes it, from the same n, ṅ, h.
        let n = p.norm();
        let n_dot = (p / n).dot(&v);
        let v_perp2 = (v.norm_squared() - n_dot * n_dot).max(0.0);
        let h = (2.0 * sum * (n - d).max(0.0)).sqrt();
        let b = h + n_dot;
        prop_assume!(h > 0.0 && h < H_MIN && b >= 0.0);
        let terms = [sum * n_dot / h, v_perp2 / n, ZETA * b.powi(3)];
        let exact = delta_k / sum * terms.iter().sum::<f64>();
        let scale = delta_k / sum * (terms.iter().map(|t| t.abs()).sum::<f64>() + sum);
        prop_assert_eq!(row.b, b);
        prop_assert!(row.c <= exact + ROUND_OFF * scale, "clamped c {:e} > exact c {:e}", row.c, exact);
    }

    /// The same for the signed line row: g < h_min and b ≥ 0 give c ≤ δṡ/g + ζb³.
    #[test]
    fn clamp_never_loosens_line_rows(
        (angle, g_target, fraction, delta) in (0.0..TAU, 1e-6..H_MIN, rate_fraction(), 1.0..8.0f64),
    ) {
        let s = D_S + g_target * g_target / (2.0 * delta);
        let s_dot = rate(s - D_S, delta, fraction);
        let row = line_row(s, s_dot, unit(angle), delta, D_S, ZETA, RowKind::Road(0));
        let g = (2.0 * delta * (s - D_S).max(0.0)).sqrt();
        let b = g + s_dot;
        prop_assume!(g > 0.0 && g < H_MIN && b >= 0.0);
        let terms = [delta * s_dot / g, ZETA * b.powi(3)];
        let exact = terms[0] + terms[1];
        let scale = terms[0].abs() + terms[1].abs() + delta;
        prop_assert!(row.c <= exact + ROUND_OFF * scale, "clamped c {:e} > exact c {:e}", row.c, exact);
    }

    /// Arbitrary (possibly jointly infeasible) rows: the output is finite and within the input bound.
    #[test]
    fn filter_output_within_bound(
        delta in 0.5..8.0f64,
        (u_ref, v) in (vec2(40.0), vec2(10.0)),
        rows in prop::collection::vec(
            (direction(), prop_oneof![-1e4..1e4f64, -10.0..10.0f64], -5.0..20.0f64, kind()),
            0..10,
        ),
    ) {
        let rows: Vec<Row> = rows.into_iter().map(|(a, c, b, kind)| Row { a, c, b, kind }).collect();
        let out = filter(u_ref, v, &rows, delta);
        prop_assert!(uav::is_finite(&out.u), "{:?}", out);
        let norm = out.u.norm();
        prop_assert!(norm <= delta * (1.0 + 1e-9), "‖u‖ = {} > δ = {}: {:?}", norm, delta, out);
    }

    /// Jointly feasible rows (u* in the δ-ball, c ≥ aᵀu*): when ρ of every row exceeds its multiplier in
    /// the hard problem (the premise of the exact-penalty claim of docs/safety.md §6, checked with an
    /// exact 2-D oracle), the filter returns the hard optimum: every row holds, every slack is 0, no
    /// failure.
    #[test]
    fn filter_exact_on_feasible_rows(
        (delta, u_star, rows) in (0.5..8.0f64).prop_flat_map(|d| (Just(d), in_ball(d)))
            .prop_flat_map(|(d, u)| (Just(d), Just(u), rows_through(u))),
        (u_ref, v) in (vec2(2.0), vec2(10.0)),
    ) {
        let u_ref = u_ref * delta;
        prop_assert!(u_star.norm() <= delta * (1.0 + 1e-12));
        let plain: Vec<(Vec2, f64)> = rows.iter().map(|r| (r.a, r.c)).collect();
        let hard = hard_qp(u_ref, &plain, delta).expect("u* is feasible");
        let settings = FILTER.with(|f| f.borrow().settings);
        let premise = hard.multipliers.as_ref().is_some_and(|l| {
            rows.iter().zip(l).all(|(r, l)| r.c >= delta || *l <= 0.5 * rho(&settings, r))
        });
        prop_assume!(premise, "multipliers not unique or above ρ (counterexamples that hold anyway: exact_penalty.rs)");
        let out = filter(u_ref, v, &rows, delta);
        prop_assert!(!out.failed, "{:?}", out);
        prop_assert!(out.u.norm() <= delta * (1.0 + 1e-9), "{:?}", out);
        prop_assert!(out.max_slack <= QP_TOL, "slack {:e} on feasible rows: {:?}", out.max_slack, out);
        for r in &rows {
            prop_assert!(r.a.dot(&out.u) <= r.c + QP_TOL, "row {:?} violated by {:?}", r, out);
        }
        // Optimal too: the objective matches the hard optimum's to the solver's tolerance (Clarabel's
        // reduced one, 5e-5, when it stopped at `AlmostSolved` on a nearly degenerate problem).
        let (got, best) = ((out.u - u_ref).norm_squared() / 2.0, (hard.u - u_ref).norm_squared() / 2.0);
        let tol = if out.status == SolverStatus::AlmostSolved { REDUCED_TOL } else { QP_TOL };
        let optimal = got <= best + tol * best.max(1.0);
        prop_assert!(optimal, "objective {:e} > optimum {:e} at {:?}", got, best, hard.u);
    }

    /// NaN or ±inf in u_ref or in a row's a or c: failed, full braking, no panic.
    #[test]
    fn non_finite_data_brakes(
        (delta, v) in (0.5..8.0f64, vec2(10.0)),
        u_ref in vec2(10.0),
        rows in prop::collection::vec((direction(), -10.0..10.0f64, -1.0..10.0f64, kind()), 1..6),
        bad in prop_oneof![Just(f64::NAN), Just(f64::INFINITY), Just(f64::NEG_INFINITY)],
        (place, row_pick) in (0..5usize, 0..6usize),
    ) {
        let mut rows: Vec<Row> = rows.into_iter().map(|(a, c, b, kind)| Row { a, c, b, kind }).collect();
        let mut u_ref = u_ref;
        let j = row_pick % rows.len();
        match place {
            0 => u_ref.x = bad,
            1 => u_ref.y = bad,
            2 => rows[j].a.x = bad,
            3 => rows[j].a.y = bad,
            _ => rows[j].c = bad,
        }
        let out = filter(u_ref, v, &rows, delta);
        prop_assert!(out.failed, "non-finite data ({} at place {}) not flagged: {:?}", bad, place, out);
        prop_assert!(out.u.norm() <= delta * (1.0 + 1e-12), "{:?}", out);
        prop_assert_eq!(out.u, braking_input(v, delta, DT));
    }

    /// A nominal input that satisfies every row and the bound is returned bit for bit, without a solve.
    #[test]
    fn safe_nominal_is_returned_unchanged(
        (delta, u_ref, rows) in (0.5..8.0f64).prop_flat_map(|d| (Just(d), in_ball(d)))
            .prop_flat_map(|(d, u)| (Just(d), Just(u), rows_through(u))),
        v in vec2(10.0),
    ) {
        prop_assume!(u_ref.norm() <= delta);
        let out = filter(u_ref, v, &rows, delta);
        prop_assert_eq!(out.u, u_ref);
        prop_assert!(!out.solved && !out.failed && out.max_slack == 0.0, "{:?}", out);
    }
}
