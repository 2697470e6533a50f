//! The multipliers of three or more lines through one point (docs/safety.md §11.2): Σ_g Λ_g n_g = y
//! with Λ_g ∈ [lo_g, hi_g] asks whether y lies in the zonotope Σ_g [lo_g, hi_g] n_g, a convex polygon
//! whose vertices have every Λ_g at a bound. Its vertices are listed in angular order, the polygon is
//! fanned into triangles from one vertex, and the triangle holding y gives Λ as the same convex
//! combination of its three vertices' Λ (which stays in the box).

use super::Group;
use uav::Vec2;

/// Sets the groups' `value` to a solution and returns true if y is in the zonotope (barycentric
/// within `tol` in Σ Λ_g n_g, then clamped); otherwise returns false and leaves each value at lo.
pub(super) fn decompose(
    groups: &mut [Group],
    order: &mut Vec<(f64, usize, bool)>,
    y: Vec2,
    tol: f64,
) -> bool {
    let mut base = Vec2::zeros();
    order.clear();
    for (i, g) in groups.iter_mut().enumerate() {
        base += g.n * g.lo;
        g.value = g.lo;
        let v = g.n * (g.hi - g.lo);
        if g.hi - g.lo <= 0.0 {
            continue;
        }
        // Orient every generator into the upper half-plane (angle in [0, π)): β → 1 − β.
        let angle = v.y.atan2(v.x);
        let flip = !(0.0..std::f64::consts::PI).contains(&angle);
        if flip {
            base += v;
        }
        order.push((if flip { angle + std::f64::consts::PI } else { angle }, i, flip));
    }
    order.sort_unstable_by(|a, b| a.0.total_cmp(&b.0));
    let generator = |j: usize| {
        let (_, i, flip) = order[j];
        let g = &groups[i];
        let v = g.n * (g.hi - g.lo);
        if flip { -v } else { v }
    };
    let k = order.len();
    let p = y - base;
    // (i, j, s, t): y = base + Σ_{i<l<j} g_l + s g_i + t g_j.
    let found = match k {
        0 => (p.norm() <= tol).then_some((0, 0, 0.0, 0.0)),
        1 => {
            let v = generator(0);
            let s = p.dot(&v) / v.norm_squared();
            let slack = tol / v.norm();
            (uav::cross(&v, &p).abs() / v.norm() <= tol && s >= -slack && s <= 1.0 + slack)
                .then_some((0, 0, s, 0.0))
        }
        _ => tile(k, &generator, p, tol),
    };
    let Some((i0, j0, s, t)) = found else { return false };
    for (l, &(_, gi, flip)) in order.iter().enumerate() {
        let beta = if l == i0 {
            s
        } else if l == j0 {
            t
        } else if l > i0 && l < j0 {
            1.0
        } else {
            0.0
        };
        let beta = beta.clamp(0.0, 1.0);
        let g = &mut groups[gi];
        g.value = (g.lo + (if flip { 1.0 - beta } else { beta }) * (g.hi - g.lo)).clamp(g.lo, g.hi);
    }
    true
}

/// The tile of the zonotope Σ_l [0, 1] g_l (generators in angular order in [0, π)) that holds p: the
/// zonotope is tiled by the parallelograms Σ_{i<l<j} g_l + [0, 1]g_i + [0, 1]g_j, i < j, each
/// well conditioned unless g_i and g_j are nearly parallel. Returns (i, j, s, t) with s, t clamped,
/// from the tile that p is least outside of (by how far clamping moves the point), if that is at most
/// `tol`: a point on the boundary of a thin tile can fall just outside every tile in round-off.
fn tile(k: usize, generator: &dyn Fn(usize) -> Vec2, p: Vec2, tol: f64) -> Option<(usize, usize, f64, f64)> {
    let mut best: Option<(usize, usize, f64, f64, f64)> = None;
    for i in 0..k {
        let gi = generator(i);
        let mut offset = Vec2::zeros();
        for j in i + 1..k {
            let gj = generator(j);
            let det = uav::cross(&gi, &gj);
            if det != 0.0 {
                let q = p - offset;
                let (s, t) = (uav::cross(&q, &gj) / det, uav::cross(&gi, &q) / det);
                // A coefficient off [0, 1] by x moves the point by x‖g‖.
                let off = |x: f64, g: Vec2| (x - x.clamp(0.0, 1.0)).abs() * g.norm();
                let outside = off(s, gi) + off(t, gj);
                if outside == 0.0 {
                    return Some((i, j, s, t));
                }
                if best.is_none_or(|b| outside < b.4) {
                    best = Some((i, j, s.clamp(0.0, 1.0), t.clamp(0.0, 1.0), outside));
                }
            }
            offset += gj;
        }
    }
    best.filter(|b| b.4 <= tol).map(|(i, j, s, t, _)| (i, j, s, t))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A point built from Λ inside the box is found again, and the Λ found reproduces it.
    #[test]
    fn decomposes_inner_points() {
        let mut seed = 12345u64;
        let mut next = || {
            seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (seed >> 11) as f64 / (1u64 << 53) as f64
        };
        let mut order = Vec::new();
        for case in 0..2000 {
            let k = 3 + case % 6;
            let mut groups: Vec<Group> = (0..k)
                .map(|g| {
                    let angle = next() * std::f64::consts::TAU;
                    let (lo, hi) =
                        if next() < 0.5 { (0.0, 10.0 * next()) } else { (-5.0 * next(), 5.0 * next()) };
                    Group { n: Vec2::new(angle.cos(), angle.sin()), lo, hi, rep: g, value: 0.0, left: 0.0 }
                })
                .collect();
            let y = groups.iter().fold(Vec2::zeros(), |acc, g| acc + g.n * (g.lo + next() * (g.hi - g.lo)));
            assert!(decompose(&mut groups, &mut order, y, 1e-12), "case {case}: not found");
            let back = groups.iter().fold(Vec2::zeros(), |acc, g| acc + g.n * g.value);
            assert!((back - y).norm() <= 1e-9, "case {case}: {back:?} vs {y:?}");
            assert!(groups.iter().all(|g| g.value >= g.lo && g.value <= g.hi));
        }
    }
}
#[cfg(test)]
mod thin {
    use super::*;

    /// A tiny generator between large ones (a fan of triangles from one vertex was ill-conditioned
    /// here: 2e-5 off).
    #[test]
    fn tiny_generator_among_large_ones() {
        let data = [
            (-0.9812942087657595, -0.19251409258228883, 1736707.5601262061),
            (0.7597063691297036, -0.6502662783074042, 63994.86030578259),
            (-0.9811977173094042, 0.19300528372771206, 199693.103857104),
            (-0.9448836684136745, 0.3274062509560825, 4.4221380200962725),
            (-0.9543997352055286, 0.29853164897480644, 1910849.4602083506),
            (-0.028318359778789097, -0.9995989548311058, 1762195.1083887038),
        ];
        let mut groups: Vec<Group> = data
            .iter()
            .enumerate()
            .map(|(i, &(x, y, hi))| Group { n: Vec2::new(x, y), lo: 0.0, hi, rep: i, value: 0.0, left: 0.0 })
            .collect();
        let y = Vec2::new(-3.9154459497312457, -0.6259763138890642);
        let mut order = Vec::new();
        let ok = decompose(&mut groups, &mut order, y, 1e-8);
        let back = groups.iter().fold(Vec2::zeros(), |acc, g| acc + g.n * g.value);
        assert!(ok && (back - y).norm() <= 1e-9, "{back:?} vs {y:?}");
    }
}
