//! Test helpers shared by the integration tests: an exact, solver-free oracle of the hard QP
//! `min ½‖u − u_r‖² s.t. aᵢᵀu ≤ cᵢ, ‖u‖ ≤ δ` in 2-D and its KKT multipliers.

#![allow(dead_code)]

pub mod roads;

use uav::Vec2;

/// Feasibility tolerance of the oracle's candidates.
const FEAS_TOL: f64 = 1e-10;
/// A constraint counts as active within this distance of its boundary.
const ACTIVE_TOL: f64 = 1e-8;

/// The hard problem's optimum and, when the active set is regular, its multipliers.
#[derive(Debug, Clone)]
pub struct Hard {
    /// The minimiser (the projection of u_r onto the feasible set).
    pub u: Vec2,
    /// λᵢ of each row (0 when inactive); `None` when more than two constraints are active or two
    /// active normals are (nearly) parallel, i.e. the multipliers are not unique or ill-defined.
    pub multipliers: Option<Vec<f64>>,
}

fn feasible(x: &Vec2, rows: &[(Vec2, f64)], delta: f64) -> bool {
    x.norm() <= delta * (1.0 + 1e-12) && rows.iter().all(|(a, c)| a.dot(x) <= c + FEAS_TOL)
}

/// Solves the hard problem exactly by enumerating the candidate optima of every face of the feasible
/// set (interior, lines, arc, line–line and line–circle vertices). `None` when it is infeasible.
pub fn hard_qp(u_r: Vec2, rows: &[(Vec2, f64)], delta: f64) -> Option<Hard> {
    let mut cands = vec![u_r];
    if u_r.norm() > 0.0 {
        cands.push(u_r * (delta / u_r.norm()));
    }
    for (i, (a, c)) in rows.iter().enumerate() {
        cands.push(u_r - a * (a.dot(&u_r) - c));
        if c.abs() <= delta {
            let t = Vec2::new(-a.y, a.x) * (delta * delta - c * c).sqrt();
            cands.extend([a * *c + t, a * *c - t]);
        }
        for (b, d) in &rows[i + 1..] {
            let det = a.x * b.y - a.y * b.x;
            if det.abs() > 1e-12 {
                cands.push(Vec2::new((c * b.y - d * a.y) / det, (a.x * d - b.x * c) / det));
            }
        }
    }
    let u = cands
        .into_iter()
        .filter(|x| feasible(x, rows, delta))
        .min_by(|x, y| (x - u_r).norm().total_cmp(&(y - u_r).norm()))?;
    Some(Hard { u, multipliers: multipliers(u_r, u, rows, delta) })
}

/// KKT multipliers at `u`: u_r − u = Σ λᵢ aᵢ + μ û with λ, μ ≥ 0 over the active constraints.
fn multipliers(u_r: Vec2, u: Vec2, rows: &[(Vec2, f64)], delta: f64) -> Option<Vec<f64>> {
    let mut active: Vec<(Option<usize>, Vec2)> = rows
        .iter()
        .enumerate()
        .filter(|(_, (a, c))| a.dot(&u) >= c - ACTIVE_TOL)
        .map(|(i, (a, _))| (Some(i), *a))
        .collect();
    if u.norm() >= delta - ACTIVE_TOL {
        active.push((None, u / u.norm()));
    }
    let g = u_r - u;
    let scale = g.norm().max(1.0);
    let lambdas: Vec<f64> = match active.as_slice() {
        [] => vec![],
        [(_, n)] => vec![g.dot(n)],
        [(_, n1), (_, n2)] => {
            let det = n1.x * n2.y - n1.y * n2.x;
            if det.abs() < 1e-6 {
                return None;
            }
            vec![(g.x * n2.y - g.y * n2.x) / det, (n1.x * g.y - n1.y * g.x) / det]
        }
        _ => return None,
    };
    let fit: Vec2 = active.iter().zip(&lambdas).map(|((_, n), l)| n * *l).sum();
    if (fit - g).norm() > 1e-6 * scale || lambdas.iter().any(|l| *l < -1e-9 * scale) {
        return None;
    }
    let mut out = vec![0.0; rows.len()];
    for ((i, _), l) in active.iter().zip(&lambdas) {
        if let Some(i) = i {
            out[*i] = l.max(0.0);
        }
    }
    Some(out)
}
