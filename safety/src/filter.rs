//! The safety filter of one UAV: skip the QP when the nominal input already satisfies every row
//! (docs/safety.md §10.2), otherwise solve it (with the exact solver of §11 or with Clarabel); a
//! result that is not `Solved` is never applied: the UAV brakes.

use crate::barrier::{Row, RowKind};
use crate::exact::{ExactError, ExactSolver};
use crate::qp::{ConstraintRow, QpSolver};
use clarabel::solver::SolverStatus;
use uav::{Vec2, braking_input};

/// Which objective the QP minimises.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Objective {
    /// ½‖u_q‖² + Σ(ρ r + ½P r²): the exact penalty ρ keeps every slack at 0 whenever the hard
    /// problem is feasible (docs/safety.md §6, E7).
    #[default]
    Exact,
    /// The paper's (17) with ‖u_q‖ squared so it is a QP: ½‖u_q‖² + Σ ½P r², no linear penalty; its
    /// slacks are never 0 while a row is active (E7). For comparison only.
    Paper,
}

impl Objective {
    /// The CLI/JSON name.
    pub fn name(&self) -> &'static str {
        match self {
            Objective::Exact => "exact",
            Objective::Paper => "paper",
        }
    }
}

impl std::str::FromStr for Objective {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "exact" => Ok(Objective::Exact),
            "paper" => Ok(Objective::Paper),
            other => Err(format!("unknown objective `{other}` (expected exact or paper)")),
        }
    }
}

/// Which solver the filter uses for its QP.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Solver {
    /// The exact active-set solver with a KKT certificate (docs/safety.md §11); an answer it cannot
    /// certify goes to Clarabel.
    #[default]
    Exact,
    /// Clarabel (interior point, tolerances 10⁻⁹), after the one-constraint closed form (§6, §10.2).
    Clarabel,
}

impl Solver {
    /// The CLI/JSON name.
    pub fn name(&self) -> &'static str {
        match self {
            Solver::Exact => "exact",
            Solver::Clarabel => "clarabel",
        }
    }
}

impl std::str::FromStr for Solver {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "exact" => Ok(Solver::Exact),
            "clarabel" => Ok(Solver::Clarabel),
            other => Err(format!("unknown solver `{other}` (expected exact or clarabel)")),
        }
    }
}

/// Slack weights and objective (docs/safety.md §6 reference values).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FilterSettings {
    /// Exact penalty ρ of a collision row's slack. 10⁴ rather than the design's reference 10³
    /// (docs/safety.md §6): the multipliers of thin feasible slivers (a UAV squeezed between two
    /// neighbours) exceed 2·10³.
    pub rho_collision: f64,
    /// Quadratic weight P of a collision row's slack.
    pub weight_collision: f64,
    /// Factor applied to ρ and P for road rows (road rows have priority).
    pub road_priority: f64,
    /// Urgency weighting: when > 0, each row's ρ and P are also divided by `clamp(b, urgency_floor, 1)`
    /// (b in m/s), so when rows conflict the QP relaxes those with a comfortable barrier value first and
    /// keeps the ones about to reach b = 0. Rows with b ≥ 1 keep the reference weights, so the weights
    /// are never below them. 0 disables it (the fixed weights of docs/safety.md §6).
    pub urgency_floor: f64,
    /// The objective.
    pub objective: Objective,
    /// The QP solver.
    pub solver: Solver,
}

impl Default for FilterSettings {
    fn default() -> Self {
        Self {
            rho_collision: 1e4,
            weight_collision: 1.0,
            road_priority: 10.0,
            urgency_floor: 0.05,
            objective: Objective::Exact,
            solver: Solver::Exact,
        }
    }
}

