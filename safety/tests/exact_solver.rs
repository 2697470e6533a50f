//! The exact solver (docs/safety.md §11) against Clarabel and against answers known in closed form,
//! on random and on degenerate instances: every answer must carry a KKT certificate within 1e-9 and
//! lie within 1e-6 of Clarabel's (tolerance 1e-12) whenever Clarabel solves the instance.

use proptest::prelude::*;
use safety::{ConstraintRow, ExactError, ExactSolver, QpSolver, kkt_residual};
use uav::Vec2;

fn unit(angle: f64) -> Vec2 {
    Vec2::new(angle.cos(), angle.sin())
}

fn row(a: Vec2, c: f64, rho: f64, weight: f64) -> ConstraintRow {
    ConstraintRow { a, c, rho, weight }
}

/// Solves with the exact solver, checks its certificate independently, and returns u.
fn solve(u_r: Vec2, rows: &[ConstraintRow], delta: f64) -> Vec2 {
    let mut exact = ExactSolver::new();
    let sol = exact.solve(u_r, rows, delta).unwrap_or_else(|e| panic!("{e} for {u_r:?} {rows:?} δ {delta}"));
    let kkt = kkt_residual(u_r, rows, delta, sol.u, exact.multipliers(), exact.ball_multiplier());
    assert!(kkt.max() <= 1e-9, "KKT {kkt:?} at {:?} for {u_r:?} {rows:?} δ {delta}", sol.u);
    assert!(sol.u.norm() <= delta * (1.0 + 1e-12));
    sol.u
}

/// F(u) = ½‖u − u_r‖² + Σ φ_c(a_cᵀu − c_c): the objective with r eliminated.
fn objective(u_r: Vec2, rows: &[ConstraintRow], u: Vec2) -> f64 {
    let slack = |r: &ConstraintRow| {
        let t = (r.a.dot(&u) - r.c).max(0.0);
        r.rho * t + 0.5 * r.weight * t * t
    };
    0.5 * (u - u_r).norm_squared() + rows.iter().map(slack).sum::<f64>()
}

/// The exact answer, checked against Clarabel at tolerance 1e-12 when Clarabel solves it: within
/// 1e-6, or farther only where Clarabel's objective shows its own error (F strongly convex with
/// modulus 1 and the exact answer optimal: F(u_clarabel) − F(u) ≥ ½‖u_clarabel − u‖²). That bound
/// is tight when no row binds at u (u = u_r), so it is compared up to rounding (1e-9 relative).
fn solve_and_compare(u_r: Vec2, rows: &[ConstraintRow], delta: f64) -> Vec2 {
    let u = solve(u_r, rows, delta);
    let reference = QpSolver::with_tolerance(1e-12).solve(u_r, rows, delta);
    if reference.status == clarabel::solver::SolverStatus::Solved {
        let du = (u - reference.u).norm();
        let gap = objective(u_r, rows, reference.u) - objective(u_r, rows, u);
        assert!(
            du <= 1e-6 || gap >= 0.5 * du * du * (1.0 - 1e-9),
            "exact {u:?} vs Clarabel {:?} (|du| {du:e}, F gap {gap:e}) for {u_r:?} {rows:?} δ {delta}",
            reference.u
        );
    }
    u
}

