//! Barrier functions and their affine CBF rows in normalised form `aᵀu_k ≤ c`, ‖a‖ = 1, with the
//! numerically safe evaluation of docs/safety.md §4 (clamp `max(h, h_min)`, never √ of a negative
//! number).

use uav::Vec2;

/// h_min (m/s): lower clamp of h = √(2δΣ(n − D_c)) and g = √(2δ(s − D_s)) in the rows
/// (docs/safety.md §4.1).
pub const H_MIN: f64 = 1e-3;
/// Distances below this (m) are treated as this, to keep p̂ defined after a collision
/// (docs/safety.md §4.3).
pub const MIN_DISTANCE_M: f64 = 1e-12;

/// What a row protects against.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RowKind {
    /// A road wall (line or end-point barrier); the index is the wall's index in the road.
    Road(usize),
    /// A neighbouring UAV; the index is the neighbour's index in the fleet.
    Collision(usize),
}

/// One CBF condition `ḃ ≥ −ζb³` as an affine row `aᵀu_k ≤ c` with ‖a‖ = 1, and the barrier value b.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Row {
    /// Row direction a (unit vector).
    pub a: Vec2,
    /// Right-hand side c (m/s²).
    pub c: f64,
    /// The barrier value b (m/s) at the current state.
    pub b: f64,
    /// What the row protects against.
    pub kind: RowKind,
}

/// `δ ẋ / max(h, h_min)` written so it is exact when h ≥ h_min and only tightens otherwise:
/// with b = h + ẋ, `δẋ/h = −δ + δb/h`, and the clamp applies to the second form, capped at 0 so
/// that inside the clearance a UAV moving away may not accelerate back in (docs/safety.md §4.1).
fn braking_term(delta: f64, rate: f64, h: f64, b: f64) -> f64 {
    if h >= H_MIN { delta * rate / h } else { (-delta + delta * b / H_MIN).min(0.0) }
}

/// Collision row of UAV k against neighbour d (docs/safety.md §1, §2; paper eq. 4, 11, 14):
/// b_kd = √(2δΣ(‖p_kd‖ − D_c)) + p̂_kdᵀv_kd, row
/// `−p̂ᵀu_k ≤ δ_k/δΣ · (δΣ ṅ/h + ‖v_⊥‖²/n + ζ b_kd³)`, with δΣ = δ_k + δ_d.
pub fn collision_row(
    p_kd: Vec2,
    v_kd: Vec2,
    delta_k: f64,
    delta_d: f64,
    d_c: f64,
    zeta: f64,
    kind: RowKind,
) -> Row {
    let n_raw = p_kd.norm();
    let n = n_raw.max(MIN_DISTANCE_M);
    let p_hat = if n_raw >= MIN_DISTANCE_M { p_kd / n_raw } else { Vec2::new(1.0, 0.0) };
    let n_dot = p_hat.dot(&v_kd);
    let v_perp2 = (v_kd.norm_squared() - n_dot * n_dot).max(0.0);
    let delta_sum = delta_k + delta_d;
    let h = (2.0 * delta_sum * (n - d_c).max(0.0)).sqrt();
    let b = h + n_dot;
    let rhs = braking_term(delta_sum, n_dot, h, b) + v_perp2 / n + zeta * b.powi(3);
    Row { a: -p_hat, c: delta_k / delta_sum * rhs, b, kind }
}

/// End-point barrier of a finite wall (docs/safety.md §5 R2): the collision barrier with a static
/// obstacle at `vertex` (δ_d = 0, D_c → D_s), for a UAV at `p` with velocity `v`.
pub fn point_row(p: Vec2, v: Vec2, vertex: Vec2, delta: f64, d_s: f64, zeta: f64, kind: RowKind) -> Row {
    collision_row(p - vertex, v, delta, 0.0, d_s, zeta, kind)
}

/// Gain κ (1/s) of the linear class-K term that [`vertex_row`] and [`pair_row`] add to ζb³.
pub const CLASS_K_GAIN: f64 = 4.0;
/// b₀ (m/s): below this barrier value a vertex's row and a pair row are the paper's again.
pub const CLASS_K_FLOOR: f64 = 0.5;

/// The linear class-K term κ·max(b − b₀, 0) added to ζb³ (docs/safety.md §10.5, §10.7).
fn linear_class_k(b: f64) -> f64 {
    CLASS_K_GAIN * (b - CLASS_K_FLOOR).max(0.0)
}

