//! Proves that every row `aᵀu ≤ c` encodes the true barrier derivative: ḃ = L_f b + L_g b·u with
//! L_f b = c/σ − ζb³ and L_g b = −a matches a central finite difference of b along the exact
//! double-integrator flow (collision, signed line and end-point barriers), and that the normalised
//! rows equal the paper's Δ¹ + Δ² divided by ‖p_kd‖ (‖O_kij‖).

use proptest::prelude::*;
use roads::{Quad, Wall, WallKind, nearest_on_segment};
use safety::RowKind;
use safety::barrier::{collision_row, line_row, point_row};
use safety::paper::{CollisionTerms, RoadTerms};
use uav::{UavState, Vec2};

const D_C: f64 = 0.3;
const D_S: f64 = 0.1;
const ZETA: f64 = 0.05;
/// Central-difference step (s).
const TAU: f64 = 1e-5;
/// |ḃ_fd − ḃ| ≤ FD_REL · max(|ḃ|, 1).
const FD_REL: f64 = 1e-5;
/// Row identities (no finite differences): relative to the size of the terms.
const ID_REL: f64 = 1e-9;
/// Distance kept from the singular sets n = D_c and s = D_s (m).
const GAP: f64 = 0.05;

fn unit(angle: f64) -> Vec2 {
    Vec2::new(angle.cos(), angle.sin())
}

fn vec2() -> impl Strategy<Value = Vec2> {
    (-5.0..5.0f64, -5.0..5.0f64).prop_map(|(x, y)| Vec2::new(x, y))
}

/// An input with ‖u‖ ≤ δ for δ = 1 (scaled by the caller).
fn unit_ball() -> impl Strategy<Value = Vec2> {
    (0.0..std::f64::consts::TAU, 0.0..=1.0f64).prop_map(|(a, r)| unit(a) * r)
}

/// Central difference of `b` along the flow of `x` under constant inputs (b takes the flowed state).
fn central<F: Fn(f64) -> f64>(b: F) -> f64 {
    (b(TAU) - b(-TAU)) / (2.0 * TAU)
}

fn assert_fd(what: &str, fd: f64, analytic: f64) -> Result<(), TestCaseError> {
    let err = (fd - analytic).abs() / analytic.abs().max(1.0);
    prop_assert!(
        err <= FD_REL,
        "{}: finite difference {:e} vs analytic {:e} (rel err {:e})",
        what,
        fd,
        analytic,
        err
    );
    Ok(())
}

fn assert_identity(what: &str, got: f64, want: f64, scale: f64) -> Result<(), TestCaseError> {
    let ok = (got - want).abs() <= ID_REL * scale.max(1.0);
    prop_assert!(ok, "{}: {:e} vs {:e}", what, got, want);
    Ok(())
}

