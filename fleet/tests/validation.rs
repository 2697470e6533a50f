//! Scenario validation and the fleet's checks of new UAVs: one id rule for both, strict links,
//! the dt bound, and the reported field for the first offending UAV in file order.

use fleet::{Edit, EditError, Fleet, FleetConfig, Scenario, ScenarioError, ScenarioUav};
use links::{LinkRules, SimLink};
use policies::PolicyRegistry;
use proptest::prelude::*;
use roads::{Road, RoadLayout};
use uav::{UAV_ID_RULE, UavState, Vec2};

/// Ids refused by both paths, with the detail of the message.
const BAD_IDS: [(&str, &str); 8] = [
    ("a/b", "(got '/' at character 1)"),
    ("a b", "(got ' ' at character 1)"),
    ("a\tb", "(got '\\t' at character 1)"),
    ("a\u{1b}[31m", "(got '\\u{1b}' at character 1)"),
    ("evil\u{202e}gpj.exe", "(got '\\u{202e}' at character 4)"),
    ("", "(got an empty id)"),
    ("ünïcödé", "(got 'ü' at character 0)"),
    ("Ωuav", "(got 'Ω' at character 0)"),
];

fn uav(id: &str, start: [f64; 2]) -> ScenarioUav {
    ScenarioUav { id: id.into(), start, goal: [20.0, 0.0], link: None }
}

fn scenario(uavs: Vec<ScenarioUav>) -> Scenario {
    Scenario::on_road("t".into(), Default::default(), RoadLayout::straight(0.0, 30.0, 4.0, 3).segments, uavs)
}

fn invalid(s: &Scenario) -> (String, String) {
    match s.validate() {
        Err(ScenarioError::Invalid { field, reason }) => (field, reason),
        other => panic!("expected a field error, got {other:?}"),
    }
}

#[test]
fn scenario_ids_follow_the_api_rule() {
    let too_long = "x".repeat(65);
    let mut cases: Vec<(&str, String)> = BAD_IDS.iter().map(|(id, d)| (*id, d.to_string())).collect();
    cases.push((&too_long, "(got 65 characters)".into()));
    for (id, detail) in cases {
        let s = scenario(vec![uav("ok", [1.0, 0.0]), uav(id, [2.0, 0.0])]);
        assert_eq!(invalid(&s), ("uavs[1].id".into(), format!("{UAV_ID_RULE} {detail}")), "{id:?}");
    }
    let fine = scenario(vec![uav(&"x".repeat(64), [1.0, 0.0]), uav("cf_1-b.2", [2.0, 0.0])]);
    assert!(fine.validate().is_ok());
}

#[test]
fn the_fleet_refuses_the_same_ids() {
    let road = Road::new(RoadLayout::straight(0.0, 30.0, 4.0, 3)).unwrap();
    let mut fleet = Fleet::new(FleetConfig::default(), road, PolicyRegistry::with_pd(5.0));
    let state = UavState::at_rest(Vec2::new(5.0, 0.0));
    let too_long = "x".repeat(65);
    let mut cases: Vec<(&str, String)> = BAD_IDS.iter().map(|(id, d)| (*id, d.to_string())).collect();
    cases.push((&too_long, "(got 65 characters)".into()));
    for (id, detail) in cases {
        let reason = format!("{UAV_ID_RULE} {detail}");
        assert_eq!(
            fleet.check_new(id, "pd", &state, None),
            Err(EditError::InvalidId(reason.clone())),
            "{id:?}"
        );
        let link = Box::new(SimLink::new(state, 0.05));
        let refused = fleet.apply(Edit::Add { id: id.into(), policy: "pd".into(), link, state, goal: None });
        let refused = refused.err().expect("refused");
        assert_eq!(refused, EditError::InvalidId(reason.clone()));
        assert_eq!(refused.to_string(), format!("id: {reason}"));
    }
    assert_eq!(fleet.uavs().len(), 0);
    let link = Box::new(SimLink::new(state, 0.05));
    let add = Edit::Add { id: "uav-1.a_B".into(), policy: "pd".into(), link, state, goal: None };
    assert!(fleet.apply(add).is_ok());
}

#[test]
fn duplicate_ids_name_the_first_holder() {
    let s = scenario(vec![
        uav("a", [1.0, 0.0]),
        uav("b", [2.0, 0.0]),
        uav("a", [3.0, 0.0]),
        uav("b", [4.0, 0.0]),
    ]);
    assert_eq!(invalid(&s), ("uavs[2].id".into(), "duplicate id `a` (also uavs[0])".into()));
}

