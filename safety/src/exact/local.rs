//! The local step at a point where rows pass through the iterate (docs/safety.md §11.2): group the
//! rows through u into lines, test 0 ∈ ∂F_κ(u) by a small linear feasibility problem on the lines'
//! summed multipliers (the certificate), and otherwise minimise the local model exactly over the
//! rays and sectors the lines cut the plane into, and step towards its minimiser.

use super::inner::PAR_TOL;
use super::{ExactSolver, Group, Working, add_outer, perp, solve_sym};
use crate::qp::ConstraintRow;
use uav::Vec2;

/// Relative tolerance of the multiplier feasibility test (a few roundings of the gradient's terms).
const LP_TOL: f64 = 1e-13;

/// What the local step did.
pub(super) enum Local {
    /// 0 ∈ ∂F_κ(u): u is the minimiser; multipliers set.
    Optimal,
    /// u moved along a strict descent direction.
    Moved,
}

impl ExactSolver {
    /// Certifies `u` or moves it (see the module doc); the working set becomes the line of the ray
    /// followed (if any) plus the row that stopped the step.
    pub(super) fn local_step(
        &mut self,
        rows: &[ConstraintRow],
        u_r: Vec2,
        kappa: f64,
        u: &mut Vec2,
        w: &mut Working,
    ) -> Local {
        // Smooth part at u: the rows beyond their kink that do not pass through u.
        let mut h0 = [kappa, 0.0, kappa];
        let mut g0 = *u * kappa - u_r;
        let norm_u = u.norm();
        let mut scale = 1.0 + u_r.norm() + kappa * norm_u;
        for (c, r) in rows.iter().enumerate() {
            let t = self.t[c];
            if !self.zmark[c] && t > 0.0 {
                let lam = r.rho + r.weight * t;
                g0 += r.a * lam;
                add_outer(&mut h0, r.a, r.weight);
                // t_c carries the rounding of |c_c| + ‖a_c‖‖u‖, multiplied by P_c.
                scale += (r.rho + r.weight * (r.c.abs() + self.norm[c] * norm_u)) * self.norm[c];
            }
        }
        self.group(rows);
        let certified = self.lp(g0, scale);
        self.distribute(rows);
        if certified {
            self.polish(rows, u);
            return Local::Optimal;
        }
        let (d, ray, value) = self.best_candidate(rows, g0, h0);
        if value.partial_cmp(&(-8.0 * f64::EPSILON * scale * d.norm())) != Some(std::cmp::Ordering::Less)
            || d.norm() <= 16.0 * f64::EPSILON * (1.0 + norm_u + scale / kappa)
        {
            // No numerically measurable descent: the certificate in `finish` judges this point.
            self.polish(rows, u);
            return Local::Optimal;
        }
        let (alpha, block) = self.ratio_test(rows, d);
        *u += d * alpha;
        *w = Working::default();
        if let Some(gi) = ray {
            w.push(self.groups[gi].rep);
        }
        if let Some(c) = block {
            w.push(c);
        }
        Local::Moved
    }

    /// Puts u exactly on the lines whose summed multiplier is strictly inside its range (the lines u
    /// must lie on), removing the drift of |t_c| ≤ τ_c that a multiplier of 10⁶ would turn into an
    /// objective error: onto the one such line, or onto the vertex of the first two.
    fn polish(&self, rows: &[ConstraintRow], u: &mut Vec2) {
        let mut interior = self.groups.iter().filter(|g| {
            let tol = 1e-9 * (g.hi - g.lo);
            g.value > g.lo + tol && g.value < g.hi - tol
        });
        let (Some(first), second) = (interior.next(), interior.next()) else { return };
        let a = &rows[first.rep];
        let target = match second {
            None => *u - a.a * ((a.a.dot(u) - a.c) / a.a.norm_squared()),
            Some(g) => {
                let b = &rows[g.rep];
                let det = uav::cross(&a.a, &b.a);
                Vec2::new(a.c * b.a.y - b.c * a.a.y, a.a.x * b.c - b.a.x * a.c) / det
            }
        };
        // Only a small correction (a far vertex means nearly parallel lines), and none that moves a
        // row not through u across its kink (its multiplier, ρ_c + P_c t_c or 0, would change).
        let small = (target - *u).norm() <= 1e-9 * (1.0 + u.norm());
        let keeps_sides = rows
            .iter()
            .enumerate()
            .all(|(c, r)| self.zmark[c] || ((r.a.dot(&target) - r.c > 0.0) == (self.t[c] > 0.0)));
        if small && keeps_sides {
            *u = target;
        }
    }

