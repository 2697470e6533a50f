//! Barrier functions and their affine CBF rows in normalised form `aᵀu_k ≤ c`, ‖a‖ = 1, with the
//! numerically safe evaluation of docs/safety.md §4 (clamp `max(h, h_min)`, never √ of a negative
//! number).

use uav::{Params, Vec2};

/// h_min (m/s): lower clamp of h = √(2δΣ(n − D_c)) and g = √(2δ(s − D_s)) in the rows
/// (docs/safety.md §4.1).
pub const H_MIN: f64 = 1e-3;
/// Distances below this (m) are treated as this, to keep p̂ defined after a collision
/// (docs/safety.md §4.3).
pub const MIN_DISTANCE_M: f64 = 1e-12;

/// The clearance a barrier keeps: the distance D (D_c or D_s) and the model-error allowances η_p, η_v
/// of docs/safety.md §12 (0 for the exact double integrator). The barrier is
/// `b = √(2δ(n − D − η_p)) + ṅ − η_v`: braking at δ from a state with b ≥ 0 stops at least D away
/// even if the true distance is η_p shorter and the true closing speed up to η_v faster.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Clearance {
    /// The distance to keep, D (m).
    pub d: f64,
    /// Position allowance η_p (m).
    pub eta_p: f64,
    /// Closing-speed allowance η_v (m/s).
    pub eta_v: f64,
}

impl Clearance {
    /// D with no model-error allowance (the double integrator of docs/safety.md §1–§11).
    pub fn exact(d: f64) -> Self {
        Self { d, eta_p: 0.0, eta_v: 0.0 }
    }

    /// D with one UAV's allowances η_p, η_v of `params`: a wall (D = D_s) or an obstacle.
    pub fn one(d: f64, params: &Params) -> Self {
        Self { d, eta_p: params.eta_p, eta_v: params.eta_v }
    }

    /// D with two UAVs' allowances, which add up (2η_p, 2η_v): a cooperating pair.
    pub fn pair(d: f64, params: &Params) -> Self {
        Self { d, eta_p: 2.0 * params.eta_p, eta_v: 2.0 * params.eta_v }
    }

    /// The distance h and the rates are measured from: D + η_p.
    pub fn boundary(&self) -> f64 {
        self.d + self.eta_p
    }
}

impl From<f64> for Clearance {
    fn from(d: f64) -> Self {
        Self::exact(d)
    }
}

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

/// Gain κ_η (1/s) with which a barrier that only the allowance η_v makes negative is brought back
/// (docs/safety.md §12).
pub const RECOVERY_GAIN: f64 = 4.0;

/// What the allowance adds to the class-K term ζb³, with b = b_std − η_v (docs/safety.md §12):
/// above 0, enough to make it `ζ((b + η_v)³ − η_v³)`, the exact model's term at the same distance
/// less its value on the new boundary (ζb³ alone left a crawl towards a wall: 0.003 m/s² at a goal
/// 0.35 m from it, and a stronger linear term let a lagging UAV push through the allowance); below
/// 0, where the state is safe for the model but not with its errors, κ_η·max(b, −η_v), which brings
/// it back (ζb³ alone let a persistent estimate error keep a pair closing at 0.26 m/s). 0 whenever
/// η_v = 0, so the exact model's rows are unchanged.
fn allowance_term(b: f64, zeta: f64, eta_v: f64) -> f64 {
    if b >= 0.0 {
        zeta * ((b + eta_v).powi(3) - b.powi(3) - eta_v.powi(3))
    } else {
        RECOVERY_GAIN * b.max(-eta_v)
    }
}

/// The rate the braking term may count on when the read `rate` is off by up to `eta_v`: a read
/// approach as read (what the allowance in b already covers), a read recession only the part of it
/// the error cannot take away, `max(rate − η_v, 0)` (docs/safety.md §12).
fn sure_rate(rate: f64, eta_v: f64) -> f64 {
    if rate > 0.0 { (rate - eta_v).max(0.0) } else { rate }
}

/// The barrier of a UAV `dist` (m) from an obstacle, receding at `rate` (m/s), braking at `delta`
/// (m/s²), and its row's right-hand side without curvature terms (docs/safety.md §1, §3, §12):
/// h = √(2δ(dist − D − η_p)), b = h + rate − η_v, c = δ·[`sure_rate`]/h + ζb³ + the allowance term.
fn barrier(dist: f64, rate: f64, delta: f64, clearance: Clearance, zeta: f64) -> (f64, f64) {
    let h = (2.0 * delta * (dist - clearance.boundary()).max(0.0)).sqrt();
    let b = h + rate - clearance.eta_v;
    let sure = sure_rate(rate, clearance.eta_v);
    let c =
        braking_term(delta, sure, h, h + sure) + zeta * b.powi(3) + allowance_term(b, zeta, clearance.eta_v);
    (b, c)
}