fn assert_near(u: Vec2, want: Vec2, tol: f64) {
    assert!((u - want).norm() <= tol, "{u:?} vs {want:?}");
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(4000))]

    /// Random instances with moderate weights (where Clarabel at 1e-12 is accurate to 1e-6 in u),
    /// with rows through u_r, duplicated and opposite rows mixed in.
    #[test]
    fn matches_clarabel(
        delta in 0.5..8.0f64,
        (angle, scale) in (0.0..std::f64::consts::TAU, 0.0..2.0f64),
        raw in prop::collection::vec((0.0..std::f64::consts::TAU, -1.5..1.0f64, 0u8..6, 0.1..10.0f64, 0.1..5.0f64), 0..10),
        paper in proptest::bool::weighted(0.1),
    ) {
        let u_r = unit(angle) * (scale * delta);
        let mut rows = Vec::new();
        for (theta, offset, kind, rho, weight) in raw {
            let a = unit(theta);
            let rho = if paper { 0.0 } else { rho * 100.0 };
            let c = if kind == 0 { a.dot(&u_r) } else { a.dot(&u_r) - offset * delta };
            rows.push(row(a, c, rho, weight));
            match kind {
                1 => rows.push(row(a, c, rho, weight)),
                2 => rows.push(row(-a, -c - 0.3 * delta, rho, weight)),
                3 => rows.push(row(a * 2.0, 2.0 * c, rho, weight)),
                _ => {}
            }
        }
        solve_and_compare(u_r, &rows, delta);
    }

    /// The filter's weights (ρ up to 2·10⁶): the certificate holds (Clarabel is not accurate to
    /// 1e-6 here, see BENCHMARKS.md).
    #[test]
    fn certified_with_filter_weights(
        (angle, scale) in (0.0..std::f64::consts::TAU, 0.0..2.0f64),
        raw in prop::collection::vec((0.0..std::f64::consts::TAU, -2.0..1.0f64, 1.0..200.0f64), 1..13),
    ) {
        let delta = 5.0;
        let u_r = unit(angle) * (scale * delta);
        let rows: Vec<_> = raw.into_iter().map(|(t, off, p)| row(unit(t), unit(t).dot(&u_r) - off * delta, 1e4 * p, p)).collect();
        solve(u_r, &rows, delta);
    }
}

#[test]
fn no_rows_inside_and_outside_the_ball() {
    assert_near(solve_and_compare(Vec2::new(1.0, 2.0), &[], 5.0), Vec2::new(1.0, 2.0), 0.0);
    assert_near(solve_and_compare(Vec2::new(6.0, 8.0), &[], 5.0), Vec2::new(3.0, 4.0), 1e-12);
    assert_near(solve_and_compare(Vec2::zeros(), &[], 5.0), Vec2::zeros(), 0.0);
}

#[test]
fn one_row_is_a_projection() {
    // u_r = (2, 0), row x ≤ 1: u = (1, 0) with λ = 1 ≤ ρ.
    let u = solve_and_compare(Vec2::new(2.0, 0.0), &[row(Vec2::new(1.0, 0.0), 1.0, 1e4, 1.0)], 5.0);
    assert_near(u, Vec2::new(1.0, 0.0), 1e-12);
}

#[test]
fn duplicate_and_scaled_rows_share_one_multiplier() {
    let r = row(Vec2::new(1.0, 0.0), 1.0, 0.6, 1.0);
    // λ = 1 is more than one row's ρ = 0.6 but within two: no slack.
    let u = solve_and_compare(Vec2::new(2.0, 0.0), &[r, r], 5.0);
    assert_near(u, Vec2::new(1.0, 0.0), 1e-12);
    let scaled = row(Vec2::new(3.0, 0.0), 3.0, 0.2, 1.0);
    let u = solve_and_compare(Vec2::new(2.0, 0.0), &[r, scaled], 5.0);
    assert_near(u, Vec2::new(1.0, 0.0), 1e-12);
}

#[test]
fn jointly_infeasible_rows_balance_their_slacks() {
    // x ≤ −1 and −x ≤ −1 (x ≥ 1) with equal weights: the slacks balance at x = 0, r = 1 each.
    let rows = [row(Vec2::new(1.0, 0.0), -1.0, 1e4, 2.0), row(Vec2::new(-1.0, 0.0), -1.0, 1e4, 2.0)];
    // F = ½(x − 0.5)² + (x + 1)² + (1 − x)² + const: x = 0.1.
    let u = solve_and_compare(Vec2::new(0.5, 0.3), &rows, 5.0);
    assert_near(u, Vec2::new(0.1, 0.3), 1e-9);
}

#[test]
fn parallel_rows_only_the_tighter_binds() {
    let rows = [row(Vec2::new(0.0, 1.0), 1.0, 1e4, 1.0), row(Vec2::new(0.0, 1.0), 0.5, 1e4, 1.0)];
    assert_near(solve_and_compare(Vec2::new(0.0, 3.0), &rows, 5.0), Vec2::new(0.0, 0.5), 1e-12);
}

