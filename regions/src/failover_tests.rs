use super::*;

fn owner(epoch: u64, incarnation: &str) -> OwnerToken {
    OwnerToken { epoch, incarnation: incarnation.into() }
}

fn tokens(samples: &[(&str, bool)]) -> Tokens {
    let mut tokens = Tokens::default();
    for (suffix, alive) in samples {
        assert!(tokens.apply(suffix, *alive), "{suffix}");
    }
    tokens
}

#[test]
fn tokens_follow_puts_and_deletes_and_remember_the_highest_epoch() {
    let t =
        tokens(&[("owner/3/aa", true), ("standby/bb", true), ("standby/cc", true), ("owner/3/aa", false)]);
    assert!(t.owners.is_empty() && t.seen_owner && t.max_epoch == 3);
    assert_eq!(t.standbys.iter().collect::<Vec<_>>(), ["bb", "cc"]);
    let mut t = Tokens::default();
    for bad in ["owner/x/aa", "owner/1", "standby", "mirror", "owner/1/aa/b"] {
        assert!(!t.apply(bad, true), "{bad}");
    }
    assert_eq!(t, Tokens::default());
}

#[test]
fn a_standby_takes_over_only_what_it_saw_owned_and_only_as_the_first_standby() {
    // Never saw an owner (started first): waits, it has nothing to fly on.
    assert_eq!(decide(&tokens(&[("standby/bb", true)]), "bb", None), Decision::Stay);
    // The owner is alive: waits.
    let alive = tokens(&[("owner/4/aa", true), ("standby/bb", true)]);
    assert_eq!(decide(&alive, "bb", None), Decision::Stay);
    // The owner is gone: the first standby takes over with the next epoch; the others wait.
    let gone =
        tokens(&[("owner/4/aa", true), ("standby/bb", true), ("standby/cc", true), ("owner/4/aa", false)]);
    assert_eq!(decide(&gone, "bb", None), Decision::TakeOver(5));
    assert_eq!(decide(&gone, "cc", None), Decision::Stay);
    // Its own standby token not seen yet: still first when it sorts first.
    let early = tokens(&[("owner/1/aa", true), ("standby/cc", true), ("owner/1/aa", false)]);
    assert_eq!(decide(&early, "bb", None), Decision::TakeOver(2));
}

#[test]
fn of_two_owners_only_the_higher_one_stays() {
    let both = tokens(&[("owner/1/aa", true), ("owner/2/bb", true)]);
    assert_eq!(decide(&both, "aa", Some(&owner(1, "aa"))), Decision::GiveWay);
    assert_eq!(decide(&both, "bb", Some(&owner(2, "bb"))), Decision::Stay);
    // Same epoch (two servers started at once): the later incarnation stays.
    let tie = tokens(&[("owner/1/aa", true), ("owner/1/ab", true)]);
    assert_eq!(decide(&tie, "aa", Some(&owner(1, "aa"))), Decision::GiveWay);
    assert_eq!(decide(&tie, "ab", Some(&owner(1, "ab"))), Decision::Stay);
    // Alone (its own token seen or not): stays.
    assert_eq!(decide(&Tokens::default(), "aa", Some(&owner(1, "aa"))), Decision::Stay);
}

#[test]
fn the_flags_are_taken_once_and_the_role_switches_at_once() {
    let f = Failover::new();
    assert!(!f.is_owner() && !f.take_takeover());
    f.became_owner(1, false);
    assert!(f.is_owner() && f.epoch() == 1 && !f.take_takeover());
    f.became_standby();
    assert!(!f.is_owner() && f.take_give_way() && !f.take_give_way());
    f.became_owner(2, true);
    assert!(f.is_owner() && f.take_takeover() && !f.take_takeover());
    let report = f.report(Instant::now());
    assert_eq!((report.role, report.takeovers), ("owner", 1));
    assert_eq!(report.given_way, 1);
}

fn mirror(epoch: u64, tick: u64) -> Mirror {
    Mirror { region: "west".into(), epoch, tick, road_version: 0, uavs: Vec::new() }
}

#[test]
fn only_a_newer_mirror_replaces_the_kept_one() {
    let f = Failover::new();
    let now = Instant::now();
    f.keep_mirror(mirror(1, 10), now);
    f.keep_mirror(mirror(1, 9), now);
    assert_eq!(f.mirror().unwrap().0.tick, 10);
    f.keep_mirror(mirror(2, 1), now);
    assert_eq!((f.mirror().unwrap().0.epoch, f.mirror().unwrap().0.tick), (2, 1));
    // A stale owner (lower epoch) never replaces the new one's mirror.
    f.keep_mirror(mirror(1, 99), now);
    assert_eq!(f.mirror().unwrap().0.epoch, 2);
}

#[test]
fn releases_from_this_region_are_remembered_for_a_while() {
    let f = Failover::new();
    let now = Instant::now();
    let record =
        UavRecord { p: [0.0; 2], v: [0.0; 2], goal: None, policy: "pd".into(), link: None, airborne: true };
    let release = |from: &str, id: &str| Message::Release {
        from: from.into(),
        to: "east".into(),
        id: id.into(),
        seq: 1,
        uav: record.clone(),
    };
    f.saw_handover("west", &release("west", "u1"), now);
    f.saw_handover("west", &release("south", "u2"), now);
    assert!(f.released_away("u1", now) && !f.released_away("u2", now));
    assert!(!f.released_away("u1", now + RELEASE_MEMORY));
}

#[test]
fn a_mirror_round_trips_through_json_and_refuses_unknown_fields() {
    let record = UavRecord {
        p: [1.0, 2.0],
        v: [0.5, 0.0],
        goal: Some([9.0, 0.0]),
        policy: "rl".into(),
        link: None,
        airborne: true,
    };
    let m = Mirror { uavs: vec![MirrorUav { id: "u1".into(), uav: record.clone() }], ..mirror(3, 7) };
    let json = serde_json::to_string(&m).unwrap();
    assert_eq!(serde_json::from_str::<Mirror>(&json).unwrap(), m);
    let extra = json.replacen('{', r#"{"x":1,"#, 1);
    assert!(serde_json::from_str::<Mirror>(&extra).is_err());
}

#[test]
fn a_mirror_lists_the_uavs_whose_links_are_closing_after_the_fleet() {
    let snapshot = engine::snapshot::Snapshot::of(
        &fleet::Fleet::new(
            fleet::FleetConfig::default(),
            roads::Road::new(roads::RoadLayout::straight(0.0, 20.0, 4.0, 2)).unwrap(), // valid
            policies::PolicyRegistry::with_pd(1.0),
        ),
        4,
        0.2,
        0,
    );
    let leaving = UavRecord {
        p: [3.0, 0.0],
        v: [1.0, 0.0],
        goal: None,
        policy: "pd".into(),
        link: Some("udp://127.0.0.1:19850".into()),
        airborne: true,
    };
    let m = Mirror::of("west", 2, &snapshot, &[MirrorUav { id: "cf1".into(), uav: leaving.clone() }]);
    assert_eq!((m.epoch, m.tick, m.uavs.len()), (2, 4, 1));
    assert_eq!((m.uavs[0].id.as_str(), &m.uavs[0].uav), ("cf1", &leaving));
}
