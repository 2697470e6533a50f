//! The handover protocol between two regions' loops, messages carried by hand (as Zenoh would, in
//! any order the tests choose): one owner at every step, refusals, stale answers and timeouts; on a
//! network, in `network`.

use super::*;
use fleet::{Fleet, FleetConfig};
use links::SimLink;
use policies::PolicyRegistry;
use roads::{Region, Road, RoadLayout};
use std::sync::mpsc::{SyncSender, sync_channel};
use uav::Vec2;

/// One region's loop side: its fleet, its protocol, the ends the test carries messages through.
struct Side {
    fleet: Fleet,
    handover: Handover,
    inbox: SyncSender<Message>,
    outbox: tokio::sync::mpsc::Receiver<Message>,
    /// The UAVs other regions list, by id (what the neighbours' state messages say).
    listed: std::collections::HashMap<String, String>,
    screen: Arc<super::super::screen::Screen>,
}

/// A straight road x ∈ [0, 40] of 8 segments: `west` 0–3, `east` 4–7.
fn road() -> Road {
    let mut layout = RoadLayout::straight(0.0, 40.0, 4.0, 8);
    let region = |name: &str, first, last| Region { name: name.into(), segments: [first, last] };
    layout.regions = Some(vec![region("west", 0, 3), region("east", 4, 7)]);
    Road::new(layout).unwrap() // a valid layout: two regions covering the eight segments
}

fn side(name: &str) -> Side {
    side_on(name, road().into())
}

/// Region `name`'s side, its fleet flying `space`.
fn side_on(name: &str, space: roads::Airspace) -> Side {
    let config = FleetConfig::default();
    let fleet = Fleet::new(config, space, PolicyRegistry::with_pd(config.params.delta));
    let (inbox, inbox_rx) = sync_channel(256);
    let (outbox_tx, outbox) = tokio::sync::mpsc::channel(256);
    let screen = Arc::new(super::super::screen::Screen::default());
    let handover =
        Handover::new(name, inbox_rx, outbox_tx, Arc::new(OwnershipLog::default()), screen.clone());
    Side { fleet, handover, inbox, outbox, listed: Default::default(), screen }
}

impl Side {
    fn add(&mut self, id: &str, x: f64) {
        let state = UavState { p: Vec2::new(x, 0.0), v: Vec2::new(1.0, 0.0) };
        let link = Box::new(SimLink::new(state, self.fleet.config.params.dt));
        self.fleet.add(id.into(), "pd".into(), link, state, Some(Vec2::new(35.0, 0.0)));
        self.fleet.tick(); // tracks its segment
    }

    /// The next message it sent, if any.
    fn sent(&mut self) -> Option<Message> {
        self.outbox.try_recv().ok()
    }

    /// One gap: receives, applies the changes as the engine does, offers.
    fn gap(&mut self, now: Instant) {
        self.handover.expire(now);
        let listed = self.listed.clone();
        let commanded_elsewhere = move || listed.clone();
        let rules = links::LinkRules::default();
        for change in self.handover.receive(&self.fleet, 100, &rules, now, &commanded_elsewhere) {
            match change {
                FleetChange::Release { id, to, seq } => {
                    let uav = self.fleet.remove(&id).unwrap(); // receive() checked it is here
                    let rec = record(&uav);
                    self.handover.released(id, to, seq, rec, now);
                }
                FleetChange::Adopt { id, uav } => {
                    let (state, dt) = (uav.state(), self.fleet.config.params.dt);
                    self.fleet.add(id.clone(), uav.policy, Box::new(SimLink::new(state, dt)), state, None);
                    self.handover.adopted(&id, now);
                }
            }
        }
        self.handover.offer(&self.fleet, 0, now);
    }

    fn owns(&self, id: &str) -> bool {
        self.fleet.uav(id).is_some()
    }
}