#[test]
fn start_separation_names_the_lowest_earlier_uav() {
    // uavs[3] is closer than D_c = 0.3 m to uavs[1] and uavs[2]; uavs[1] comes first in the file.
    let s = scenario(vec![
        uav("a", [1.0, 0.0]),
        uav("b", [5.0, 0.0]),
        uav("c", [5.5, 0.0]),
        uav("d", [5.25, 0.05]),
    ]);
    assert_eq!(invalid(&s), ("uavs[3].start".into(), "closer than D_c = 0.3 m to uavs[1].start".into()));
    // Just under and just over D_c, across cell borders on both axes.
    for (dx, dy, close) in [
        (0.2999, 0.0, true),
        (0.3001, 0.0, false),
        (0.0, 0.3001, false),
        (0.0, -0.2999, true),
        (0.212, 0.212, true),
    ] {
        let s = scenario(vec![uav("a", [6.0, 0.0]), uav("b", [6.0 + dx, dy])]);
        assert_eq!(s.validate().is_err(), close, "({dx}, {dy})");
    }
}

#[test]
fn links_are_checked_strictly_and_against_the_rules() {
    let mut s = scenario(vec![uav("a", [1.0, 0.0]), uav("b", [2.0, 0.0])]);
    s.uavs[1].link = Some("udp://127.0.0.1:99999".into());
    assert_eq!(
        invalid(&s),
        ("uavs[1].link".into(), "udp://127.0.0.1:99999: port 99999 is not in 1..=65535".into())
    );
    s.uavs[1].link = Some("udp://192.168.1.7:19850".into());
    assert_eq!(invalid(&s).0, "uavs[1].link");
    let rules = LinkRules { udp_hosts: vec!["192.168.1.7".parse().unwrap()] };
    assert!(s.validate_with(&rules).is_ok());
    s.uavs[0].link = Some("radio://0/80/2M/E7E7E7E7E1".into());
    assert!(s.validate_with(&rules).is_ok());
}

#[test]
fn dt_above_a_tenth_of_a_second_is_refused() {
    let mut s = scenario(vec![uav("a", [1.0, 0.0])]);
    s.params.dt = 1.0;
    assert_eq!(invalid(&s), ("params.dt".into(), "is outside its valid range 0.001..=0.1 (got 1)".into()));
    s.params.dt = 0.1;
    assert!(s.validate().is_ok());
}

/// The first clash in file order as the quadratic search found it (before the grid and the map):
/// a duplicate id names the first holder, a start closer than D_c the first earlier UAV.
fn first_clash(uavs: &[ScenarioUav], d_c: f64) -> Option<(String, String)> {
    for (i, u) in uavs.iter().enumerate() {
        if let Some(j) = uavs[..i].iter().position(|o| o.id == u.id) {
            return Some((format!("uavs[{i}].id"), format!("duplicate id `{}` (also uavs[{j}])", u.id)));
        }
        let start = Vec2::new(u.start[0], u.start[1]);
        if let Some(j) =
            uavs[..i].iter().position(|o| (Vec2::new(o.start[0], o.start[1]) - start).norm() < d_c)
        {
            return Some((
                format!("uavs[{i}].start"),
                format!("closer than D_c = {d_c} m to uavs[{j}].start"),
            ));
        }
    }
    None
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(2000))]

    /// Ids from a small set and starts on a 5 cm lattice (many exact D_c distances): the hash map and
    /// the grid report the same first clash as the quadratic search, or none.
    #[test]
    fn the_first_clash_is_the_one_the_quadratic_search_finds(
        cells in proptest::collection::vec((0u32..40, 0u32..20, 0u32..80), 1..60),
        d_c in prop_oneof![Just(0.3), Just(0.25), 0.05f64..1.0],
        spread in 1u32..20,
    ) {
        let uavs: Vec<ScenarioUav> = cells
            .iter()
            .map(|&(x, y, id)| uav(&format!("u{id}"), [2.0 + f64::from(x * spread) * 0.05 % 26.0, -1.5 + f64::from(y) * 0.15]))
            .collect();
        let mut s = scenario(uavs);
        s.params.d_c = d_c;
        let got = match s.validate() {
            Ok(_) => None,
            Err(ScenarioError::Invalid { field, reason }) => Some((field, reason)),
            Err(e) => return Err(TestCaseError::fail(format!("{e}"))),
        };
        prop_assert_eq!(got, first_clash(&s.uavs, d_c));
    }
}
