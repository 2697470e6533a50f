//! The exact solver of the filter's QP (docs/safety.md §11): with r eliminated, the QP of §6 is the
//! minimisation of the strongly convex piecewise quadratic
//!
//! `F(u) = ½‖u − u_r‖² + Σ_c φ_c(a_cᵀu − c_c)`,  `φ_c(t) = ρ_c t + ½P_c t²` for t > 0, 0 otherwise,
//!
//! over the disk ‖u‖ ≤ δ, with r_c = max(0, a_cᵀu − c_c). The disk is handled by its multiplier μ:
//! u(μ) = argmin F + ½μ‖u‖² is found exactly by a primal active-set method in R² (`inner`, `local`),
//! ‖u(μ)‖ is non-increasing in μ, and μ is the root of ‖u(μ)‖ = δ, solved exactly on the pattern of
//! rows it lands in (with bisection as a safeguard). Every answer carries a KKT certificate
//! ([`kkt_residual`]); an answer that fails it is an error, never a `Solved`.
//!
//! Deterministic and allocation-free in steady state (scratch buffers kept in [`ExactSolver`]).

mod inner;
mod kkt;
mod local;
mod zonotope;

pub use kkt::{KktResidual, kkt_residual};

use crate::qp::{ConstraintRow, QpSolution};
use clarabel::solver::SolverStatus;
use uav::Vec2;

/// Largest KKT residual ([`KktResidual::max`]) of an answer reported as `Solved`.
pub const CERTIFY_TOL: f64 = 1e-9;
/// Rows with ‖a‖ at most this are constant rows: they cost φ_c(−c_c) whatever u is.
const A_MIN: f64 = 1e-150;
/// A row passes through the iterate when |a_cᵀu − c_c| ≤ this × (|c_c| + ‖a_c‖(‖u‖ + δ + ‖u_r‖)).
const TAU_REL: f64 = 1e-13;
/// The ball is active when |‖u‖ − δ| ≤ this × δ.
const BALL_TOL: f64 = 1e-13;
/// Outer (μ) iterations before giving up.
const MAX_OUTER: usize = 100;

/// Why the exact solver returned no certified optimum.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum ExactError {
    /// u_r, a row or δ is NaN or infinite.
    #[error("non-finite QP data")]
    NonFinite,
    /// A weight is negative or δ is not positive.
    #[error("invalid QP data: {0}")]
    Invalid(&'static str),
    /// The iterations ended without an answer whose KKT residual is within [`CERTIFY_TOL`].
    #[error("no certified optimum after {iterations} iterations (KKT residual {residual:e})")]
    NotCertified {
        /// Active-set iterations spent.
        iterations: usize,
        /// KKT residual of the best answer found.
        residual: f64,
    },
}

/// The working set of the active-set method: rows held at a_cᵀu = c_c (at most two, independent).
#[derive(Debug, Clone, Copy, Default)]
struct Working {
    rows: [usize; 2],
    len: usize,
}

impl Working {
    fn contains(&self, c: usize) -> bool {
        self.rows[..self.len].contains(&c)
    }
    fn push(&mut self, c: usize) {
        if self.len < 2 && !self.contains(c) {
            self.rows[self.len] = c;
            self.len += 1;
        }
    }
    fn as_slice(&self) -> &[usize] {
        &self.rows[..self.len]
    }
}

/// One line through the iterate: rows whose lines coincide there (parallel or antiparallel a_c),
/// with the range [lo, hi] of their summed multiplier Λ along the unit normal n.
#[derive(Debug, Clone, Copy, Default)]
struct Group {
    n: Vec2,
    lo: f64,
    hi: f64,
    rep: usize,
    value: f64,
    /// Part of `value` not yet given to a row (scratch of the split among rows).
    left: f64,
}