#[test]
fn a_uav_in_the_neighbours_segment_is_offered_accepted_released_and_adopted_with_one_owner_throughout() {
    let (mut west, mut east) = (side("west"), side("east"));
    west.add("u", 10.0); // segment 2: west's own
    let t0 = Instant::now();
    west.gap(t0);
    assert!(west.sent().is_none(), "a UAV in its own region is not offered");
    west.fleet.remove("u").unwrap();
    west.add("u", 21.0); // segment 4: east's
    west.gap(t0);
    let offer = west.sent().expect("an offer");
    assert!(matches!(&offer, Message::Offer { to, id, .. } if to == "east" && id == "u"), "{offer:?}");
    west.gap(t0);
    assert!(west.sent().is_none(), "one offer at a time");
    east.inbox.send(offer).unwrap();
    east.gap(t0);
    let accept = east.sent().expect("an accept");
    assert!(matches!(accept, Message::Accept { .. }), "{accept:?}");
    assert!(west.owns("u") && !east.owns("u"), "accepting does not take it");
    west.inbox.send(accept).unwrap();
    west.gap(t0);
    assert!(!west.owns("u") && !east.owns("u"), "released, not adopted yet");
    let release = west.sent().expect("a release");
    let Message::Release { uav, .. } = &release else { panic!("{release:?}") };
    assert_eq!(uav.p, [21.0, 0.0]);
    assert_eq!(uav.goal, Some([35.0, 0.0]));
    // Meanwhile west's fleet sees the UAV as a ghost, and east leaves west's stale listing of it out.
    let mut foreign = Vec::new();
    west.handover.adjust_foreign(&mut foreign, t0);
    assert_eq!(foreign.iter().map(|f| f.id.as_str()).collect::<Vec<_>>(), ["u"]);
    east.inbox.send(release).unwrap();
    east.gap(t0);
    assert!(east.owns("u") && !west.owns("u"));
    let mut stale = vec![ForeignUav { id: "u".into(), state: UavState::at_rest(Vec2::zeros()), age_s: 0.0 }];
    east.handover.adjust_foreign(&mut stale, t0);
    assert!(stale.is_empty(), "an adopted UAV is never its own neighbour");
    // Once east lists it, west's ghost goes.
    let mut listed = vec![ForeignUav { id: "u".into(), state: UavState::at_rest(Vec2::zeros()), age_s: 0.0 }];
    west.handover.adjust_foreign(&mut listed, t0);
    assert_eq!(listed.len(), 1);
    assert_eq!((west.handover.counts.released, east.handover.counts.adopted), (1, 1));
}

#[test]
fn refusals_stale_answers_and_silence_leave_the_owner_flying_it() {
    let (mut west, mut east) = (side("west"), side("east"));
    west.add("u", 21.0);
    east.add("u", 30.0); // east flies a UAV of the same id: it must refuse
    let t0 = Instant::now();
    west.gap(t0);
    east.inbox.send(west.sent().unwrap()).unwrap();
    east.gap(t0);
    let refuse = east.sent().unwrap();
    assert!(matches!(&refuse, Message::Refuse { reason, .. } if reason.contains("flown here")), "{refuse:?}");
    west.inbox.send(refuse).unwrap();
    west.gap(t0);
    assert!(west.owns("u") && west.sent().is_none(), "kept, and not offered again at once");
    west.gap(t0 + RETRY_AFTER);
    let offer = west.sent().expect("offered again after the pause");
    let Message::Offer { seq, .. } = offer else { panic!("{offer:?}") };
    // An accept for another offer, or from another region, releases nothing.
    for stale in [
        Message::Accept { from: "east".into(), to: "west".into(), id: "u".into(), seq: seq + 7 },
        Message::Accept { from: "north".into(), to: "west".into(), id: "u".into(), seq },
        Message::Accept { from: "east".into(), to: "elsewhere".into(), id: "u".into(), seq },
    ] {
        west.inbox.send(stale).unwrap();
    }
    west.gap(t0 + RETRY_AFTER);
    assert!(west.owns("u") && west.sent().is_none());
    assert_eq!(west.handover.counts.dropped, 1, "the message for another region");
    // Unanswered, the offer lapses and is made again.
    west.gap(t0 + RETRY_AFTER + OFFER_TIMEOUT);
    assert!(west.sent().is_none(), "lapsed, waiting before the next");
    west.gap(t0 + 2 * RETRY_AFTER + OFFER_TIMEOUT);
    assert!(matches!(west.sent(), Some(Message::Offer { seq: s, .. }) if s > seq));
    assert!(west.owns("u"));
}

