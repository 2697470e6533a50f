use super::*;
use engine::snapshot::{UavSnapshot, UavStatus};
use proptest::prelude::*;

fn uav(id: &str, p: [f64; 2], v: [f64; 2]) -> UavSnapshot {
    UavSnapshot {
        id: id.into(),
        policy: "pd".into(),
        p,
        v,
        u_ref: [0.0; 2],
        u: [0.5, -0.25],
        target: [p[0] + 1.0, p[1]],
        goal: None,
        arrived: false,
        status: UavStatus::Waiting,
        link: "sim".into(),
        phase: links::LinkPhase::Flying,
        lost: true,
        link_error: None,
        firmware: None,
        wait_reason: None,
        active_rows: 0,
        slack: 0.0,
        min_barrier: None,
        collision_margin_m: None,
        road_margin_m: 1.0,
    }
}

fn snapshot(uavs: Vec<UavSnapshot>) -> Snapshot {
    Snapshot {
        tick: 7,
        time: 0.35,
        paused: false,
        road_version: 0,
        min_collision_margin_m: None,
        min_road_margin_m: None,
        d_c: 0.3,
        d_s: 0.1,
        uavs,
        reservations: Vec::new(),
    }
}

#[test]
fn a_payload_has_the_documented_layout() {
    let bytes =
        encode("west", &snapshot(vec![uav("a1", [1.5, -2.0], [0.25, 0.0])]), 0.01, &Unheard::default());
    assert_eq!(bytes.len(), HEADER_BYTES + 4 + 2 + 2 + RECORD_TAIL_BYTES);
    assert_eq!(&bytes[..8], &[1, 4, 4, 0, 1, 0, 0, 0]);
    assert_eq!(u64::from_le_bytes(bytes[8..16].try_into().unwrap()), 7);
    assert_eq!(&bytes[HEADER_BYTES..HEADER_BYTES + 4], b"west");
    let record = &bytes[HEADER_BYTES + 4..];
    assert_eq!(&record[..4], &[2, 0, b'a', b'1']);
    assert_eq!(f32::from_le_bytes(record[4..8].try_into().unwrap()), 1.5);
    // The binary stream's status code (12 waiting) and flags (2 lost).
    assert_eq!(&record[36..40], &[12, 2, 0, 0]);
    let decoded = decode(&bytes).unwrap();
    assert_eq!((decoded.region.as_str(), decoded.tick, decoded.time), ("west", 7, 0.35));
    assert_eq!(decoded.uavs[0].p, [1.5, -2.0]);
    assert_eq!(decoded.uavs[0].u, [0.5, -0.25]);
}

#[test]
fn silent_uavs_carry_their_unheard_time_and_ghosts_follow_the_fleet() {
    let uavs = vec![uav("a", [0.0, 0.0], [0.0, 0.0]), uav("b", [1.0, 0.0], [0.0, 0.0])];
    let ghost = UavState { p: uav::Vec2::new(5.0, 1.0), v: uav::Vec2::new(1.0, 0.0) };
    let unheard = Unheard { silent: vec![(1, 350)], ghosts: vec![("g".into(), ghost, 120)] };
    let decoded = decode(&encode("west", &snapshot(uavs), 0.01, &unheard)).unwrap();
    let seen: Vec<(&str, u16, bool)> =
        decoded.uavs.iter().map(|u| (u.id.as_str(), u.unheard_ms, u.ghost())).collect();
    assert_eq!(seen, [("a", 0, false), ("b", 350, false), ("g", 120, true)]);
    assert_eq!((decoded.uavs[2].p, decoded.uavs[2].v), ([5.0, 1.0], [1.0, 0.0]));
    assert_eq!((saturating_ms(0.25), saturating_ms(1e9), saturating_ms(f64::NAN)), (250, u16::MAX, 0));
}