/// Exact solver for the per-UAV QP, with its scratch buffers.
#[derive(Debug, Default)]
pub struct ExactSolver {
    /// ‖a_c‖ per row.
    norm: Vec<f64>,
    /// t_c = a_cᵀu − c_c at the iterate.
    t: Vec<f64>,
    /// Row c passes through the iterate (or is held in the working set).
    zmark: Vec<bool>,
    /// Group of each marked row.
    gid: Vec<usize>,
    /// Multipliers λ_c of the last answer.
    lambda: Vec<f64>,
    /// Slacks r_c of the last answer.
    slacks: Vec<f64>,
    groups: Vec<Group>,
    /// Scratch: ray angles of the local step; generators of the multiplier zonotope.
    angles: Vec<f64>,
    order: Vec<(f64, usize, bool)>,
    /// Ball multiplier μ of the last answer.
    mu: f64,
    /// Active-set iterations of the last solve.
    iterations: usize,
    /// δ + ‖u_r‖: the size of the inputs, the floor of the scale of t_c's round-off.
    size: f64,
    kkt: KktResidual,
}

impl ExactSolver {
    /// An empty solver; buffers grow to the largest row count seen and are then reused.
    pub fn new() -> Self {
        Self::default()
    }

    /// The multipliers λ_c of the rows at the last answer.
    pub fn multipliers(&self) -> &[f64] {
        &self.lambda
    }

    /// The multiplier μ of ‖u‖ ≤ δ (in the form ½μ(‖u‖² − δ²)) at the last answer.
    pub fn ball_multiplier(&self) -> f64 {
        self.mu
    }

    /// The slacks r_c = max(0, a_cᵀu − c_c) of the last answer.
    pub fn slacks(&self) -> &[f64] {
        &self.slacks
    }

    /// Active-set iterations of the last solve (over all values of μ tried).
    pub fn iterations(&self) -> usize {
        self.iterations
    }

    /// The KKT residuals of the last answer.
    pub fn kkt(&self) -> KktResidual {
        self.kkt
    }

    /// Solves the QP for nominal input `u_r`, `rows` and bound δ; `Ok` only with a KKT certificate
    /// within [`CERTIFY_TOL`] (status `Solved`, `retried` false).
    pub fn solve(&mut self, u_r: Vec2, rows: &[ConstraintRow], delta: f64) -> Result<QpSolution, ExactError> {
        validate(u_r, rows, delta)?;
        let m = rows.len();
        self.norm.clear();
        self.norm.extend(rows.iter().map(|r| r.a.norm()));
        for buf in [&mut self.t, &mut self.lambda, &mut self.slacks] {
            buf.clear();
            buf.resize(m, 0.0);
        }
        self.zmark.clear();
        self.zmark.resize(m, false);
        self.gid.clear();
        self.gid.resize(m, 0);
        self.iterations = 0;
        self.size = delta + u_r.norm();
        let (mut u, mut w) = self.start(rows, u_r, 4.0 * (delta + u_r.norm()));
        let mut mu = 0.0;
        let mut done = self.inner(rows, u_r, 1.0, &mut u, &mut w);
        if done && u.norm() > delta * (1.0 + BALL_TOL) {
            done = self.ball(rows, u_r, delta, &mut u, &mut w, &mut mu);
        }
        self.finish(rows, u_r, delta, u, mu, done)
    }

    /// Finds μ > 0 with ‖u(μ)‖ = δ, starting from u = u(0) outside the ball; false if an inner solve
    /// failed or the iterations ran out.
    fn ball(
        &mut self,
        rows: &[ConstraintRow],
        u_r: Vec2,
        delta: f64,
        u: &mut Vec2,
        w: &mut Working,
        mu: &mut f64,
    ) -> bool {
        let (mut lo, mut hi, mut hi_seen) = (0.0, self.mu_bound(rows, u_r, delta), false);
        let mut next = self.pattern_root(rows, u_r, delta, lo);
        for _ in 0..MAX_OUTER {
            let guess = match next {
                Some(g) if g > lo && g < hi => g,
                _ if hi_seen || lo > 0.0 => 0.5 * (lo + hi),
                _ => hi.min(1.0),
            };
            *mu = guess;
            if !self.inner(rows, u_r, 1.0 + guess, u, w) {
                return false;
            }
            let n = u.norm();
            if (n - delta).abs() <= BALL_TOL * delta {
                return true;
            }
            if n > delta {
                lo = guess;
            } else {
                (hi, hi_seen) = (guess, true);
            }
            if hi - lo <= f64::EPSILON * hi {
                return true;
            }
            next = self.pattern_root(rows, u_r, delta, lo);
        }
        false
    }

