//! The active-set loop for fixed μ (docs/safety.md §11.2): minimise
//! `F_κ(u) = ½κ‖u‖² − u_rᵀu + Σ_c φ_c(a_cᵀu − c_c)` (κ = 1 + μ) over R², and the exact root of
//! ‖u(μ)‖ = δ on one pattern of rows (§11.3).

use super::{A_MIN, ExactSolver, TAU_REL, Working, add_outer, perp, solve_sym};
use crate::qp::ConstraintRow;
use uav::Vec2;

/// Rows whose unit normals differ by at most this (|sin| of the angle) lie on one line when both pass
/// through the iterate.
pub(super) const PAR_TOL: f64 = 1e-12;

impl ExactSolver {
    /// Minimises F_κ starting from `u` with working set `w`; true when the local certificate held (the
    /// multipliers of the rows through `u` are then in `lambda`, `zmark` and `groups`).
    pub(super) fn inner(
        &mut self,
        rows: &[ConstraintRow],
        u_r: Vec2,
        kappa: f64,
        u: &mut Vec2,
        w: &mut Working,
    ) -> bool {
        let max_iter = 16 + 8 * rows.len();
        for _ in 0..max_iter {
            self.iterations += 1;
            let simple = self.classify(rows, *u, w);
            if simple && w.len < 2 && self.subspace_step(rows, u_r, kappa, u, w) {
                continue;
            }
            if let super::local::Local::Optimal = self.local_step(rows, u_r, kappa, u, w) {
                return true;
            }
        }
        false
    }

    /// A starting point for μ = 0, in the manner of a dual method: u_r projected on the most violated
    /// row, then the vertex with the row most violated there (if not parallel). Any start is correct
    /// (the problem is unconstrained in u); this one usually leaves only the certificate to do.
    /// Rows whose line lies farther than `reach` from the origin (tiny ‖a_c‖) are not used.
    pub(super) fn start(&self, rows: &[ConstraintRow], u_r: Vec2, reach: f64) -> (Vec2, Working) {
        let (mut u, mut w) = (u_r, Working::default());
        for _ in 0..2 {
            let mut most: Option<(usize, f64)> = None;
            for (c, r) in rows.iter().enumerate() {
                let n = self.norm[c];
                if n > A_MIN && !w.contains(c) && r.c.abs() <= reach * n {
                    let dist = (r.a.dot(&u) - r.c) / n;
                    if dist > most.map_or(0.0, |m| m.1) {
                        most = Some((c, dist));
                    }
                }
            }
            let Some((c, _)) = most else { break };
            let r = &rows[c];
            if w.len == 0 {
                u -= r.a * ((r.a.dot(&u) - r.c) / (self.norm[c] * self.norm[c]));
            } else {
                let k = &rows[w.rows[0]];
                let det = uav::cross(&k.a, &r.a);
                if det.abs() <= PAR_TOL * self.norm[c] * self.norm[w.rows[0]] {
                    break;
                }
                let vertex = Vec2::new(k.c * r.a.y - r.c * k.a.y, k.a.x * r.c - r.a.x * k.c) / det;
                if vertex.norm().partial_cmp(&reach) != Some(std::cmp::Ordering::Less) {
                    break;
                }
                u = vertex;
            }
            w.push(c);
        }
        (u, w)
    }

    /// Computes t_c at `u` and marks the rows through `u` (|t_c| ≤ τ_c, geometric rows only) and the
    /// working set; true when every marked row lies on the line of a working row (no degeneracy
    /// beyond the working set).
    fn classify(&mut self, rows: &[ConstraintRow], u: Vec2, w: &Working) -> bool {
        // The floor δ + ‖u_r‖ keeps rows through a point near the origin from looking apart.
        let norm_u = u.norm() + self.size;
        let mut simple = true;
        for (c, r) in rows.iter().enumerate() {
            let t = r.a.dot(&u) - r.c;
            self.t[c] = t;
            let n = self.norm[c];
            let mark = n > A_MIN && (w.contains(c) || t.abs() <= TAU_REL * (r.c.abs() + n * norm_u));
            self.zmark[c] = mark;
            if mark && !w.contains(c) {
                let on_working_line = w.as_slice().iter().any(|&k| {
                    let cross = uav::cross(&r.a, &rows[k].a);
                    cross.abs() <= PAR_TOL * n * self.norm[k]
                });
                simple &= on_working_line;
            }
        }
        simple
    }

    /// One step towards the minimiser of the current quadratic piece on the working set's subspace
    /// (the plane, or the line of the one working row), stopped where an unmarked row reaches its
    /// kink (it joins the working set). False when `u` is already that minimiser.
    fn subspace_step(
        &mut self,
        rows: &[ConstraintRow],
        u_r: Vec2,
        kappa: f64,
        u: &mut Vec2,
        w: &mut Working,
    ) -> bool {
        let mut h = [kappa, 0.0, kappa];
        let mut g = u_r;
        let norm_u = u.norm();
        // Size of the gradient's terms: the step carries their rounding divided by the curvature ≥ κ.
        let mut scale = 1.0 + u_r.norm() + kappa * norm_u;
        for (c, r) in rows.iter().enumerate() {
            if !self.zmark[c] && self.t[c] > 0.0 {
                add_outer(&mut h, r.a, r.weight);
                g -= r.a * (r.rho - r.weight * r.c);
                scale += (r.rho + r.weight * (r.c.abs() + self.norm[c] * norm_u)) * self.norm[c];
            }
        }
        let target = if w.len == 0 {
            match solve_sym(h, g) {
                Some(x) => x,
                None => return false,
            }
        } else {
            let k = w.rows[0];
            let e = perp(rows[k].a) / self.norm[k];
            let grad = Vec2::new(h[0] * u.x + h[1] * u.y, h[1] * u.x + h[2] * u.y) - g;
            let curv = h[0] * e.x * e.x + 2.0 * h[1] * e.x * e.y + h[2] * e.y * e.y;
            *u - e * (e.dot(&grad) / curv)
        };
        let d = target - *u;
        // (NaN counts as negligible.)
        if d.norm().partial_cmp(&(16.0 * f64::EPSILON * (1.0 + norm_u + scale / kappa)))
            != Some(std::cmp::Ordering::Greater)
        {
            return false;
        }
        let (alpha, block) = self.ratio_test(rows, d);
        *u += d * alpha;
        if let Some(c) = block {
            w.push(c);
        }
        true
    }

