//! `airroads bench solver`: the exact solver against Clarabel on random QP instances that mix the
//! degenerate kinds on purpose (duplicate, parallel and concurrent rows, jointly infeasible hard
//! rows, rows through u_r, the ball active alone and with rows, u_r = 0 or outside the ball, rows
//! with tiny or zero a, up to 64 rows, both objectives). Exits 1 if any exact answer is
//! uncertified or has a KKT residual above 1e-9, or differs from a Clarabel answer by more than 1e-6
//! with a higher objective (see [`Versus`] for how a difference is attributed).

use flights::say;

use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use safety::{ConstraintRow, ExactSolver, QpSolver, kkt_residual};
use std::process::ExitCode;
use std::time::Instant;
use uav::Vec2;

/// Largest ‖u − u_clarabel‖ accepted.
const U_TOL: f64 = 1e-6;
/// Largest KKT residual accepted.
const KKT_TOL: f64 = 1e-9;

fn unit(angle: f64) -> Vec2 {
    Vec2::new(angle.cos(), angle.sin())
}

/// A random instance (u_r, rows, δ) for instance number `i`; each kind of degeneracy is switched on
/// with its own probability, so most instances combine several.
pub fn instance(rng: &mut StdRng, out: &mut Vec<ConstraintRow>) -> (Vec2, f64) {
    out.clear();
    let delta = if rng.random_bool(0.7) { 5.0 } else { rng.random_range(0.5..10.0) };
    let paper = rng.random_bool(0.1);
    let u_r = match rng.random_range(0..10) {
        0 => Vec2::zeros(),
        1..=2 => unit(rng.random_range(0.0..std::f64::consts::TAU)) * delta * rng.random_range(1.0..4.0),
        _ => unit(rng.random_range(0.0..std::f64::consts::TAU)) * delta * rng.random_range(0.0..1.0),
    };
    let m = match rng.random_range(0..20) {
        0 => 0,
        1 => rng.random_range(13..=64),
        _ => rng.random_range(1..=12),
    };
    let weights = |rng: &mut StdRng| {
        // The filter's range: ×10 for road rows, ×1/clamp(b, 0.05, 1) for urgency.
        let priority = if rng.random_bool(0.5) { 10.0 } else { 1.0 } * rng.random_range(1.0..20.0f64);
        let rho = if paper {
            0.0
        } else if rng.random_bool(0.1) {
            rng.random_range(0.0..10.0)
        } else {
            1e4 * priority
        };
        (rho, priority)
    };
    let through_ur = rng.random_bool(0.15);
    let concurrent =
        rng.random_bool(0.15).then(|| u_r + unit(rng.random_range(0.0..6.3)) * rng.random_range(0.0..delta));
    for _ in 0..m {
        let (rho, weight) = weights(rng);
        // Mostly rows that face u_r (so they bind), some in any direction.
        let facing = u_r.norm() > 0.0 && rng.random_bool(0.7);
        let base = if facing { u_r.y.atan2(u_r.x) } else { 0.0 };
        let spread = if facing { 1.2 } else { std::f64::consts::PI };
        let a = unit(base + rng.random_range(-spread..spread));
        let c = if through_ur && rng.random_bool(0.5) {
            a.dot(&u_r)
        } else if let Some(p) = concurrent.filter(|_| rng.random_bool(0.6)) {
            a.dot(&p)
        } else if rng.random_bool(0.2) {
            rng.random_range(-2.5 * delta..-delta)
        } else {
            a.dot(&u_r) - rng.random_range(-0.5..2.0) * delta
        };
        out.push(ConstraintRow { a, c, rho, weight });
    }
    let n = out.len();
    if n > 0 {
        for _ in 0..rng.random_range(0..3) {
            let k = rng.random_range(0..n);
            let row = out[k];
            match rng.random_range(0..6) {
                // A duplicate.
                0 => out.push(row),
                // A scaled duplicate (same line, other ‖a‖).
                1 => {
                    let s = rng.random_range(0.1..3.0);
                    out.push(ConstraintRow { a: row.a * s, c: row.c * s, ..row });
                }
                // A parallel row.
                2 => out.push(ConstraintRow { c: row.c + rng.random_range(-1.0..1.0), ..row }),
                // The opposite row, often making the pair jointly infeasible.
                3 => out.push(ConstraintRow { a: -row.a, c: -row.c - rng.random_range(-0.5..1.0), ..row }),
                // A row with tiny or zero a.
                4 => {
                    let s = if rng.random_bool(0.5) { 0.0 } else { 1e-9 };
                    out.push(ConstraintRow { a: row.a * s, c: rng.random_range(-1.0..1.0), ..row });
                }
                // A tie: another row through the vertex of row k and the next one.
                _ => {
                    let other = out[(k + 1) % n];
                    let det = uav::cross(&row.a, &other.a);
                    if det.abs() > 1e-3 {
                        let v = Vec2::new(
                            row.c * other.a.y - other.c * row.a.y,
                            row.a.x * other.c - other.a.x * row.c,
                        ) / det;
                        let a = unit(rng.random_range(0.0..std::f64::consts::TAU));
                        out.push(ConstraintRow { a, c: a.dot(&v), ..row });
                    }
                }
            }
        }
    }
    (u_r, delta)
}

