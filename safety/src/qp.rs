//! The per-UAV QP of docs/safety.md §6 in Clarabel's standard form, with one solver per row count
//! built once and then only updated (`update_P/q/A/b`; presolve and zero-dropping off so the pattern
//! is fixed).
//!
//! `min_{u_q, r} ½‖u_q‖² + Σ_c (ρ_c r_c + ½P_c r_c²)  s.t.  a_cᵀ(u_r + u_q) ≤ c_c + r_c,  r_c ≥ 0,
//! ‖u_r + u_q‖ ≤ δ`, with x = [u_q; r].

use clarabel::algebra::CscMatrix;
use clarabel::solver::{
    DefaultSettings, DefaultSolver, IPSolver, SolverStatus, SupportedConeT::NonnegativeConeT,
    SupportedConeT::SecondOrderConeT,
};
use uav::Vec2;

/// Row counts up to this keep a cached solver; larger problems build a fresh one per solve.
const MAX_CACHED_ROWS: usize = 64;

/// One constraint `aᵀu ≤ c + r` with its slack's exact penalty ρ and quadratic weight P.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ConstraintRow {
    /// Row direction a.
    pub a: Vec2,
    /// Right-hand side c.
    pub c: f64,
    /// Linear (exact, L1) slack penalty ρ.
    pub rho: f64,
    /// Quadratic slack weight P.
    pub weight: f64,
}

/// Result of one QP solve.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct QpSolution {
    /// The filtered input u = u_r + u_q, projected onto the δ-ball against round-off.
    pub u: Vec2,
    /// Largest slack r_c.
    pub max_slack: f64,
    /// Objective value ½‖u_q‖² + Σ(ρr + ½Pr²).
    pub objective: f64,
    /// Clarabel's final status (after the retry, if one was needed).
    pub status: SolverStatus,
    /// True when the cached solver did not reach `Solved` and fresh solvers were tried.
    pub retried: bool,
}

/// Clarabel-backed QP solver with cached problem structures and scratch buffers.
pub struct QpSolver {
    cache: Vec<Option<DefaultSolver<f64>>>,
    p_vals: Vec<f64>,
    q: Vec<f64>,
    a_vals: Vec<f64>,
    b: Vec<f64>,
    slacks: Vec<f64>,
    x_u: Vec2,
    /// Clarabel's gap and feasibility tolerances.
    tol: f64,
}

/// The filter's Clarabel tolerances (gap, absolute and relative, and feasibility).
pub const CLARABEL_TOL: f64 = 1e-9;

impl Default for QpSolver {
    fn default() -> Self {
        Self::new()
    }
}

/// Which Clarabel settings an attempt uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Attempt {
    /// The cached solver: equilibration on, iterative refinement off (fastest, see BENCHMARKS.md).
    Fast,
    /// A freshly built solver with Clarabel's defaults (equilibration computed for this instance,
    /// iterative refinement on): cached solvers reuse the scaling of the instance they were built for.
    Fresh,
    /// A fresh solver without equilibration and with a shorter maximum step (docs/safety.md §10.2).
    Robust,
}

fn settings(attempt: Attempt, tol: f64) -> DefaultSettings<f64> {
    DefaultSettings {
        verbose: false,
        presolve_enable: false,
        input_sparse_dropzeros: false,
        tol_gap_abs: tol,
        tol_gap_rel: tol,
        tol_feas: tol,
        // The slack penalties (ρ from 10³ to 10⁵ next to unit weights) make the data badly scaled:
        // equilibration halves the iterations, and iterative refinement costs a third of the time
        // without changing the result at these tolerances (`airroads bench filter`).
        equilibrate_enable: attempt != Attempt::Robust,
        iterative_refinement_enable: attempt != Attempt::Fast,
        max_step_fraction: if attempt == Attempt::Robust { 0.9 } else { 0.99 },
        ..DefaultSettings::default()
    }
}

/// Sparsity pattern of P (diagonal) and A for m rows; values are filled by [`QpSolver::fill`].
fn pattern(m: usize, p_vals: &[f64], a_vals: &[f64]) -> (CscMatrix<f64>, CscMatrix<f64>) {
    let n = 2 + m;
    let p = CscMatrix::new(n, n, (0..=n).collect(), (0..n).collect(), p_vals.to_vec());
    let mut colptr = vec![0, m + 1, 2 * m + 2];
    let mut rowval: Vec<usize> = (0..m).chain([2 * m + 1]).chain(0..m).chain([2 * m + 2]).collect();
    for c in 0..m {
        rowval.extend([c, m + c]);
        colptr.push(colptr[colptr.len() - 1] + 2);
    }
    let a = CscMatrix::new(2 * m + 3, n, colptr, rowval, a_vals.to_vec());
    (p, a)
}

impl QpSolver {
    /// An empty solver; structures are built on first use for each row count.
    pub fn new() -> Self {
        Self::with_tolerance(CLARABEL_TOL)
    }