    /// The largest step α ≤ 1 along d before an unmarked row changes sign, and that row.
    pub(super) fn ratio_test(&self, rows: &[ConstraintRow], d: Vec2) -> (f64, Option<usize>) {
        let (mut alpha, mut block) = (1.0, None);
        for (c, r) in rows.iter().enumerate() {
            if self.zmark[c] {
                continue;
            }
            let rate = r.a.dot(&d);
            let t = self.t[c];
            let hit = if t > 0.0 && rate < 0.0 {
                t / -rate
            } else if t <= 0.0 && rate > 0.0 {
                -t / rate
            } else {
                continue;
            };
            if hit < alpha {
                (alpha, block) = (hit, Some(c));
            }
        }
        (alpha, block)
    }

    /// The μ ≥ `lo` at which the pattern of rows of the last inner answer (rows beyond their kink, the
    /// line its multipliers hold u on) puts u(μ) on the circle ‖u‖ = δ, if that pattern has one.
    pub(super) fn pattern_root(&self, rows: &[ConstraintRow], u_r: Vec2, delta: f64, lo: f64) -> Option<f64> {
        let mut h = [1.0, 0.0, 1.0];
        let mut g = u_r;
        let mut line = None;
        for (gi, grp) in self.groups.iter().enumerate() {
            let tol = 1e-12 * (grp.hi - grp.lo).max(1.0);
            if grp.value > grp.lo + tol && grp.value < grp.hi - tol {
                if line.is_some() {
                    return None;
                }
                line = Some(gi);
            }
        }
        for (c, r) in rows.iter().enumerate() {
            let on = if self.zmark[c] {
                line != Some(self.gid[c]) && r.rho > 0.0 && self.lambda[c] >= r.rho
            } else {
                self.t[c] > 0.0
            };
            if on {
                add_outer(&mut h, r.a, r.weight);
                g -= r.a * (r.rho - r.weight * r.c);
            }
        }
        match line {
            None => secular_root(h, g, delta, lo),
            Some(gi) => {
                let k = self.groups[gi].rep;
                let a = rows[k].a;
                let p0 = a * (rows[k].c / a.norm_squared());
                let e = perp(a) / a.norm();
                let hp0 = Vec2::new(h[0] * p0.x + h[1] * p0.y, h[1] * p0.x + h[2] * p0.y);
                let g_t = e.dot(&(g - hp0));
                let h_tt = h[0] * e.x * e.x + 2.0 * h[1] * e.x * e.y + h[2] * e.y * e.y;
                let r2 = delta * delta - p0.norm_squared();
                if r2 <= 0.0 || g_t == 0.0 {
                    return None;
                }
                let s = r2.sqrt().copysign(g_t);
                Some(g_t / s - h_tt)
            }
        }
    }
}

/// The root μ ≥ `lo` of ‖(H + μI)⁻¹g‖ = δ (H symmetric positive definite, packed), by Newton's method
/// on 1/‖·‖ − 1/δ from `lo`, which increases monotonically to the root; None if ‖·‖ ≤ δ at `lo`.
fn secular_root(h: [f64; 3], g: Vec2, delta: f64, lo: f64) -> Option<f64> {
    let mean = 0.5 * (h[0] + h[2]);
    let diff = 0.5 * (h[0] - h[2]);
    let rad = diff.hypot(h[1]);
    let v = if rad == 0.0 {
        Vec2::new(1.0, 0.0)
    } else if diff >= 0.0 {
        Vec2::new(diff + rad, h[1])
    } else {
        Vec2::new(h[1], rad - diff)
    };
    let e1 = v / v.norm();
    let (l1, l2) = (mean + rad, mean - rad);
    let (g1, g2) = (e1.dot(&g), perp(e1).dot(&g));
    let norm = |mu: f64| (g1 / (l1 + mu)).hypot(g2 / (l2 + mu));
    if norm(lo).partial_cmp(&delta) != Some(std::cmp::Ordering::Greater) {
        return None;
    }
    let mut mu = lo;
    for _ in 0..60 {
        let psi = norm(mu);
        let q = g1 * g1 / (l1 + mu).powi(3) + g2 * g2 / (l2 + mu).powi(3);
        let step = -(1.0 / psi - 1.0 / delta) * psi.powi(3) / q;
        if !step.is_finite() {
            return None;
        }
        mu += step;
        if step.abs() <= 4.0 * f64::EPSILON * (1.0 + mu) {
            break;
        }
    }
    Some(mu)
}