    /// Groups the marked rows into distinct lines through u.
    fn group(&mut self, rows: &[ConstraintRow]) {
        self.groups.clear();
        for (c, r) in rows.iter().enumerate() {
            if !self.zmark[c] {
                continue;
            }
            let n = self.norm[c];
            let unit = r.a / n;
            let found = self.groups.iter().position(|g| uav::cross(&g.n, &unit).abs() <= PAR_TOL);
            let gi = found.unwrap_or_else(|| {
                self.groups.push(Group { n: unit, lo: 0.0, hi: 0.0, rep: c, value: 0.0, left: 0.0 });
                self.groups.len() - 1
            });
            self.gid[c] = gi;
            let g = &mut self.groups[gi];
            if g.n.dot(&unit) > 0.0 {
                g.hi += r.rho * n;
            } else {
                g.lo -= r.rho * n;
            }
        }
    }

    /// Finds Λ_g ∈ [lo_g, hi_g] with Σ Λ_g n_g = −g0 (to `LP_TOL`·scale); true if found. The values
    /// left in the groups are clamped to their ranges either way.
    fn lp(&mut self, g0: Vec2, scale: f64) -> bool {
        let tol = LP_TOL * scale;
        let within = |g: &Group, v: f64| v >= g.lo - tol && v <= g.hi + tol;
        let y = -g0;
        let ok = match self.groups.len() {
            0 => g0.norm() <= tol,
            1 => {
                let g = &mut self.groups[0];
                let v = y.dot(&g.n);
                let ok = uav::cross(&g.n, &y).abs() <= tol && within(g, v);
                g.value = v;
                ok
            }
            2 => {
                let (n1, n2) = (self.groups[0].n, self.groups[1].n);
                let det = uav::cross(&n1, &n2);
                let (v1, v2) = (uav::cross(&y, &n2) / det, uav::cross(&n1, &y) / det);
                self.groups[0].value = v1;
                self.groups[1].value = v2;
                within(&self.groups[0], v1) && within(&self.groups[1], v2)
            }
            // Most often two lines carry y and the others have Λ = 0 (which every range holds):
            // exact, and without the zonotope's cancellation of large bounds.
            _ => {
                self.lp_pairs(y, tol) || super::zonotope::decompose(&mut self.groups, &mut self.order, y, tol)
            }
        };
        for g in &mut self.groups {
            g.value = if g.value.is_finite() { g.value.clamp(g.lo, g.hi) } else { 0.0 };
        }
        ok
    }

    /// Σ Λ_g n_g = y with at most two lines nonzero; true (values set) if some pair fits its ranges.
    fn lp_pairs(&mut self, y: Vec2, tol: f64) -> bool {
        let k = self.groups.len();
        let within = |g: &Group, v: f64| v >= g.lo - tol && v <= g.hi + tol;
        for i in 0..k {
            for j in i + 1..k {
                let (gi, gj) = (&self.groups[i], &self.groups[j]);
                let det = uav::cross(&gi.n, &gj.n);
                let (vi, vj) = (uav::cross(&y, &gj.n) / det, uav::cross(&gi.n, &y) / det);
                if within(gi, vi) && within(gj, vj) {
                    for (l, g) in self.groups.iter_mut().enumerate() {
                        g.value = if l == i {
                            vi
                        } else if l == j {
                            vj
                        } else {
                            0.0
                        };
                    }
                    return true;
                }
            }
        }
        false
    }

