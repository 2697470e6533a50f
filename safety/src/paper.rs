//! The paper's unnormalised quantities (eq. 2–4, 6–8, 11, 12) with the corrections of
//! docs/safety.md §0 (E1 sign of the braking integral, E2 Δ² carries the minus sign, E3 outer
//! product). Used as an oracle against `safety/tests/data/cbf_test_vectors.json` and by the `paper`
//! road rule's unsigned barrier.

use uav::Vec2;

/// Collision terms of UAV k against d at paper scale (rows multiplied by ‖p_kd‖).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CollisionTerms {
    /// ‖p_kd‖.
    pub norm_p_kd: f64,
    /// v̄_kd = p̂_kdᵀv_kd (negative when approaching).
    pub vbar_kd: f64,
    /// √(2(δ_k+δ_d)(‖p_kd‖ − D_c)).
    pub sqrt_term: f64,
    /// b_kd (eq. 4).
    pub b_kd: f64,
    /// S_kd = ‖p_kd‖ − min(v̄,0)²/(2δΣ), the left side of eq. (2) with E1 applied.
    pub s_kd: f64,
    /// Δ¹ = δΣ v_kdᵀp_kd/√(…) + ‖v_kd‖².
    pub delta1: f64,
    /// Δ² = −(v_kdᵀp_kd)²/‖p_kd‖² + ζ b³‖p_kd‖ (E2).
    pub delta2: f64,
}

impl CollisionTerms {
    /// Evaluates the terms for relative position `p_kd`, velocity `v_kd`.
    pub fn new(p_kd: Vec2, v_kd: Vec2, delta_k: f64, delta_d: f64, d_c: f64, zeta: f64) -> Self {
        let delta_sum = delta_k + delta_d;
        let n = p_kd.norm();
        let vp = v_kd.dot(&p_kd);
        let vbar = vp / n;
        let h = (2.0 * delta_sum * (n - d_c).max(0.0)).sqrt();
        let b = h + vbar;
        let delta1 = delta_sum * vp / h + v_kd.norm_squared();
        let delta2 = -vp * vp / (n * n) + zeta * b.powi(3) * n;
        let s_kd = crate::barrier::braking_margin(n, vbar, delta_sum);
        Self { norm_p_kd: n, vbar_kd: vbar, sqrt_term: h, b_kd: b, s_kd, delta1, delta2 }
    }

    /// Right-hand side Δ¹ + Δ² of eq. (11)/(13): `−p_kdᵀu_kd ≤ Δ¹ + Δ²`.
    pub fn rhs(&self) -> f64 {
        self.delta1 + self.delta2
    }
}

/// Road terms of UAV k for barrier line j of segment i at paper scale (rows multiplied by ‖O_kij‖).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RoadTerms {
    /// O_kij = O_ij(p_k − p̃_{i(j)₂}), the perpendicular from the line to the UAV.
    pub o_kij: Vec2,
    /// ‖O_kij‖, the (unsigned) distance to the infinite line.
    pub norm_o_kij: f64,
    /// v̄_kij = Ô_kijᵀv.
    pub vbar_kij: f64,
    /// √(2δ_k(‖O_kij‖ − D_s)).
    pub sqrt_term: f64,
    /// b_kij (eq. 8).
    pub b_kij: f64,
    /// S_kij = ‖O_kij‖ − min(v̄,0)²/(2δ), the left side of eq. (6) with E1 applied.
    pub s_kij: f64,
    /// Δ¹ = δ O_kijᵀv/√(…) + vᵀO_ijᵀO_ij v.
    pub delta1: f64,
    /// Δ² = −(O_kijᵀO_ij v)²/‖O_kij‖² + ζ b³‖O_kij‖ (E2, E3).
    pub delta2: f64,
}

impl RoadTerms {
    /// Evaluates the terms for a UAV at `p`, `v` and the line through `line_point` along `line_vector`.
    pub fn new(
        p: Vec2,
        v: Vec2,
        line_point: Vec2,
        line_vector: Vec2,
        delta: f64,
        d_s: f64,
        zeta: f64,
    ) -> Self {
        let e = line_vector / line_vector.norm();
        let project = |x: Vec2| x - e * e.dot(&x); // O_ij x with O_ij = I − êêᵀ
        let w = project(p - line_point);
        let ov = project(v);
        let m = w.norm();
        let wv = w.dot(&v);
        let vbar = wv / m;
        let g = (2.0 * delta * (m - d_s).max(0.0)).sqrt();
        let b = g + vbar;
        let delta1 = delta * wv / g + ov.norm_squared();
        let w_ov = w.dot(&ov);
        let delta2 = -w_ov * w_ov / (m * m) + zeta * b.powi(3) * m;
        let s_kij = crate::barrier::braking_margin(m, vbar, delta);
        Self { o_kij: w, norm_o_kij: m, vbar_kij: vbar, sqrt_term: g, b_kij: b, s_kij, delta1, delta2 }
    }

    /// Right-hand side Δ¹ + Δ² of eq. (12): `−O_kijᵀu_k ≤ Δ¹ + Δ²`.
    pub fn rhs(&self) -> f64 {
        self.delta1 + self.delta2
    }
}
