//! The closed-form shortcut of the Clarabel path (one binding constraint) returns the same input as
//! Clarabel. (The exact solver is checked against Clarabel in `exact_solver.rs`.)

use proptest::prelude::*;
use safety::{ConstraintRow, FilterSettings, QpSolver, Row, RowKind, SafetyFilter, Solver};
use uav::Vec2;

fn unit(angle: f64) -> Vec2 {
    Vec2::new(angle.cos(), angle.sin())
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(3000))]

    #[test]
    fn filter_matches_clarabel(
        delta in 1.0..8.0f64,
        (angle, scale) in (0.0..std::f64::consts::TAU, 0.0..2.0f64),
        rows in prop::collection::vec((0.0..std::f64::consts::TAU, -6.0..6.0f64, 0.01..6.0f64, any::<bool>()), 1..5),
    ) {
        let u_ref = unit(angle) * (scale * delta);
        let rows: Vec<Row> = rows
            .into_iter()
            .map(|(t, c, b, road)| Row { a: unit(t), c, b, kind: if road { RowKind::Road(0) } else { RowKind::Collision(0) } })
            .collect();
        let settings = FilterSettings { solver: Solver::Clarabel, ..FilterSettings::default() };
        let out = SafetyFilter::new(settings).filter(u_ref, Vec2::zeros(), &rows, delta, 0.05);
        let constraints: Vec<ConstraintRow> = settings.constraint_rows(&rows, delta).collect();
        let reference = QpSolver::new().solve(u_ref, &constraints, delta);
        prop_assume!(reference.status == clarabel::solver::SolverStatus::Solved && !out.failed);
        // Clarabel stops within its tolerances, the closed form is exact. Without slack the objective
        // is ½‖u − u_ref‖², 1-strongly convex: a feasible point e above the optimum's objective lies
        // within √(2e) of it, so Clarabel's own excess over the filter's objective bounds how far
        // apart the two may be (it once stopped 2.3e-4 m/s² off an unconstrained u_ref).
        // Both objectives are computed here, at each input: Clarabel's reported objective carries its
        // own rounding (once 1e-8 above the value at its own u, which the filter had returned).
        let objective = 0.5 * (out.u - u_ref).norm_squared();
        let clarabel_objective = 0.5 * (reference.u - u_ref).norm_squared();
        let unslacked = out.max_slack == 0.0 && reference.max_slack == 0.0;
        let excess = if unslacked { (clarabel_objective - objective).max(0.0) } else { 0.0 };
        prop_assert!(
            (out.u - reference.u).norm() <= 1e-4 * delta + (2.0 * excess).sqrt(),
            "filter {:?} vs Clarabel {:?}", out, reference
        );
        // And the filter's input is never worse than Clarabel's.
        prop_assert!(!unslacked || objective <= clarabel_objective + 1e-9, "filter {:?} vs Clarabel {:?}", out, reference);
    }
}
