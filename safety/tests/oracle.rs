//! Proves that `safety::paper`, `safety::barrier` and `safety::QpSolver` reproduce every value of the
//! oracle `tests/data/cbf_test_vectors.json` (30 states, 6 end-point walls, 12 QP cases).

use roads::{Quad, Wall, WallKind, nearest_on_segment};
use safety::barrier::{collision_row, line_row, point_row};
use safety::paper::{CollisionTerms, RoadTerms};
use safety::{ConstraintRow, QpSolver, RowKind};
use serde_json::Value;
use uav::Vec2;

const VECTORS: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data/cbf_test_vectors.json");
/// Barrier and row values: |x − y| ≤ REL·max(|y|, 1).
const REL: f64 = 1e-9;
/// QP solutions (interior-point tolerances 1e-9, compared loosely).
const QP_TOL: f64 = 1e-5;

fn load() -> Option<Value> {
    match std::fs::read_to_string(VECTORS) {
        Ok(text) => Some(serde_json::from_str(&text).expect("cbf_test_vectors.json is valid JSON")),
        Err(e) => {
            eprintln!("skipping: oracle file {VECTORS} not found ({e})");
            None
        }
    }
}

fn num(v: &Value) -> f64 {
    v.as_f64().unwrap_or_else(|| panic!("expected a number, got {v}"))
}

fn vec2(v: &Value) -> Vec2 {
    Vec2::new(num(&v[0]), num(&v[1]))
}

fn check(what: &str, got: f64, want: f64) {
    assert!(
        got.is_finite() && (got - want).abs() <= REL * want.abs().max(1.0),
        "{what}: got {got:e}, oracle {want:e}"
    );
}

fn check_v(what: &str, got: Vec2, want: &Value) {
    let want = vec2(want);
    check(&format!("{what}.x"), got.x, want.x);
    check(&format!("{what}.y"), got.y, want.y);
}

fn check_qp(what: &str, got: f64, want: f64) {
    assert!((got - want).abs() <= QP_TOL, "{what}: got {got:e}, oracle {want:e}");
}

#[test]
fn description_matches_the_conventions_used_here() {
    let Some(d) = load() else { return };
    let desc = d["description"].as_str().expect("description");
    assert!(desc.contains("Delta2 = -(v_kd.p_kd)^2/|p_kd|^2 + zeta b^3 |p_kd|"), "{desc}");
    assert!(desc.contains("21: through p1, direction p2-p1; 43: through p3, direction p4-p3"), "{desc}");
    let conv = d["segment_convention"].as_str().expect("segment_convention");
    assert!(conv.contains("[p1,p2,p3,p4]") && conv.contains("polygon order p1,p2,p4,p3"), "{conv}");
    let params = uav::Params::default();
    assert_eq!(num(&d["constants"]["D_c"]), params.d_c);
    assert_eq!(num(&d["constants"]["D_s"]), params.d_s);
    assert_eq!(num(&d["constants"]["zeta"]), params.zeta);
}

fn check_collision(id: &str, inp: &Value, c: &Value, (d_c, zeta): (f64, f64)) {
    let (p_k, v_k, u_k) = (vec2(&inp["p_k"]), vec2(&inp["v_k"]), vec2(&inp["u_k"]));
    let (p_d, v_d, u_d) = (vec2(&inp["p_d"]), vec2(&inp["v_d"]), vec2(&inp["u_d"]));
    let (dk, dd) = (num(&inp["delta_k"]), num(&inp["delta_d"]));
    let (p, v) = (p_k - p_d, v_k - v_d);
    check_v(&format!("{id}.p_kd"), p, &c["p_kd"]);
    check_v(&format!("{id}.v_kd"), v, &c["v_kd"]);
    let t = CollisionTerms::new(p, v, dk, dd, d_c, zeta);
    check(&format!("{id}.norm_p_kd"), t.norm_p_kd, num(&c["norm_p_kd"]));
    check(&format!("{id}.vbar_kd"), t.vbar_kd, num(&c["vbar_kd"]));
    check(&format!("{id}.sqrt_term"), t.sqrt_term, num(&c["sqrt_term"]));
    check(&format!("{id}.b_kd"), t.b_kd, num(&c["b_kd"]));
    check(&format!("{id}.S_kd"), t.s_kd, num(&c["S_kd"]));
    check(&format!("{id}.Delta1"), t.delta1, num(&c["Delta1"]));
    check(&format!("{id}.Delta2"), t.delta2, num(&c["Delta2"]));
    check_v(&format!("{id}.rel_row.a"), -p, &c["rel_row"]["a"]);
    check(&format!("{id}.rel_row.rhs"), t.rhs(), num(&c["rel_row"]["rhs"]));
    let sum = dk + dd;
    check_v(&format!("{id}.dec_row_k.a"), -p, &c["dec_row_k"]["a"]);
    check(&format!("{id}.dec_row_k.rhs"), dk / sum * t.rhs(), num(&c["dec_row_k"]["rhs"]));
    check_v(&format!("{id}.dec_row_d.a"), p, &c["dec_row_d"]["a"]);
    check(&format!("{id}.dec_row_d.rhs"), dd / sum * t.rhs(), num(&c["dec_row_d"]["rhs"]));
    let row = collision_row(p, v, dk, dd, d_c, zeta, RowKind::Collision(1));
    check_v(&format!("{id}.dec_row_k_normalized.a"), row.a, &c["dec_row_k_normalized"]["a"]);
    check(&format!("{id}.dec_row_k_normalized.rhs"), row.c, num(&c["dec_row_k_normalized"]["rhs"]));
    check(&format!("{id}.b_kd (row)"), row.b, num(&c["b_kd"]));
    // The pair's rows from d's side (p → −p, v → −v) carry the same barrier and the other share.
    let row_d = collision_row(-p, -v, dd, dk, d_c, zeta, RowKind::Collision(0));
    check(&format!("{id}.dec_row_d.rhs (normalised)"), row_d.c * t.norm_p_kd, num(&c["dec_row_d"]["rhs"]));
    let bdot = t.rhs() / t.norm_p_kd - zeta * t.b_kd.powi(3) + p.dot(&(u_k - u_d)) / t.norm_p_kd;
    check(&format!("{id}.bdot_at_u"), bdot, num(&c["bdot_at_u"]));
}