#[test]
fn offers_of_unknown_policies_and_bad_states_are_refused_and_releases_of_owned_uavs_ignored() {
    let mut east = side("east");
    east.add("mine", 30.0);
    let record = |policy: &str, p: [f64; 2]| UavRecord {
        p,
        v: [0.0, 0.0],
        goal: None,
        policy: policy.into(),
        link: None,
        airborne: true,
    };
    let offer =
        |id: &str, uav| Message::Offer { from: "west".into(), to: "east".into(), id: id.into(), seq: 1, uav };
    east.inbox.send(offer("a", record("nope", [21.0, 0.0]))).unwrap();
    east.inbox.send(offer("b", record("pd", [f64::NAN, 0.0]))).unwrap();
    east.inbox.send(offer("bad id!", record("pd", [21.0, 0.0]))).unwrap();
    let t0 = Instant::now();
    east.gap(t0);
    let reasons: Vec<String> = std::iter::from_fn(|| east.sent())
        .map(|m| match m {
            Message::Refuse { reason, .. } => reason,
            other => panic!("{other:?}"),
        })
        .collect();
    assert_eq!(reasons.len(), 3, "{reasons:?}");
    assert!(
        reasons[0].contains("policy `nope`") && reasons[1].contains("finite") && reasons[2].starts_with("id")
    );
    // A release of a UAV east flies already changes nothing.
    let release = Message::Release {
        from: "west".into(),
        to: "east".into(),
        id: "mine".into(),
        seq: 1,
        uav: record("pd", [21.0, 0.0]),
    };
    east.inbox.send(release).unwrap();
    east.gap(t0);
    assert_eq!(east.fleet.uavs().len(), 1);
    assert_eq!(east.fleet.uav("mine").unwrap().state.p, Vec2::new(30.0, 0.0));
}

#[test]
fn a_crazyflie_is_accepted_only_on_a_link_this_server_may_open() {
    let mut east = side("east");
    let record = |link: &str| UavRecord {
        p: [21.0, 0.0],
        v: [0.0, 0.0],
        goal: None,
        policy: "pd".into(),
        link: Some(link.into()),
        airborne: true,
    };
    let offer = |id: &str, link| Message::Offer {
        from: "west".into(),
        to: "east".into(),
        id: id.into(),
        seq: 1,
        uav: record(link),
    };
    // On loopback (the default rules) it is taken; another host needs `--allow-link-host`.
    east.inbox.send(offer("near", "udp://127.0.0.1:19850")).unwrap();
    east.inbox.send(offer("far", "udp://10.0.0.5:19850")).unwrap();
    east.inbox.send(offer("typo", "radio://0/80/2M/E7E7E7E7")).unwrap();
    east.gap(Instant::now());
    let answers: Vec<Message> = std::iter::from_fn(|| east.sent()).collect();
    assert!(matches!(&answers[0], Message::Accept { id, .. } if id == "near"), "{answers:?}");
    for (answer, id) in answers[1..].iter().zip(["far", "typo"]) {
        assert!(
            matches!(answer, Message::Refuse { id: i, reason, .. } if i == id && reason.starts_with("link: ")),
            "{answer:?}"
        );
    }
    assert_eq!(answers.len(), 3);
}