    /// An empty solver with Clarabel's gap and feasibility tolerances set to `tol` instead of
    /// [`CLARABEL_TOL`] (a tighter reference for checking the exact solver, `airroads bench solver`).
    pub fn with_tolerance(tol: f64) -> Self {
        Self {
            cache: Vec::new(),
            p_vals: Vec::new(),
            q: Vec::new(),
            a_vals: Vec::new(),
            b: Vec::new(),
            slacks: Vec::new(),
            x_u: Vec2::zeros(),
            tol,
        }
    }

    /// The slacks r_c of the last solve.
    pub fn slacks(&self) -> &[f64] {
        &self.slacks
    }

    /// Writes P, q, A, b of the problem into the scratch buffers, in the pattern's order.
    fn fill(&mut self, u_r: Vec2, rows: &[ConstraintRow], delta: f64) {
        let m = rows.len();
        self.p_vals.clear();
        self.p_vals.extend([1.0, 1.0]);
        self.p_vals.extend(rows.iter().map(|r| r.weight));
        self.q.clear();
        self.q.extend([0.0, 0.0]);
        self.q.extend(rows.iter().map(|r| r.rho));
        self.a_vals.clear();
        self.a_vals.extend(rows.iter().map(|r| r.a.x));
        self.a_vals.push(-1.0);
        self.a_vals.extend(rows.iter().map(|r| r.a.y));
        self.a_vals.push(-1.0);
        self.a_vals.extend(std::iter::repeat_n(-1.0, 2 * m));
        self.b.clear();
        self.b.extend(rows.iter().map(|r| r.c - r.a.dot(&u_r)));
        self.b.extend(std::iter::repeat_n(0.0, m));
        self.b.extend([delta, u_r.x, u_r.y]);
    }

    fn build(&self, m: usize, attempt: Attempt) -> Option<DefaultSolver<f64>> {
        let (p, a) = pattern(m, &self.p_vals, &self.a_vals);
        let cones = [NonnegativeConeT(2 * m), SecondOrderConeT(3)];
        DefaultSolver::new(&p, &self.q, &a, &self.b, &cones, settings(attempt, self.tol)).ok()
    }

    /// Builds a fresh solver for the filled data, solves and reads the result.
    fn solve_fresh(&mut self, m: usize, attempt: Attempt) -> SolverStatus {
        match self.build(m, attempt) {
            Some(mut solver) => {
                solver.solve();
                self.read(&solver, m);
                solver.solution.status
            }
            None => SolverStatus::NumericalError,
        }
    }

    /// Solves with the cached solver for m rows (built on first use), returning its status.
    fn solve_cached(&mut self, m: usize) -> SolverStatus {
        if m > MAX_CACHED_ROWS {
            return SolverStatus::Unsolved;
        }
        if self.cache.len() <= m {
            self.cache.resize_with(m + 1, || None);
        }
        let mut solver = match self.cache[m].take() {
            Some(mut solver) => {
                let updated = solver
                    .update_P(&self.p_vals)
                    .and_then(|()| solver.update_q(&self.q))
                    .and_then(|()| solver.update_A(&self.a_vals))
                    .and_then(|()| solver.update_b(&self.b));
                if updated.is_err() {
                    return SolverStatus::Unsolved;
                }
                solver
            }
            None => match self.build(m, Attempt::Fast) {
                Some(solver) => solver,
                None => return SolverStatus::Unsolved,
            },
        };
        solver.solve();
        self.read(&solver, m);
        let status = solver.solution.status;
        self.cache[m] = Some(solver);
        status
    }

    /// Copies u_q and the slacks out of a solver's solution.
    fn read(&mut self, solver: &DefaultSolver<f64>, m: usize) {
        let x = &solver.solution.x;
        self.x_u = Vec2::new(x[0], x[1]);
        self.slacks.clear();
        self.slacks.extend(x[2..2 + m].iter().map(|r| r.max(0.0)));
    }

    /// Solves the QP for nominal input `u_r`, rows `rows` and bound δ. Never panics: a status other
    /// than `Solved` is reported in the result for the caller to act on.
    pub fn solve(&mut self, u_r: Vec2, rows: &[ConstraintRow], delta: f64) -> QpSolution {
        let m = rows.len();
        self.fill(u_r, rows, delta);
        let mut status = self.solve_cached(m);
        let retried = status != SolverStatus::Solved;
        for attempt in [Attempt::Fresh, Attempt::Robust] {
            if status == SolverStatus::Solved {
                break;
            }
            status = self.solve_fresh(m, attempt);
        }
        let x_u = self.x_u;
        let u = uav::saturate(u_r + x_u, delta);
        let objective = 0.5 * x_u.norm_squared()
            + rows.iter().zip(&self.slacks).map(|(r, s)| r.rho * s + 0.5 * r.weight * s * s).sum::<f64>();
        let max_slack = self.slacks.iter().copied().fold(0.0, f64::max);
        QpSolution { u, max_slack, objective, status, retried }
    }
}