/// A wall `[a, b]` with its road on the side of `side` (±1), built through `roads::Wall::new`.
fn wall(a: Vec2, angle: f64, len: f64, side: f64) -> Wall {
    let e = unit(angle);
    let b = a + e * len;
    let n = Vec2::new(-e.y, e.x) * side;
    let quad = Quad { p: [a, b, a + n * 3.0, b + n * 3.0] };
    Wall::new(a, b, &quad, 0, WallKind::Side21)
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(2000))]

    #[test]
    fn collision_barrier_derivative(
        (p_k, dir, extra) in (vec2(), 0.0..std::f64::consts::TAU, 0.0..8.0f64),
        (v_k, v_d) in (vec2(), vec2()),
        (u_k, u_d) in (unit_ball(), unit_ball()),
        (delta_k, delta_d) in (1.0..8.0f64, 1.0..8.0f64),
    ) {
        let p_d = p_k + unit(dir) * (D_C + GAP + extra);
        let (k, d) = (UavState { p: p_k, v: v_k }, UavState { p: p_d, v: v_d });
        let (u_k, u_d) = (u_k * delta_k, u_d * delta_d);
        let (p, v) = (k.p - d.p, k.v - d.v);
        let b_at = |t: f64| {
            let (k, d) = (k.stepped(u_k, t), d.stepped(u_d, t));
            collision_row(k.p - d.p, k.v - d.v, delta_k, delta_d, D_C, ZETA, RowKind::Collision(1)).b
        };
        let row = collision_row(p, v, delta_k, delta_d, D_C, ZETA, RowKind::Collision(1));
        let share = delta_k / (delta_k + delta_d);
        let lf = row.c / share - ZETA * row.b.powi(3);
        let lg = -row.a;
        let bdot = lf + lg.dot(&(u_k - u_d));
        assert_fd("collision ḃ", central(b_at), bdot)?;

        // Paper scale: ‖p_kd‖ · (normalised full rhs) = Δ¹ + Δ², and ‖p‖(ḃ + ζb³) = Δ¹ + Δ² + p_kdᵀu_kd.
        let t = CollisionTerms::new(p, v, delta_k, delta_d, D_C, ZETA);
        let scale = t.delta1.abs().max(t.delta2.abs());
        assert_identity("collision b", row.b, t.b_kd, t.b_kd.abs())?;
        assert_identity("‖p_kd‖·c/σ = Δ¹+Δ²", t.norm_p_kd * row.c / share, t.rhs(), scale)?;
        let paper_bdot = (t.rhs() + p.dot(&(u_k - u_d))) / t.norm_p_kd - ZETA * t.b_kd.powi(3);
        assert_identity("paper ḃ", paper_bdot, bdot, scale / t.norm_p_kd)?;
        // The neighbour's row (p → −p, v → −v) has the same barrier and the complementary share.
        let row_d = collision_row(-p, -v, delta_d, delta_k, D_C, ZETA, RowKind::Collision(0));
        assert_identity("b_dk = b_kd", row_d.b, row.b, row.b.abs())?;
        assert_identity("shares add up", row.c + row_d.c, row.c / share, scale / t.norm_p_kd)?;
    }

    #[test]
    fn signed_line_barrier_derivative(
        (a, angle, len, side) in (vec2(), 0.0..std::f64::consts::TAU, 0.5..10.0f64, prop::bool::ANY),
        (along, extra) in (-1.0..2.0f64, 0.0..5.0f64),
        (v, u, delta) in (vec2(), unit_ball(), 1.0..8.0f64),
    ) {
        let w = wall(a, angle, len, if side { 1.0 } else { -1.0 });
        let e = (w.b - w.a) / len;
        let x = UavState { p: w.a + e * (along * len) + w.n_in * (D_S + GAP + extra), v };
        let u = u * delta;
        let row_at = |x: &UavState| {
            line_row(w.signed_distance(&x.p), w.n_in.dot(&x.v), w.n_in, delta, D_S, ZETA, RowKind::Road(0))
        };
        let row = row_at(&x);
        let bdot = (row.c - ZETA * row.b.powi(3)) + (-row.a).dot(&u);
        assert_fd("line ḃ", central(|t| row_at(&x.stepped(u, t)).b), bdot)?;

        // On the road side the signed barrier is the paper's unsigned one: ‖O_kij‖·c = Δ¹ + Δ².
        let t = RoadTerms::new(x.p, x.v, w.a, w.b - w.a, delta, D_S, ZETA);
        let scale = t.delta1.abs().max(t.delta2.abs());
        assert_identity("road b", row.b, t.b_kij, t.b_kij.abs())?;
        assert_identity("‖O_kij‖·c = Δ¹+Δ²", t.norm_o_kij * row.c, t.rhs(), scale)?;
        prop_assert!((t.o_kij / t.norm_o_kij - w.n_in).norm() < 1e-9, "Ô_kij = n̂_in on the road side");
    }

    #[test]
    fn end_point_barrier_derivative(
        (a, angle, len, side) in (vec2(), 0.0..std::f64::consts::TAU, 0.5..10.0f64, prop::bool::ANY),
        (beyond, extra) in (0.1..(std::f64::consts::PI - 0.1), 0.0..5.0f64),
        (v, u, delta) in (vec2(), unit_ball(), 1.0..8.0f64),
    ) {
        let w = wall(a, angle, len, if side { 1.0 } else { -1.0 });
        // A point beyond end a: the direction from a makes an angle > 90° (+0.1 rad) with b − a.
        let back = -(w.b - w.a) / len;
        let dir = unit(back.y.atan2(back.x) + beyond - std::f64::consts::FRAC_PI_2);
        let x = UavState { p: w.a + dir * (D_S + GAP + extra), v };
        let u = u * delta;
        let row_at = |x: &UavState| {
            let (c, t) = nearest_on_segment(&w.a, &w.b, &x.p);
            assert_eq!((c, t), (w.a, 0.0), "the state stays in the end-point region");
            point_row(x.p, x.v, c, delta, D_S, ZETA, RowKind::Road(0))
        };
        let row = row_at(&x);
        let bdot = (row.c - ZETA * row.b.powi(3)) + (-row.a).dot(&u);
        assert_fd("end-point ḃ", central(|t| row_at(&x.stepped(u, t)).b), bdot)?;

        // The end-point row is the collision row with a static obstacle (δ_d = 0, D_c → D_s).
        let t = CollisionTerms::new(x.p - w.a, x.v, delta, 0.0, D_S, ZETA);
        let scale = t.delta1.abs().max(t.delta2.abs());
        assert_identity("‖p − A‖·c = Δ¹+Δ²", t.norm_p_kd * row.c, t.rhs(), scale)?;
    }
}