    /// An upper bound on the ball multiplier: at the optimum κ‖u‖ = ‖u_r − Σλ_c a_c‖ with
    /// λ_c ≤ ρ_c + P_c(‖a_c‖δ + |c_c|).
    fn mu_bound(&self, rows: &[ConstraintRow], u_r: Vec2, delta: f64) -> f64 {
        let pull: f64 =
            rows.iter().zip(&self.norm).map(|(r, n)| n * (r.rho + r.weight * (n * delta + r.c.abs()))).sum();
        2.0 * (u_r.norm() + pull) / delta + 1.0
    }

    /// Completes the answer at u: multipliers of the rows off the iterate's lines, slacks, objective
    /// and the KKT certificate.
    fn finish(
        &mut self,
        rows: &[ConstraintRow],
        u_r: Vec2,
        delta: f64,
        mut u: Vec2,
        mu: f64,
        done: bool,
    ) -> Result<QpSolution, ExactError> {
        let n = u.norm();
        if n > delta {
            u *= delta / n;
        }
        self.mu = mu;
        let mut slack_cost = 0.0;
        let mut max_slack = 0f64;
        for (c, r) in rows.iter().enumerate() {
            let t = r.a.dot(&u) - r.c;
            let s = t.max(0.0);
            if !self.zmark[c] {
                self.lambda[c] = if t > 0.0 { r.rho + r.weight * t } else { 0.0 };
            }
            self.slacks[c] = s;
            slack_cost += r.rho * s + 0.5 * r.weight * s * s;
            max_slack = max_slack.max(s);
        }
        self.kkt = kkt_residual(u_r, rows, delta, u, &self.lambda, mu);
        let residual = self.kkt.max();
        if !done || residual > CERTIFY_TOL {
            return Err(ExactError::NotCertified { iterations: self.iterations, residual });
        }
        let objective = 0.5 * (u - u_r).norm_squared() + slack_cost;
        Ok(QpSolution { u, max_slack, objective, status: SolverStatus::Solved, retried: false })
    }
}

/// Checks that the data are finite and the weights and δ admissible.
fn validate(u_r: Vec2, rows: &[ConstraintRow], delta: f64) -> Result<(), ExactError> {
    let finite = uav::is_finite(&u_r)
        && delta.is_finite()
        && rows
            .iter()
            .all(|r| uav::is_finite(&r.a) && r.c.is_finite() && r.rho.is_finite() && r.weight.is_finite());
    if !finite {
        return Err(ExactError::NonFinite);
    }
    if delta <= 0.0 {
        return Err(ExactError::Invalid("δ must be positive"));
    }
    if rows.iter().any(|r| r.rho < 0.0 || r.weight < 0.0) {
        return Err(ExactError::Invalid("slack weights ρ and P must be non-negative"));
    }
    Ok(())
}

/// Solution of the 2×2 symmetric system [[h00, h01], [h01, h11]] x = g (None if singular).
fn solve_sym(h: [f64; 3], g: Vec2) -> Option<Vec2> {
    let det = h[0] * h[2] - h[1] * h[1];
    (det > 0.0 && det.is_finite()).then(|| Vec2::new(h[2] * g.x - h[1] * g.y, h[0] * g.y - h[1] * g.x) / det)
}

/// Adds P·a aᵀ to the packed symmetric 2×2 matrix h.
fn add_outer(h: &mut [f64; 3], a: Vec2, p: f64) {
    h[0] += p * a.x * a.x;
    h[1] += p * a.x * a.y;
    h[2] += p * a.y * a.y;
}

/// The left normal of a: a rotated by +90°.
fn perp(a: Vec2) -> Vec2 {
    Vec2::new(-a.y, a.x)
}