impl FilterSettings {
    /// The QP rows the filter solves for CBF `rows` under ‖u‖ ≤ δ: rows that cannot bind (c ≥ δ)
    /// dropped, right-hand sides clamped at −2δ, slack weights from [`Self::slack_weights`].
    pub fn constraint_rows<'a>(
        &'a self,
        rows: &'a [Row],
        delta: f64,
    ) -> impl Iterator<Item = ConstraintRow> + 'a {
        rows.iter().filter(move |r| r.c < delta).map(move |r| {
            let (rho, weight) = self.slack_weights(r);
            ConstraintRow { a: r.a, c: r.c.max(MIN_RHS_IN_DELTAS * delta), rho, weight }
        })
    }

    /// The slack penalty (ρ, P) of a row: the collision reference, ×`road_priority` for road rows,
    /// ×1/clamp(b, `urgency_floor`, 1) when urgency weighting is on; ρ = 0 with the paper's objective.
    pub fn slack_weights(&self, row: &Row) -> (f64, f64) {
        let kind = if matches!(row.kind, RowKind::Road(_)) { self.road_priority } else { 1.0 };
        let urgency =
            if self.urgency_floor > 0.0 { 1.0 / row.b.max(self.urgency_floor).min(1.0) } else { 1.0 };
        let priority = kind * urgency;
        let rho = if self.objective == Objective::Exact { self.rho_collision * priority } else { 0.0 };
        (rho, self.weight_collision * priority)
    }
}

/// What the filter did for one UAV in one tick.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FilterOutcome {
    /// The input to apply, ‖u‖ ≤ δ.
    pub u: Vec2,
    /// True when a QP was solved (false when the nominal input was already safe).
    pub solved: bool,
    /// True when that QP was solved without Clarabel: by the exact solver ([`Solver::Exact`], its
    /// answer certified by KKT), or in closed form with one binding constraint ([`Solver::Clarabel`]).
    pub closed_form: bool,
    /// True when the solver did not reach `Solved` even after the retry, or the data were not
    /// finite: `u` is then full braking.
    pub failed: bool,
    /// Largest slack of the solve (0 when skipped).
    pub max_slack: f64,
    /// Rows that are binding at `u` (aᵀu ≥ c − 10⁻⁶).
    pub active_rows: usize,
    /// Clarabel's status: `Solved` when the QP was skipped or solved without Clarabel (the exact
    /// solver's certified answer, the closed form); `NumericalError` when the data were not finite.
    pub status: SolverStatus,
}

/// The per-UAV safety filter with its reusable solver and scratch rows.
#[derive(Default)]
pub struct SafetyFilter {
    /// Weights and objective.
    pub settings: FilterSettings,
    solver: QpSolver,
    exact: ExactSolver,
    scratch: Vec<ConstraintRow>,
}

/// Rows with c ≥ δ can never bind under ‖u‖ ≤ δ with ‖a‖ = 1; rows with c below this many δ are
/// clamped. Such a row (b < 0, docs/safety.md §4.1) already asks for more than full braking, so its
/// slack is positive either way and the exact penalty makes the QP brake as hard as the other rows
/// allow; the clamp keeps one violated row's quadratic penalty from swamping every other row (in jams
/// that made the inputs chatter between opposite full-braking directions).
const MIN_RHS_IN_DELTAS: f64 = -2.0;

impl SafetyFilter {
    /// A filter with the given settings.
    pub fn new(settings: FilterSettings) -> Self {
        Self { settings, ..Self::default() }
    }

    /// Filters nominal input `u_ref` of a UAV with velocity `v` against `rows`, under ‖u‖ ≤ δ.
    pub fn filter(&mut self, u_ref: Vec2, v: Vec2, rows: &[Row], delta: f64, dt: f64) -> FilterOutcome {
        self.filter_timed(u_ref, v, rows, delta, dt).0
    }

    /// [`SafetyFilter::filter`], with how long its QP took when it solved one (the clock is read
    /// only then: a nominal input that is already safe costs no clock reads).
    pub fn filter_timed(
        &mut self,
        u_ref: Vec2,
        v: Vec2,
        rows: &[Row],
        delta: f64,
        dt: f64,
    ) -> (FilterOutcome, Option<std::time::Duration>) {
        let data_ok = uav::is_finite(&u_ref) && rows.iter().all(|r| uav::is_finite(&r.a) && r.c.is_finite());
        if !data_ok {
            return (self.brake(v, delta, dt), None);
        }
        let safe = |u: &Vec2| rows.iter().all(|r| r.a.dot(u) <= r.c);
        if u_ref.norm() <= delta && safe(&u_ref) {
            let active_rows = count_active(rows, &u_ref);
            let kept = FilterOutcome {
                u: u_ref,
                solved: false,
                closed_form: false,
                failed: false,
                max_slack: 0.0,
                active_rows,
                status: SolverStatus::Solved,
            };
            return (kept, None);
        }
        let started = std::time::Instant::now();
        let out = self.solve(u_ref, v, rows, delta, dt);
        (out, Some(started.elapsed()))
    }