/// Tolerance of the reference Clarabel solve (the filter's is [`safety::CLARABEL_TOL`]).
const REFERENCE_TOL: f64 = 1e-12;

/// F(u) = ½‖u − u_r‖² + Σ_c φ_c(a_cᵀu − c_c), the QP's objective with r eliminated.
fn objective(u_r: Vec2, rows: &[ConstraintRow], u: Vec2) -> f64 {
    let slack = |r: &ConstraintRow| {
        let t = (r.a.dot(&u) - r.c).max(0.0);
        r.rho * t + 0.5 * r.weight * t * t
    };
    0.5 * (u - u_r).norm_squared() + rows.iter().map(slack).sum::<f64>()
}

/// The comparison with one Clarabel configuration. With F strongly convex (modulus 1) and u_exact
/// certified optimal, F(u_clarabel) − F(u_exact) ≥ ½‖u_clarabel − u_exact‖²: a difference above 1e-6
/// is Clarabel's when F shows that gap, the exact solver's when F(u_exact) > F(u_clarabel), and
/// undecided when the gap is below F's round-off.
#[derive(Default)]
struct Versus {
    max_du: f64,
    worst: u64,
    unsolved: u64,
    compared: u64,
    /// ‖Δu‖ > 1e-6 and F(u_clarabel) − F(u_exact) ≥ ½‖Δu‖² beyond round-off: Clarabel's error.
    clarabel_off: u64,
    /// ‖Δu‖ > 1e-6 and F(u_exact) > F(u_clarabel) beyond round-off: the exact solver's error.
    exact_off: u64,
    /// ‖Δu‖ > 1e-6 and neither shown at F's round-off (objectives of 10⁵–10⁷ with ρ up to 2·10⁶).
    undecided: u64,
    max_undecided: f64,
    seconds: f64,
}

impl Versus {
    /// Adds one instance; returns ‖u − u_clarabel‖ when Clarabel solved it.
    fn add(
        &mut self,
        i: u64,
        u_r: Vec2,
        rows: &[ConstraintRow],
        ours: Vec2,
        reference: &safety::QpSolution,
    ) -> f64 {
        if reference.status != clarabel::solver::SolverStatus::Solved {
            self.unsolved += 1;
            return 0.0;
        }
        self.compared += 1;
        let du = (ours - reference.u).norm();
        if du > self.max_du {
            (self.max_du, self.worst) = (du, i);
        }
        if du <= U_TOL {
            return du;
        }
        let (f_ours, f_ref) = (objective(u_r, rows, ours), objective(u_r, rows, reference.u));
        // F's round-off: ρ_c t_c and P_c t_c² with t_c rounded at ε(|c_c| + ‖a_c‖‖u‖).
        let size: f64 = rows
            .iter()
            .map(|r| (r.rho + r.weight * r.c.abs()) * (r.c.abs() + r.a.norm() * ours.norm()))
            .sum();
        let round_off = 1e-14 * (1.0 + f_ref.abs() + size);
        if f_ours > f_ref + round_off {
            self.exact_off += 1;
        } else if f_ref - f_ours >= 0.5 * du * du + round_off {
            self.clarabel_off += 1;
        } else {
            self.undecided += 1;
            self.max_undecided = self.max_undecided.max(du);
        }
        du
    }
}