#[test]
fn bad_payloads_are_refused_with_their_reason() {
    let good = encode("west", &snapshot(vec![uav("a", [0.0, 0.0], [0.0, 0.0])]), 0.0, &Unheard::default());
    assert_eq!(decode(&good[..10]), Err(WireError::Truncated("header")));
    // Fewer bytes than the count's smallest records, or a record cut short.
    assert_eq!(decode(&good[..good.len() - 1]), Err(WireError::Truncated("records")));
    let long_id =
        encode("west", &snapshot(vec![uav("abcdef", [0.0, 0.0], [0.0, 0.0])]), 0.0, &Unheard::default());
    assert_eq!(decode(&long_id[..long_id.len() - 1]), Err(WireError::Truncated("record")));
    let mut bad = good.clone();
    bad[0] = 2;
    assert_eq!(decode(&bad), Err(WireError::Version(2)));
    let mut bad = good.clone();
    bad[1] = 1;
    assert_eq!(decode(&bad), Err(WireError::Kind(1)));
    let mut bad = good.clone();
    bad.push(0);
    assert_eq!(decode(&bad), Err(WireError::Trailing(1)));
    let mut bad = good.clone();
    bad[4..8].copy_from_slice(&u32::MAX.to_le_bytes());
    assert_eq!(decode(&bad), Err(WireError::Truncated("records")));
    let mut bad = good.clone();
    bad[HEADER_BYTES] = 0xff;
    assert_eq!(decode(&bad), Err(WireError::Name("region name")));
    let mut bad = good.clone();
    bad[24..28].copy_from_slice(&(-1.0f32).to_le_bytes());
    assert_eq!(decode(&bad), Err(WireError::Age));
    for p in [[f64::NAN, 0.0], [0.0, f64::INFINITY]] {
        let bytes = encode("west", &snapshot(vec![uav("a", p, [0.0, 0.0])]), 0.0, &Unheard::default());
        assert_eq!(decode(&bytes), Err(WireError::NotFinite("a".into())));
    }
    let bytes = encode(
        "west",
        &snapshot(vec![uav("a", [0.0, 0.0], [f64::NEG_INFINITY, 0.0])]),
        0.0,
        &Unheard::default(),
    );
    assert_eq!(decode(&bytes), Err(WireError::NotFinite("a".into())));
    // An f64 beyond f32's range is not finite once sent.
    let bytes = encode("west", &snapshot(vec![uav("a", [1e300, 0.0], [0.0, 0.0])]), 0.0, &Unheard::default());
    assert_eq!(decode(&bytes), Err(WireError::NotFinite("a".into())));
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(2000))]

    /// Every snapshot with finite states comes back as sent (to f32 precision).
    #[test]
    fn round_trip(
        region in "[A-Za-z0-9_-]{1,64}",
        tick in any::<u64>(),
        age in 0.0f32..10.0,
        uavs in proptest::collection::vec(("[a-z0-9.-]{1,20}", [-1e4f64..1e4, -1e4f64..1e4, -5f64..5.0, -5f64..5.0]), 0..40),
    ) {
        let list: Vec<UavSnapshot> = uavs.iter().map(|(id, x)| uav(id, [x[0], x[1]], [x[2], x[3]])).collect();
        let mut snap = snapshot(list);
        snap.tick = tick;
        let decoded = decode(&encode(&region, &snap, age, &Unheard::default())).unwrap();
        prop_assert_eq!(&decoded.region, &region);
        prop_assert_eq!(decoded.tick, tick);
        prop_assert_eq!(decoded.age_at_send_s, age);
        prop_assert_eq!(decoded.uavs.len(), uavs.len());
        for (d, (id, x)) in decoded.uavs.iter().zip(&uavs) {
            prop_assert_eq!(&d.id, id);
            prop_assert_eq!(d.p, [x[0] as f32, x[1] as f32]);
            prop_assert_eq!(d.v, [x[2] as f32, x[3] as f32]);
        }
    }

    /// Random bytes, and random changes to a valid payload, are decoded or refused, never a panic.
    #[test]
    fn random_bytes_never_panic(
        noise in proptest::collection::vec(any::<u8>(), 0..400),
        flips in proptest::collection::vec((any::<usize>(), any::<u8>()), 0..8),
        cut in any::<usize>(),
    ) {
        let _ = decode(&noise);
        let mut valid = noise.clone();
        valid.splice(0..0, [WIRE_VERSION, KIND_REGION_STATES]);
        let _ = decode(&valid);
        let mut bytes = encode("east", &snapshot(vec![uav("a", [1.0, 2.0], [0.0, 0.0]), uav("b", [3.0, 4.0], [1.0, 0.0])]), 0.02, &Unheard::default());
        for (at, value) in flips {
            let at = at % bytes.len();
            bytes[at] = value;
        }
        bytes.truncate(cut % (bytes.len() + 1));
        if let Ok(states) = decode(&bytes) {
            prop_assert!(states.uavs.iter().all(|u| u.p.iter().chain(&u.v).all(|x| x.is_finite())));
        }
    }
}
