//! The KKT certificate of a solution of the QP of docs/safety.md §6, computed from (u, λ, μ) alone so
//! that it checks the exact solver independently of how the solver found them (docs/safety.md §11).

use crate::qp::ConstraintRow;
use uav::Vec2;

/// KKT residuals of a candidate (u, λ, μ), each relative to the size of the terms it compares.
///
/// With r_c = max(0, a_cᵀu − c_c) (the slack the objective picks for u), ν_c = ρ_c + P_c r_c − λ_c
/// (the multiplier of r_c ≥ 0) and κ = 1 + μ:
/// - `stationarity`: ‖κu − u_r + Σ λ_c a_c‖ / max(1, ‖u_r‖, κ‖u‖, Σ|λ_c|‖a_c‖);
/// - `primal`: (‖u‖ − δ)₊ / max(1, δ) (the rows hold with r_c by construction);
/// - `complementarity`: the largest of λ_c(c_c + r_c − a_cᵀu)/(1 + λ_c), ν_c r_c/(1 + |ν_c|) and
///   μ(δ − ‖u‖)₊/((1 + μ) max(1, δ)): a gap in m/s² for a multiplier ≥ 1, the product below;
/// - `multipliers`: how far λ_c leaves [0, ρ_c + P_c r_c] (over max(1, ρ_c + P_c r_c)) and μ leaves [0, ∞).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct KktResidual {
    /// Relative residual of ∇ₓL = 0.
    pub stationarity: f64,
    /// Relative violation of ‖u‖ ≤ δ.
    pub primal: f64,
    /// Largest relative complementarity product.
    pub complementarity: f64,
    /// Largest relative violation of 0 ≤ λ_c ≤ ρ_c + P_c r_c and μ ≥ 0.
    pub multipliers: f64,
}

impl KktResidual {
    /// The largest of the four residuals (NaN counts as infinite).
    pub fn max(&self) -> f64 {
        [self.stationarity, self.primal, self.complementarity, self.multipliers]
            .into_iter()
            .map(|x| if x.is_nan() { f64::INFINITY } else { x })
            .fold(0.0, f64::max)
    }
}

/// The KKT residuals of (u, λ, μ) for nominal input `u_r`, `rows` and bound δ; `lambda` has one
/// multiplier per row (missing ones count as 0).
pub fn kkt_residual(
    u_r: Vec2,
    rows: &[ConstraintRow],
    delta: f64,
    u: Vec2,
    lambda: &[f64],
    mu: f64,
) -> KktResidual {
    let kappa = 1.0 + mu.max(0.0);
    let norm_u = u.norm();
    let mut grad = u * kappa - u_r;
    let mut scale = 1f64.max(u_r.norm()).max(kappa * norm_u);
    let (mut comp, mut mult) = (0f64, 0f64);
    for (c, row) in rows.iter().enumerate() {
        let l = lambda.get(c).copied().unwrap_or(0.0);
        let t = row.a.dot(&u) - row.c;
        let r = t.max(0.0);
        grad += row.a * l;
        scale = scale.max(l.abs() * row.a.norm());
        let cap = row.rho + row.weight * r;
        mult = mult.max((-l).max(l - cap).max(0.0) / cap.max(1.0));
        let nu = cap - l;
        comp = comp.max(l.max(0.0) * (r - t) / (1.0 + l.abs())).max((nu.max(0.0) * r) / (1.0 + nu.abs()));
    }
    let gap = (delta - norm_u).max(0.0);
    comp = comp.max(mu.max(0.0) * gap / (kappa * delta.max(1.0)));
    mult = mult.max(-mu);
    KktResidual {
        stationarity: grad.norm() / scale,
        primal: (norm_u - delta).max(0.0) / delta.max(1.0),
        complementarity: comp,
        multipliers: mult,
    }
}