fn check_road(id: &str, inp: &Value, j: &str, r: &Value, (d_s, zeta): (f64, f64)) {
    let (p, v, u) = (vec2(&inp["p_k"]), vec2(&inp["v_k"]), vec2(&inp["u_k"]));
    let delta = num(&inp["delta_k"]);
    let seg = &inp["segment"];
    let quad = Quad { p: [vec2(&seg[0]), vec2(&seg[1]), vec2(&seg[2]), vec2(&seg[3])] };
    // j = 21: line through p1 along p2 − p1; j = 43: through p3 along p4 − p3 (segment_convention).
    let (a, b, kind) = match j {
        "21" => (quad.p[0], quad.p[1], WallKind::Side21),
        "43" => (quad.p[2], quad.p[3], WallKind::Side43),
        other => panic!("unknown line {other}"),
    };
    check_v(&format!("{id}.line_point"), a, &r["line_point"]);
    check_v(&format!("{id}.line_vector"), b - a, &r["line_vector"]);
    let t = RoadTerms::new(p, v, a, b - a, delta, d_s, zeta);
    check_v(&format!("{id}.O_kij"), t.o_kij, &r["O_kij"]);
    check(&format!("{id}.norm_O_kij"), t.norm_o_kij, num(&r["norm_O_kij"]));
    check(&format!("{id}.vbar_kij"), t.vbar_kij, num(&r["vbar_kij"]));
    check(&format!("{id}.sqrt_term"), t.sqrt_term, num(&r["sqrt_term"]));
    check(&format!("{id}.b_kij"), t.b_kij, num(&r["b_kij"]));
    check(&format!("{id}.S_kij"), t.s_kij, num(&r["S_kij"]));
    check(&format!("{id}.Delta1"), t.delta1, num(&r["Delta1"]));
    check(&format!("{id}.Delta2"), t.delta2, num(&r["Delta2"]));
    check_v(&format!("{id}.row.a"), -t.o_kij, &r["row"]["a"]);
    check(&format!("{id}.row.rhs"), t.rhs(), num(&r["row"]["rhs"]));
    // 2-D: the curvature terms cancel, rhs = ‖O‖(δ v̄/g + ζb³).
    let simplified = t.norm_o_kij * (delta * t.vbar_kij / t.sqrt_term + zeta * t.b_kij.powi(3));
    check(&format!("{id}.rhs_2d_simplified"), simplified, num(&r["rhs_2d_simplified"]));

    let wall = Wall::new(a, b, &quad, 0, kind);
    check_v(&format!("{id}.inward_normal"), wall.n_in, &r["inward_normal"]);
    // Unsigned direction Ô = O_kij/‖O_kij‖ is ±n̂_in.
    let o_hat = t.o_kij / t.norm_o_kij;
    assert!((o_hat.dot(&wall.n_in).abs() - 1.0).abs() < 1e-12, "{id}: Ô is not ±n̂_in");
    let row = line_row(t.norm_o_kij, o_hat.dot(&v), o_hat, delta, d_s, zeta, RowKind::Road(0));
    check_v(&format!("{id}.row_normalized.a"), row.a, &r["row_normalized"]["a"]);
    check(&format!("{id}.row_normalized.rhs"), row.c, num(&r["row_normalized"]["rhs"]));
    check(&format!("{id}.b_kij (row)"), row.b, num(&r["b_kij"]));
    let s = wall.signed_distance(&p);
    check(&format!("{id}.signed_distance"), s, num(&r["signed_distance"]));
    let signed = line_row(s, wall.n_in.dot(&v), wall.n_in, delta, d_s, zeta, RowKind::Road(0));
    check(&format!("{id}.b_signed"), signed.b, num(&r["b_signed"]));
    let bdot = t.rhs() / t.norm_o_kij - zeta * t.b_kij.powi(3) + o_hat.dot(&u);
    check(&format!("{id}.bdot_at_u"), bdot, num(&r["bdot_at_u"]));
}