/// Collision row of UAV k against neighbour d (docs/safety.md §1, §2; paper eq. 4, 11, 14):
/// b_kd = √(2δΣ(‖p_kd‖ − D_c)) + p̂_kdᵀv_kd, row
/// `−p̂ᵀu_k ≤ δ_k/δΣ · (δΣ ṅ/h + ‖v_⊥‖²/n + ζ b_kd³)`, with δΣ = δ_k + δ_d; with model-error
/// allowances D_c + η_p in h, b_kd − η_v in the class-K term and the braking term at the rate the
/// read vouches for, ṅ_η (§12).
pub fn collision_row(
    p_kd: Vec2,
    v_kd: Vec2,
    delta_k: f64,
    delta_d: f64,
    d_c: impl Into<Clearance>,
    zeta: f64,
    kind: RowKind,
) -> Row {
    let n_raw = p_kd.norm();
    let n = n_raw.max(MIN_DISTANCE_M);
    let p_hat = if n_raw >= MIN_DISTANCE_M { p_kd / n_raw } else { Vec2::new(1.0, 0.0) };
    let n_dot = p_hat.dot(&v_kd);
    let v_perp2 = (v_kd.norm_squared() - n_dot * n_dot).max(0.0);
    let delta_sum = delta_k + delta_d;
    let (b, rhs) = barrier(n, n_dot, delta_sum, d_c.into(), zeta);
    Row { a: -p_hat, c: delta_k / delta_sum * (rhs + v_perp2 / n), b, kind }
}

/// End-point barrier of a finite wall (docs/safety.md §5 R2): the collision barrier with a static
/// obstacle at `vertex` (δ_d = 0, D_c → D_s), for a UAV at `p` with velocity `v`.
pub fn point_row(
    p: Vec2,
    v: Vec2,
    vertex: Vec2,
    delta: f64,
    d_s: impl Into<Clearance>,
    zeta: f64,
    kind: RowKind,
) -> Row {
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
    d_c: impl Into<Clearance>,
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
pub fn vertex_row(
    p: Vec2,
    v: Vec2,
    vertex: Vec2,
    delta: f64,
    d_s: impl Into<Clearance>,
    zeta: f64,
    kind: RowKind,
) -> Row {
    let row = point_row(p, v, vertex, delta, d_s, zeta, kind);
    Row { c: row.c + linear_class_k(row.b), ..row }
}

/// Signed line barrier (docs/safety.md §3, E5): with s = n̂_inᵀ(p − a) and ṡ = n̂_inᵀv,
/// b_kij = √(2δ(s − D_s)) + ṡ, row `−n̂_inᵀu ≤ δṡ/g + ζb³`; with model-error allowances D_s + η_p in
/// g, b_kij − η_v in the class-K term and ṡ_η in the braking term (§12). `n_in` must be a unit
/// vector.
pub fn line_row(
    s: f64,
    s_dot: f64,
    n_in: Vec2,
    delta: f64,
    d_s: impl Into<Clearance>,
    zeta: f64,
    kind: RowKind,
) -> Row {
    let (b, c) = barrier(s, s_dot, delta, d_s.into(), zeta);
    Row { a: -n_in, c, b, kind }
}

/// The braking margin of eq. (2)/(6) with the corrected sign (E1): `dist − min(rate, 0)²/(2δ)`, the
/// closest distance reached if braking at δ starts now.
pub fn braking_margin(dist: f64, rate: f64, delta: f64) -> f64 {
    let closing = rate.min(0.0);
    dist - closing * closing / (2.0 * delta)
}

/// The largest acceleration (m/s²) towards an obstacle that, held for one tick `dt`, leaves the
/// barrier non-negative at the next sample (docs/safety.md §4.4, §12), for a UAV `gap` (m) beyond
/// its boundary D + η_p (taken as 0 inside it) moving away at `rate` (m/s), with closing-speed
/// allowance `eta_v` (m/s). Negative: it must accelerate away.
///
/// With e = gap, w = rate + a·dt after a push a: the next sample's gap is `e + (rate + w)dt/2` and
/// the barrier there asks `w − η_v ≥ −√(2δ·gap)`; the bound is the root of that, increasing in w.
/// It is ≥ −δ whenever the barrier is ≥ 0 now, so full braking still meets it. With η_v = 0 it is
/// the braking margin `e + (rate + w)dt/2 − min(w, 0)²/(2δ) ≥ 0` of §4.4.
pub fn held_push_limit(gap: f64, rate: f64, delta: f64, dt: f64, eta_v: f64) -> f64 {
    let coast = gap.max(0.0) + (rate + eta_v) * dt / 2.0;
    let w_min = if coast >= 0.0 {
        eta_v + (delta * dt - (delta * delta * dt * dt + 8.0 * delta * coast).sqrt()) / 2.0
    } else {
        -2.0 * (gap.max(0.0) + rate * dt / 2.0) / dt
    };
    (rate - w_min) / dt
}

/// `row` tightened so that its input, held for `dt`, keeps the barrier ≥ 0 at the next sample
/// ([`held_push_limit`]); `bend` (m/s²) is the rate's own change at zero input (‖v_⊥‖²/n for a point,
/// 0 for a line).
pub fn held_for(row: Row, gap: f64, rate: f64, bend: f64, delta: f64, dt: f64, eta_v: f64) -> Row {
    Row { c: row.c.min(bend + held_push_limit(gap, rate, delta, dt, eta_v)), ..row }
}