    /// Splits each line's Λ among its rows: rows whose normal points along Λ's sign take up to ρ_c
    /// each, in index order; the others get 0.
    fn distribute(&mut self, rows: &[ConstraintRow]) {
        for g in &mut self.groups {
            g.left = g.value;
        }
        for (c, r) in rows.iter().enumerate() {
            if !self.zmark[c] {
                continue;
            }
            let gi = self.gid[c];
            let n = self.norm[c];
            let along = self.groups[gi].n.dot(&r.a) > 0.0;
            let l = &mut self.groups[gi].left;
            let want = if along { l.max(0.0) } else { (-*l).max(0.0) } / n;
            let lam = want.min(r.rho);
            self.lambda[c] = lam;
            *l -= if along { lam * n } else { -lam * n };
        }
    }

    /// The exact minimiser of the local model m(d) = g0ᵀd + ½dᵀH0d + Σ_marked φ_c(a_cᵀd): the best of
    /// the 1-D minimisers on the rays along each line and the quadratic minimisers of each sector
    /// between them (one is the true minimiser; every candidate is scored by m itself). Returns d, the
    /// line of the ray (None for a sector) and m(d).
    fn best_candidate(
        &mut self,
        rows: &[ConstraintRow],
        g0: Vec2,
        h0: [f64; 3],
    ) -> (Vec2, Option<usize>, f64) {
        let mut best = (Vec2::zeros(), None, 0.0);
        let mut angles = std::mem::take(&mut self.angles);
        angles.clear();
        for (gi, grp) in self.groups.iter().enumerate() {
            for sign in [1.0, -1.0] {
                let e = perp(grp.n) * sign;
                angles.push(e.y.atan2(e.x));
                let (mut slope, mut curv) = (g0.dot(&e), quad(h0, e));
                for (c, r) in rows.iter().enumerate() {
                    if self.zmark[c] && self.gid[c] != gi {
                        let s = r.a.dot(&e);
                        if s > 0.0 {
                            slope += r.rho * s;
                            curv += r.weight * s * s;
                        }
                    }
                }
                if slope < 0.0 && curv > 0.0 {
                    let d = e * (-slope / curv);
                    let v = self.model(rows, g0, h0, d);
                    if v < best.2 {
                        best = (d, Some(gi), v);
                    }
                }
            }
        }
        angles.sort_unstable_by(f64::total_cmp);
        for i in 0..angles.len().max(1) {
            let mid = match angles.len() {
                0 => 0.0,
                len if i + 1 < len => 0.5 * (angles[i] + angles[i + 1]),
                len => 0.5 * (angles[len - 1] + angles[0] + std::f64::consts::TAU),
            };
            let b = Vec2::new(mid.cos(), mid.sin());
            let (mut h, mut g) = (h0, g0);
            for (c, r) in rows.iter().enumerate() {
                if self.zmark[c] && r.a.dot(&b) > 0.0 {
                    g += r.a * r.rho;
                    add_outer(&mut h, r.a, r.weight);
                }
            }
            if let Some(d) = solve_sym(h, -g) {
                let v = self.model(rows, g0, h0, d);
                if v < best.2 {
                    best = (d, None, v);
                }
            }
        }
        self.angles = angles;
        best
    }

    /// The local model m(d) at the iterate (marked rows exactly at their kink).
    fn model(&self, rows: &[ConstraintRow], g0: Vec2, h0: [f64; 3], d: Vec2) -> f64 {
        let mut v = g0.dot(&d) + 0.5 * quad(h0, d);
        for (c, r) in rows.iter().enumerate() {
            if self.zmark[c] {
                let s = r.a.dot(&d);
                if s > 0.0 {
                    v += r.rho * s + 0.5 * r.weight * s * s;
                }
            }
        }
        v
    }
}

/// dᵀHd for the packed symmetric 2×2 matrix h.
fn quad(h: [f64; 3], d: Vec2) -> f64 {
    h[0] * d.x * d.x + 2.0 * h[1] * d.x * d.y + h[2] * d.y * d.y
}