#[test]
fn vectors_collision_and_road_terms() {
    let Some(d) = load() else { return };
    let k = &d["constants"];
    let (d_c, d_s, zeta) = (num(&k["D_c"]), num(&k["D_s"]), num(&k["zeta"]));
    let vectors = d["vectors"].as_array().expect("vectors");
    assert_eq!(vectors.len(), 30, "oracle should hold 30 vectors");
    let (mut n_coll, mut n_road) = (0, 0);
    for vec in vectors {
        let id = format!("vectors[{}]", vec["id"]);
        check_collision(&format!("{id}.collision"), &vec["inputs"], &vec["collision"], (d_c, zeta));
        n_coll += 1;
        let road = vec["road"].as_object().expect("road");
        assert_eq!(road.len(), 2, "{id}: lines 21 and 43");
        for (j, r) in road {
            check_road(&format!("{id}.road.{j}"), &vec["inputs"], j, r, (d_s, zeta));
            n_road += 1;
        }
    }
    assert_eq!((n_coll, n_road), (30, 60));
}

#[test]
fn walls_end_point_rows() {
    let Some(d) = load() else { return };
    let k = &d["constants"];
    let (d_s, zeta) = (num(&k["D_s"]), num(&k["zeta"]));
    let walls = d["walls"].as_array().expect("walls");
    assert_eq!(walls.len(), 6, "oracle should hold 6 walls");
    let mut checked = 0;
    for w in walls {
        let id = format!("walls[{}]", w["id"]);
        let inp = &w["inputs"];
        let (p, v) = (vec2(&inp["p_k"]), vec2(&inp["v_k"]));
        let (a, b) = (vec2(&inp["A"]), vec2(&inp["B"]));
        let (c, t) = nearest_on_segment(&a, &b, &p);
        assert!(t == 0.0 || t == 1.0, "{id}: the oracle's walls are in the end-point region (t = {t})");
        check_v(&format!("{id}.nearest_point"), c, &w["nearest_point"]);
        let row = point_row(p, v, c, num(&inp["delta_k"]), d_s, zeta, RowKind::Road(0));
        check(&format!("{id}.b"), row.b, num(&w["b"]));
        check_v(&format!("{id}.row_normalized.a"), row.a, &w["row_normalized"]["a"]);
        check(&format!("{id}.row_normalized.rhs"), row.c, num(&w["row_normalized"]["rhs"]));
        checked += 1;
    }
    assert_eq!(checked, 6);
}

#[test]
fn qp_cases() {
    let Some(d) = load() else { return };
    let cases = d["qp_cases"].as_array().expect("qp_cases");
    assert_eq!(cases.len(), 12, "oracle should hold 12 QP cases");
    let mut solver = QpSolver::new();
    let mut checked = 0;
    for case in cases {
        let id = format!("qp_cases[{}]", case["id"]);
        let (inp, want) = (&case["inputs"], &case["expected"]);
        let (rho, weight) = (num(&inp["rho"]), num(&inp["p_slack"]));
        let rows_a = inp["rows_a"].as_array().expect("rows_a");
        let rows_c = inp["rows_c"].as_array().expect("rows_c");
        assert_eq!(rows_a.len(), rows_c.len(), "{id}");
        let rows: Vec<ConstraintRow> = rows_a
            .iter()
            .zip(rows_c)
            .map(|(a, c)| ConstraintRow { a: vec2(a), c: num(c), rho, weight })
            .collect();
        let sol = solver.solve(vec2(&inp["u_r"]), &rows, num(&inp["delta_k"]));
        assert_eq!(format!("{:?}", sol.status), want["status"].as_str().expect("status"), "{id}");
        let u = vec2(&want["u"]);
        check_qp(&format!("{id}.u.x"), sol.u.x, u.x);
        check_qp(&format!("{id}.u.y"), sol.u.y, u.y);
        check_qp(&format!("{id}.objective"), sol.objective, num(&want["objective"]));
        let slacks = want["slacks"].as_array().expect("slacks");
        assert_eq!(solver.slacks().len(), slacks.len(), "{id}: one slack per row");
        for (c, (got, want)) in solver.slacks().iter().zip(slacks).enumerate() {
            check_qp(&format!("{id}.slacks[{c}]"), *got, num(want));
        }
        let max = slacks.iter().map(num).fold(0.0, f64::max);
        check_qp(&format!("{id}.max_slack"), sol.max_slack, max);
        checked += 1;
    }
    assert_eq!(checked, 12);
}