#[test]
fn three_rows_through_one_vertex() {
    // x ≤ 1, y ≤ 1 and x + y ≤ 2 all pass through (1, 1); u_r = (3, 3) lands there.
    let d = std::f64::consts::FRAC_1_SQRT_2;
    let rows = [
        row(Vec2::new(1.0, 0.0), 1.0, 1e4, 1.0),
        row(Vec2::new(0.0, 1.0), 1.0, 1e4, 1.0),
        row(Vec2::new(d, d), 2.0 * d, 1e4, 1.0),
    ];
    assert_near(solve_and_compare(Vec2::new(3.0, 3.0), &rows, 5.0), Vec2::new(1.0, 1.0), 1e-12);
    // A tie: two of them in duplicate.
    let tied = [rows[0], rows[2], rows[1], rows[2], rows[0]];
    assert_near(solve_and_compare(Vec2::new(3.0, 2.0), &tied, 5.0), Vec2::new(1.0, 1.0), 1e-12);
}

#[test]
fn rows_through_u_r_leave_it_unchanged() {
    let u_r = Vec2::new(0.7, -1.2);
    let rows: Vec<_> = (0..9).map(|k| unit(0.7 * k as f64)).map(|a| row(a, a.dot(&u_r), 1e4, 1.0)).collect();
    assert_near(solve_and_compare(u_r, &rows, 5.0), u_r, 1e-12);
    // u_r = 0 with rows through it and one violated row.
    let mut rows: Vec<_> = (0..6).map(|k| row(unit(1.1 * k as f64), 0.0, 1e4, 1.0)).collect();
    rows.push(row(Vec2::new(0.0, -1.0), -1.0, 1e5, 1.0));
    solve_and_compare(Vec2::zeros(), &rows, 5.0);
}

/// Found by CI: u_r = 0 on the boundary of every row through it; Clarabel stops 1.08e-6 away with
/// F exactly ½‖du‖² above the exact answer (the bound is tight there, not Clarabel beating it).
#[test]
fn u_r_zero_on_rows_through_it_where_clarabel_stops_short() {
    let r = |x: f64, y: f64, c: f64, rho: f64, weight: f64| row(Vec2::new(x, y), c, rho, weight);
    let rows = [
        r(0.6238881639910462, 0.781513633170837, 2.9920934005191495, 618.1199049010986, 0.1),
        r(0.6238881639910462, 0.781513633170837, 2.9920934005191495, 618.1199049010986, 0.1),
        r(-0.0767385025750073, -0.9970512535584847, -0.0, 938.510118924169, 2.542454882349382),
        r(0.6309338937395176, 0.775836594735445, 2.1926640655671856, 700.1910071167498, 4.951652162515325),
        r(1.2618677874790352, 1.55167318947089, 4.385328131134371, 700.1910071167498, 4.951652162515325),
        r(0.058592935677382565, 0.9982819581103858, 0.0, 988.7193154313741, 3.803845558225784),
        r(-0.8178301594741932, -0.5754596686601204, -0.0, 346.5716502615626, 3.3983057854797263),
        r(-0.3952475365155359, 0.9185746485062606, 5.682237939455767, 897.9503886038701, 0.22685225254713287),
        r(-0.3952475365155359, 0.9185746485062606, 5.682237939455767, 897.9503886038701, 0.22685225254713287),
        r(0.369170292884682, 0.929361767478864, 3.3803150623658866, 132.64875372802837, 2.1660341680383848),
        r(0.738340585769364, 1.858723534957728, 6.760630124731773, 132.64875372802837, 2.1660341680383848),
    ];
    assert_near(solve_and_compare(Vec2::zeros(), &rows, 4.856313079518836), Vec2::zeros(), 0.0);
}