/// The instance as Rust source (for a regression test).
fn dump(u_r: Vec2, delta: f64, rows: &[ConstraintRow]) -> String {
    let rows: Vec<String> = rows
        .iter()
        .map(|r| format!("row({:?}, {:?}, {:?}, {:?}, {:?})", r.a.x, r.a.y, r.c, r.rho, r.weight))
        .collect();
    format!("Vec2::new({:?}, {:?}), {delta:?}, &[{}]", u_r.x, u_r.y, rows.join(", "))
}

/// Runs the verification over `instances` instances from `seed`.
pub fn main(instances: u64, seed: u64) -> ExitCode {
    let mut rng = StdRng::seed_from_u64(seed);
    let mut exact = ExactSolver::new();
    let (mut filter_clarabel, mut reference) = (QpSolver::new(), QpSolver::with_tolerance(REFERENCE_TOL));
    let mut rows = Vec::new();
    let (mut max_kkt, mut worst_kkt, mut uncertified, mut kkt_over) = (0f64, 0u64, 0u64, 0u64);
    let (mut vs_filter, mut vs_reference) = (Versus::default(), Versus::default());
    let mut t_exact = 0.0;
    let (mut iters, mut max_iters, mut slow) = (0usize, 0usize, 0u64);
    for i in 0..instances {
        let (u_r, delta) = instance(&mut rng, &mut rows);
        let start = Instant::now();
        let ours = exact.solve(u_r, &rows, delta);
        t_exact += start.elapsed().as_secs_f64();
        let sol = match ours {
            Ok(sol) => sol,
            Err(e) => {
                uncertified += 1;
                if uncertified <= 5 {
                    say!("instance {i}: exact solver error: {e}");
                    say!("  {}", dump(u_r, delta, &rows));
                }
                continue;
            }
        };
        iters += exact.iterations();
        max_iters = max_iters.max(exact.iterations());
        slow += u64::from(exact.iterations() > 20);
        let kkt = kkt_residual(u_r, &rows, delta, sol.u, exact.multipliers(), exact.ball_multiplier()).max();
        if kkt > max_kkt {
            (max_kkt, worst_kkt) = (kkt, i);
        }
        kkt_over += u64::from(kkt > KKT_TOL);
        let (mut du, off_before) = (0.0, vs_filter.exact_off + vs_reference.exact_off);
        for (versus, solver) in [(&mut vs_filter, &mut filter_clarabel), (&mut vs_reference, &mut reference)]
        {
            let start = Instant::now();
            let other = solver.solve(u_r, &rows, delta);
            versus.seconds += start.elapsed().as_secs_f64();
            du = versus.add(i, u_r, &rows, sol.u, &other);
        }
        if vs_filter.exact_off + vs_reference.exact_off > off_before && off_before < 3 {
            say!("instance {i}: |u - u_reference| = {du:e}, exact {:?}: {}", sol.u, dump(u_r, delta, &rows));
        }
    }
    let n = instances.max(1) as f64;
    say!("airroads bench solver: {instances} random instances (seed {seed}), exact solver vs Clarabel");
    say!(
        "  exact solver: not certified {uncertified}, max KKT residual {max_kkt:.3e} (instance {worst_kkt}), above 1e-9: {kkt_over}, mean {:.2} µs",
        t_exact / n * 1e6
    );
    for (name, v) in [
        (format!("Clarabel tol {:.0e} (as the filter)", safety::CLARABEL_TOL), &vs_filter),
        (format!("Clarabel tol {REFERENCE_TOL:.0e} (reference)"), &vs_reference),
    ] {
        say!(
            "  vs {name}: not Solved {} (not compared), compared {}, mean {:.1} µs",
            v.unsolved,
            v.compared,
            v.seconds / n * 1e6
        );
        say!(
            "    max |u - u_clarabel| {:.3e} (instance {}); above 1e-6: {} Clarabel's error (its F higher by >= |du|^2/2), {} exact's error (its F higher), {} undecided at F's round-off (max |du| {:.3e})",
            v.max_du,
            v.worst,
            v.clarabel_off,
            v.exact_off,
            v.undecided,
            v.max_undecided
        );
    }
    let pass = uncertified == 0 && kkt_over == 0 && vs_reference.exact_off == 0 && vs_filter.exact_off == 0;
    say!(
        "  active-set iterations: mean {:.2}, max {max_iters}, instances above 20: {slow}",
        iters as f64 / n
    );
    say!("  result: {}", if pass { "PASS" } else { "FAIL" });
    if pass { ExitCode::SUCCESS } else { ExitCode::FAILURE }
}
