//! Feasible filter problems that once broke the exact-penalty promise of docs/safety.md §6 (slack 0
//! whenever the hard problem is feasible), found by `properties.rs`'s generator: slivers whose hard
//! multipliers exceeded ρ (urgency weights used to lower ρ for rows with b > 1; ρ = 10³ was below a
//! sliver's 2.1·10³) and a single-point feasible set on which the cached solver stops at `AlmostSolved`
//! (a freshly built solver solves it). Each must now be solved exactly.

mod common;

use common::hard_qp;
use safety::{FilterSettings, Row, RowKind, SafetyFilter};
use uav::Vec2;

/// (a.x, a.y, c, b, is_road) of each row.
type RawRow = (f64, f64, f64, f64, bool);

fn rows(raw: &[RawRow]) -> Vec<Row> {
    raw.iter()
        .map(|&(x, y, c, b, road)| Row {
            a: Vec2::new(x, y),
            c,
            b,
            kind: if road { RowKind::Road(0) } else { RowKind::Collision(0) },
        })
        .collect()
}

/// Checks that the hard problem (no slack) is feasible, then asserts the exact-penalty outcome.
fn assert_exact(settings: FilterSettings, delta: f64, u_ref: Vec2, raw: &[RawRow]) {
    let rows = rows(raw);
    let plain: Vec<(Vec2, f64)> = rows.iter().map(|r| (r.a, r.c)).collect();
    let hard = hard_qp(u_ref, &plain, delta).expect("the hard problem is feasible");
    let out = SafetyFilter::new(settings).filter(u_ref, Vec2::zeros(), &rows, delta, 0.05);
    let worst = rows.iter().map(|r| r.a.dot(&out.u) - r.c).fold(f64::NEG_INFINITY, f64::max);
    assert!(
        !out.failed && out.max_slack <= 1e-6 && worst <= 1e-6,
        "feasible problem (hard optimum {:?}, multipliers {:?}) filtered to {:?}, worst row violation {worst:e}",
        hard.u,
        hard.multipliers,
        out
    );
}

/// Two nearly antiparallel collision rows leave a thin feasible wedge (a UAV squeezed between two
/// neighbours). Their hard multipliers (~170) exceeded the ρ the urgency weights once gave rows with
/// b ≈ 7–8 (1000/b ≈ 120–137), and the filter relaxed a row by 0.073 m/s² instead of satisfying it.
#[test]
fn sliver_with_urgency_weights() {
    let raw = [
        (-0.12417731287615752, -0.9922600440241746, 0.6635346652746315, 7.316657743152145, false),
        (0.0862858197169667, 0.9962704237885269, -0.760843328639643, 8.34533270482461, false),
        (0.9848446234778062, -0.17343894489663525, 2.596790358684089, 7.346309953309053, true),
    ];
    let u_ref = Vec2::new(-4.011158412575481, -0.4756986046250651);
    assert_exact(FilterSettings::default(), 6.479327543547886, u_ref, &raw);
}

/// With fixed weights: a thinner strip needs ρ ≈ 2.1·10³ on its collision row, more than the design's
/// reference 10³ of docs/safety.md §6 ("multipliers ≤ ~2δ" is not a bound); the default ρ is 10⁴.
#[test]
fn sliver_with_reference_weights() {
    let raw = [
        (0.7230295198542178, -0.6908171345728037, -3.163393909389022, 0.22156258534029893, false),
        (-0.7243778672818814, 0.6894031515681902, 3.1552231410192513, 1.0060440186493995, true),
        (0.1538912991911644, 0.9880877835664479, 6.690766916982405, 9.401177031883067, false),
        (-0.9737192638189993, 0.22775160870515473, 1.454949539429121, 8.10061822147707, true),
    ];
    let settings = FilterSettings { urgency_floor: 0.0, ..FilterSettings::default() };
    assert_exact(settings, 5.24118457453147, Vec2::new(-5.137826399247698, 4.982991212414345), &raw);
}

/// Rows through one point of the circle ‖u‖ = δ (δ = 5.192592820227619) and the nominal input.
const SINGLE_POINT: [RawRow; 7] = [
    (-0.7972584726557864, -0.6036380768130541, -3.991510732232178, 3.5382717614157677, false),
    (-0.6685216121249546, 0.7436927148505972, -3.5582775558550295, -0.5040158068398558, true),
    (0.769592604722542, -0.6385352165357625, 5.3669990224396225, -0.3375139616302869, false),
    (-0.6694436069357539, -0.7428628790919949, -3.387532493193229, 3.702475871659601, false),
    (-0.1629164635733987, -0.9866398663629691, -0.39530947497019897, 9.879456874825319, true),
    (-0.8736181497007118, -0.4866120924447979, -4.477711506987589, 4.834843299706169, true),
    (0.6558982408634472, 0.7548493211444489, 3.8329509635627046, 9.980569299373606, false),
];

fn single_point_u_ref() -> Vec2 {
    Vec2::new(-0.4132307737231538, -1.003271388973462)
}

/// Two rows through the same point of the circle ‖u‖ = δ make the feasible set that single point
/// (docs/safety.md §4.1: states close to it give badly conditioned QPs). The cached solver stopped at
/// `AlmostSolved` and the filter braked; the retry with a freshly built solver solves it.
/// (Shrinking δ by 1e-9 makes the problem infeasible.)
#[test]
fn single_point_feasible_set() {
    let raw = SINGLE_POINT;
    let u_ref = single_point_u_ref();
    assert_exact(FilterSettings::default(), 5.192592820227619, u_ref, &raw);
}

/// The same single-point problem with fixed weights.
#[test]
fn single_point_feasible_set_with_fixed_weights_is_solved() {
    let raw = SINGLE_POINT;
    let settings = FilterSettings { urgency_floor: 0.0, ..FilterSettings::default() };
    let u_ref = single_point_u_ref();
    assert_exact(settings, 5.192592820227619, u_ref, &raw);
}