#[test]
fn ball_active_alone_and_with_a_row() {
    // Ball alone: u_r outside → radial projection.
    assert_near(solve_and_compare(Vec2::new(0.0, -9.0), &[], 3.0), Vec2::new(0.0, -3.0), 1e-12);
    // Row x ≥ 3 (−x ≤ −3) and u_r = (6, 8) far outside δ = 5: the row's line meets the circle at
    // (3, ±4); the optimum is (3, 4).
    let rows = [row(Vec2::new(-1.0, 0.0), -3.0, 1e4, 1.0)];
    assert_near(solve_and_compare(Vec2::new(6.0, 8.0), &rows, 5.0), Vec2::new(3.0, 4.0), 1e-9);
    // Full braking demanded beyond δ: the row's slack is positive and u is on the ball.
    let rows = [row(Vec2::new(1.0, 0.0), -7.0, 1e4, 1.0)];
    assert_near(solve_and_compare(Vec2::new(1.0, 0.0), &rows, 5.0), Vec2::new(-5.0, 0.0), 1e-9);
}

#[test]
fn zero_and_tiny_rows() {
    let rows = [
        row(Vec2::zeros(), -0.5, 1e4, 1.0),
        row(Vec2::new(1e-9, 0.0), 0.3, 1e4, 1.0),
        row(Vec2::new(1.0, 0.0), 1.0, 1e4, 1.0),
    ];
    let u = solve_and_compare(Vec2::new(2.0, 0.0), &rows, 5.0);
    assert_near(u, Vec2::new(1.0, 0.0), 1e-9);
}

#[test]
fn paper_objective_without_linear_penalty() {
    // ρ = 0, P = 1: r = t/(1 + P) for one row: x = 2 − (2 − 1)/2 = 1.5.
    let u = solve_and_compare(Vec2::new(2.0, 0.0), &[row(Vec2::new(1.0, 0.0), 1.0, 0.0, 1.0)], 5.0);
    assert_near(u, Vec2::new(1.5, 0.0), 1e-12);
}

#[test]
fn many_rows() {
    let u_r = Vec2::new(3.0, 1.0);
    let rows: Vec<_> =
        (0..64).map(|k| unit(0.1 * k as f64)).map(|a| row(a, a.dot(&u_r) - 1.0, 1e4, 1.0)).collect();
    solve_and_compare(u_r, &rows, 5.0);
}

#[test]
fn invalid_data_is_an_error() {
    let mut exact = ExactSolver::new();
    let ok = row(Vec2::new(1.0, 0.0), 1.0, 1e4, 1.0);
    assert_eq!(exact.solve(Vec2::new(f64::NAN, 0.0), &[ok], 5.0), Err(ExactError::NonFinite));
    assert_eq!(
        exact.solve(Vec2::zeros(), &[row(Vec2::new(f64::INFINITY, 0.0), 1.0, 1.0, 1.0)], 5.0),
        Err(ExactError::NonFinite)
    );
    assert_eq!(exact.solve(Vec2::zeros(), &[ok], f64::NAN), Err(ExactError::NonFinite));
    assert!(matches!(exact.solve(Vec2::zeros(), &[ok], 0.0), Err(ExactError::Invalid(_))));
    assert!(matches!(
        exact.solve(Vec2::zeros(), &[row(Vec2::new(1.0, 0.0), 1.0, -1.0, 1.0)], 5.0),
        Err(ExactError::Invalid(_))
    ));
}

/// The certificate itself can fail: a wrong answer is rejected.
#[test]
fn kkt_residual_rejects_a_wrong_answer() {
    let rows = [row(Vec2::new(1.0, 0.0), 1.0, 1e4, 1.0)];
    let good = kkt_residual(Vec2::new(2.0, 0.0), &rows, 5.0, Vec2::new(1.0, 0.0), &[1.0], 0.0);
    assert!(good.max() <= 1e-15, "{good:?}");
    let moved = kkt_residual(Vec2::new(2.0, 0.0), &rows, 5.0, Vec2::new(1.0, 0.001), &[1.0], 0.0);
    assert!(moved.stationarity > 1e-4);
    let over = kkt_residual(Vec2::new(2.0, 0.0), &rows, 5.0, Vec2::new(1.0, 0.0), &[2e4], 0.0);
    assert!(over.multipliers > 0.5 && over.stationarity > 0.5);
}