    /// The QP of [`SafetyFilter::filter`] for a nominal input that is not safe as it is.
    fn solve(&mut self, u_ref: Vec2, v: Vec2, rows: &[Row], delta: f64, dt: f64) -> FilterOutcome {
        self.scratch.clear();
        self.scratch.extend(self.settings.constraint_rows(rows, delta));
        if self.settings.solver == Solver::Exact {
            match self.exact.solve(u_ref, &self.scratch, delta) {
                Ok(sol) => {
                    return FilterOutcome {
                        u: sol.u,
                        solved: true,
                        closed_form: true,
                        failed: false,
                        max_slack: sol.max_slack,
                        active_rows: count_active(rows, &sol.u),
                        status: sol.status,
                    };
                }
                Err(ExactError::NonFinite | ExactError::Invalid(_)) => return self.brake(v, delta, dt),
                // Not certified (2 in 10⁶ instances of `airroads bench solver`): Clarabel decides.
                Err(ExactError::NotCertified { .. }) => {}
            }
        }
        if let Some(u) = closed_form(u_ref, &self.scratch, delta) {
            let active_rows = count_active(rows, &u);
            return FilterOutcome {
                u,
                solved: true,
                closed_form: true,
                failed: false,
                max_slack: 0.0,
                active_rows,
                status: SolverStatus::Solved,
            };
        }
        let sol = self.solver.solve(u_ref, &self.scratch, delta);
        // Clarabel stops at reduced accuracy (`AlmostSolved`) on nearly degenerate problems (a
        // feasible set that is a sliver at the δ-ball's edge); its answer is used only when every row
        // holds at it with the slack it reports, to 1e-6, like a `Solved` one.
        let usable = sol.status == SolverStatus::Solved
            || (sol.status == SolverStatus::AlmostSolved
                && holds_with_slack(&self.scratch, &sol.u, self.solver.slacks()));
        if !usable {
            return FilterOutcome { status: sol.status, ..self.brake(v, delta, dt) };
        }
        FilterOutcome {
            u: sol.u,
            solved: true,
            closed_form: false,
            failed: false,
            max_slack: sol.max_slack,
            active_rows: count_active(rows, &sol.u),
            status: sol.status,
        }
    }

    fn brake(&self, v: Vec2, delta: f64, dt: f64) -> FilterOutcome {
        let u = braking_input(v, delta, dt);
        FilterOutcome {
            u,
            solved: false,
            closed_form: false,
            failed: true,
            max_slack: 0.0,
            active_rows: 0,
            status: SolverStatus::NumericalError,
        }
    }
}

/// Feasibility tolerance of the closed-form shortcut, as Clarabel's (1e-9).
const CLOSED_FORM_TOL: f64 = 1e-9;

/// The exact optimum when only one constraint binds, without a solver: the projection of `u_ref` onto
/// the δ-ball, or onto one row's half-plane, if it satisfies every row and the bound. For a row, its
/// multiplier a·u_ref − c must also be within ρ, so the exact-penalty optimum has zero slack there.
/// (KKT: the other rows and the bound are inactive, so the projection is the optimum.)
fn closed_form(u_ref: Vec2, rows: &[ConstraintRow], delta: f64) -> Option<Vec2> {
    let feasible = |u: &Vec2| {
        u.norm() <= delta * (1.0 + CLOSED_FORM_TOL)
            && rows.iter().all(|r| r.a.dot(u) <= r.c + CLOSED_FORM_TOL)
    };
    let norm = u_ref.norm();
    if norm > delta && feasible(&(u_ref * (delta / norm))) {
        return Some(u_ref * (delta / norm));
    }
    rows.iter().find_map(|r| {
        let lambda = r.a.dot(&u_ref) - r.c;
        let u = u_ref - r.a * lambda;
        (lambda > 0.0 && lambda <= r.rho && feasible(&u)).then_some(u)
    })
}

/// Every QP row holds at `u` with its slack: aᵀu ≤ c + r, to 1e-6.
fn holds_with_slack(rows: &[ConstraintRow], u: &Vec2, slacks: &[f64]) -> bool {
    rows.len() == slacks.len() && rows.iter().zip(slacks).all(|(r, s)| r.a.dot(u) <= r.c + s + 1e-6)
}

fn count_active(rows: &[Row], u: &Vec2) -> usize {
    rows.iter().filter(|r| r.a.dot(u) >= r.c - 1e-6).count()
}