#[test]
fn messages_round_trip_as_json_and_unknown_fields_are_refused() {
    let m = Message::Release {
        from: "west".into(),
        to: "east".into(),
        id: "u".into(),
        seq: 3,
        uav: UavRecord {
            p: [1.0, 2.0],
            v: [0.5, 0.0],
            goal: Some([3.0, 0.0]),
            policy: "rl".into(),
            link: None,
            airborne: true,
        },
    };
    let text = serde_json::to_string(&m).unwrap();
    assert!(text.contains(r#""kind":"release""#), "{text}");
    assert_eq!(serde_json::from_str::<Message>(&text).unwrap(), m);
    let extra = text.replacen('{', r#"{"x":1,"#, 1);
    assert!(serde_json::from_str::<Message>(&extra).is_err());
}

/// A record of a UAV at `p`, hovering, flying `pd`.
fn hovering(p: [f64; 2]) -> UavRecord {
    UavRecord { p, v: [0.0, 0.0], goal: None, policy: "pd".into(), link: None, airborne: true }
}

#[test]
fn a_release_is_adopted_only_for_an_offer_accepted_from_its_sender() {
    let mut east = side("east");
    let release = |from: &str, id: &str, seq| Message::Release {
        from: from.into(),
        to: "east".into(),
        id: id.into(),
        seq,
        uav: hovering([21.0, 0.0]),
    };
    let t0 = Instant::now();
    // Unsolicited: nothing was offered.
    east.inbox.send(release("west", "u", 1)).unwrap();
    east.gap(t0);
    assert!(!east.owns("u"), "an unsolicited release is refused");
    // Offered by west and accepted: a release of another number or from another region is not it.
    let offer = Message::Offer {
        from: "west".into(),
        to: "east".into(),
        id: "u".into(),
        seq: 7,
        uav: hovering([21.0, 0.0]),
    };
    east.inbox.send(offer).unwrap();
    east.gap(t0);
    assert!(matches!(east.sent(), Some(Message::Accept { seq: 7, .. })));
    east.inbox.send(release("west", "u", 8)).unwrap();
    east.inbox.send(release("north", "u", 7)).unwrap();
    east.gap(t0);
    assert!(!east.owns("u"));
    east.inbox.send(release("west", "u", 7)).unwrap();
    east.gap(t0);
    assert!(east.owns("u"), "the release of the accepted offer is adopted");
    east.inbox.send(release("west", "u", 7)).unwrap();
    east.gap(t0);
    assert_eq!(east.fleet.uavs().len(), 1, "and only once");
    assert_eq!(serde_json::to_value(east.screen.report()).unwrap()["unrequested_release"], 4);
}

#[test]
fn offers_off_the_road_too_close_listed_elsewhere_or_too_many_are_refused_by_name() {
    let mut east = side("east");
    east.add("mine", 30.0);
    east.listed.insert("theirs".into(), "north".into());
    east.listed.insert("crossing".into(), "west".into());
    let offer = |id: &str, seq, p| Message::Offer {
        from: "west".into(),
        to: "east".into(),
        id: id.into(),
        seq,
        uav: hovering(p),
    };
    let t0 = Instant::now();
    for (k, (id, p)) in [
        ("off", [500.0, 500.0]),
        ("on-top", [30.062, 0.0]),
        ("theirs", [22.0, 0.0]),
        ("deep-west", [2.0, 0.0]),
        ("crossing", [21.0, 0.0]),
    ]
    .into_iter()
    .enumerate()
    {
        east.inbox.send(offer(id, k as u64, p)).unwrap();
    }
    east.gap(t0);
    let answers: Vec<Message> = std::iter::from_fn(|| east.sent()).collect();
    let refused = |id: &str, why: &str| {
        answers
            .iter()
            .any(|m| matches!(m, Message::Refuse { id: i, reason, .. } if i == id && reason.contains(why)))
    };
    assert!(refused("off", "outside the road"), "{answers:?}");
    assert!(refused("on-top", "D_c"), "{answers:?}");
    assert!(refused("theirs", "flown by region `north`"), "{answers:?}");
    assert!(refused("deep-west", "not in or next to region `east`"), "{answers:?}");
    assert!(matches!(answers.last(), Some(Message::Accept { id, .. }) if id == "crossing"), "{answers:?}");
    // One sender's offers are read at most so many per gap, and it may have only so many waiting.
    for k in 0..MAX_RESERVATIONS_PER_SENDER {
        let x = 20.5 + 0.01 * k as f64;
        east.inbox.send(offer(&format!("n{k}"), 100 + k as u64, [x, 1.5 - 0.04 * k as f64])).unwrap();
    }
    east.gap(t0);
    let first: Vec<Message> = std::iter::from_fn(|| east.sent()).collect();
    assert_eq!(first.len(), MAX_OFFERS_PER_SENDER_PER_GAP, "the rest wait for their sender to offer again");
    assert_eq!(
        serde_json::to_value(east.screen.report()).unwrap()["too_many_offers"],
        (MAX_RESERVATIONS_PER_SENDER - MAX_OFFERS_PER_SENDER_PER_GAP) as u64
    );
    for k in MAX_OFFERS_PER_SENDER_PER_GAP..MAX_RESERVATIONS_PER_SENDER {
        let x = 20.5 + 0.01 * k as f64;
        east.inbox.send(offer(&format!("n{k}"), 100 + k as u64, [x, 1.5 - 0.04 * k as f64])).unwrap();
    }
    east.gap(t0);
    let answers: Vec<Message> = std::iter::from_fn(|| east.sent()).collect();
    assert!(
        matches!(answers.last(), Some(Message::Refuse { reason, .. }) if reason.contains("not released")),
        "{answers:?}"
    );
    let report = serde_json::to_value(east.screen.report()).unwrap();
    assert_eq!(
        report["too_many_offers"],
        (MAX_RESERVATIONS_PER_SENDER - MAX_OFFERS_PER_SENDER_PER_GAP + 1) as u64
    );
    assert_eq!(report["unsafe_uav"], 3);
    assert_eq!(report["far_from_region"], 1);
}

#[path = "handover_network_tests.rs"]
mod network;