/// Pair row of cooperating UAVs k and d (docs/safety.md §10.7): the [`collision_row`] with the
/// class-K function ζb³ + κ·max(b − b₀, 0) instead of ζb³, shared like the rest of the row
/// (δ_k/δΣ of it). It still keeps b_kd ≥ 0 and is the paper's row below b₀; above b₀ it no longer
/// keeps a UAV from braking (or a pair from closing in) while their braking margin is large.
pub fn pair_row(
    p_kd: Vec2,
    v_kd: Vec2,
    delta_k: f64,
    delta_d: f64,
    d_c: f64,
    zeta: f64,
    kind: RowKind,
) -> Row {
    let row = collision_row(p_kd, v_kd, delta_k, delta_d, d_c, zeta, kind);
    Row { c: row.c + delta_k / (delta_k + delta_d) * linear_class_k(row.b), ..row }
}

/// End-point barrier of a road vertex V (docs/safety.md §10.5): the row of [`point_row`] with the
/// class-K function ζb³ + κ·max(b − b₀, 0) (κ = [`CLASS_K_GAIN`], b₀ = [`CLASS_K_FLOOR`]) instead of
/// ζb³. It still keeps b ≥ 0 and is the paper's row below b₀; above b₀ it no longer throttles a UAV
/// flying past V (along a wall that V ends, or through the mouth of a narrowing) to a crawl while
/// its braking margin to V is large.
pub fn vertex_row(p: Vec2, v: Vec2, vertex: Vec2, delta: f64, d_s: f64, zeta: f64, kind: RowKind) -> Row {
    let row = point_row(p, v, vertex, delta, d_s, zeta, kind);
    Row { c: row.c + linear_class_k(row.b), ..row }
}

/// Signed line barrier (docs/safety.md §3, E5): with s = n̂_inᵀ(p − a) and ṡ = n̂_inᵀv,
/// b_kij = √(2δ(s − D_s)) + ṡ, row `−n̂_inᵀu ≤ δṡ/g + ζb³`. `n_in` must be a unit vector.
pub fn line_row(s: f64, s_dot: f64, n_in: Vec2, delta: f64, d_s: f64, zeta: f64, kind: RowKind) -> Row {
    let g = (2.0 * delta * (s - d_s).max(0.0)).sqrt();
    let b = g + s_dot;
    let c = braking_term(delta, s_dot, g, b) + zeta * b.powi(3);
    Row { a: -n_in, c, b, kind }
}

/// The braking margin of eq. (2)/(6) with the corrected sign (E1): `dist − min(rate, 0)²/(2δ)`, the
/// closest distance reached if braking at δ starts now.
pub fn braking_margin(dist: f64, rate: f64, delta: f64) -> f64 {
    let closing = rate.min(0.0);
    dist - closing * closing / (2.0 * delta)
}

/// The largest acceleration (m/s²) towards an obstacle that, held for one tick `dt`, leaves the
/// braking margin non-negative at the next sample (docs/safety.md §4.4), for a UAV `gap` (m) beyond
/// its clearance (taken as 0 inside it) moving away at `rate` (m/s). Negative: it must accelerate away.
///
/// With e = gap, w = rate + a·dt after a push a: the margin `e + (rate + w)dt/2 − min(w, 0)²/(2δ)` is
/// increasing in w, so the bound is its root; it is ≥ −δ whenever the margin is ≥ 0 now, which is
/// b ≥ 0, so full braking still meets it.
pub fn held_push_limit(gap: f64, rate: f64, delta: f64, dt: f64) -> f64 {
    let coast = gap.max(0.0) + rate * dt / 2.0;
    let w_min = if coast >= 0.0 {
        (delta * dt - (delta * delta * dt * dt + 8.0 * delta * coast).sqrt()) / 2.0
    } else {
        -2.0 * coast / dt
    };
    (rate - w_min) / dt
}

/// `row` tightened so that its input, held for `dt`, keeps the braking margin ≥ 0 at the next sample
/// ([`held_push_limit`]); `bend` (m/s²) is the rate's own change at zero input (‖v_⊥‖²/n for a point,
/// 0 for a line).
pub fn held_for(row: Row, gap: f64, rate: f64, bend: f64, delta: f64, dt: f64) -> Row {
    Row { c: row.c.min(bend + held_push_limit(gap, rate, delta, dt)), ..row }
}
