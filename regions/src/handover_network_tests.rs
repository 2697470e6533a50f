//! The handover on a road network (the T of `test_network`: `west` holds the junction and the east
//! road's first two segments, `east` the last two): a UAV is offered when the cell it is in belongs
//! to a neighbouring region, and an offer is taken only in a cell of the region or one a passage
//! joins to it.

use super::*;
use crate::test_network::tee_in_three;

impl Side {
    /// Adds UAV `id` at `p` flying to `goal` and ticks once.
    fn add_at(&mut self, id: &str, p: [f64; 2], goal: [f64; 2]) {
        let state = UavState { p: Vec2::new(p[0], p[1]), v: Vec2::new(1.0, 0.0) };
        let link = Box::new(SimLink::new(state, self.fleet.config.params.dt));
        self.fleet.add(id.into(), "pd".into(), link, state, Some(Vec2::new(goal[0], goal[1])));
        self.fleet.tick();
    }
}

#[test]
fn on_a_network_a_uav_is_offered_by_its_cell_and_adopted_next_door() {
    let (mut west, mut east) = (side_on("west", tee_in_three()), side_on("east", tee_in_three()));
    let t0 = Instant::now();
    west.add_at("u", [5.0, 0.0], [18.0, 0.0]); // the east road's segment 0: west's own
    west.gap(t0);
    assert!(west.sent().is_none(), "a UAV in its own region's cell is not offered");
    west.fleet.remove("u").unwrap();
    west.add_at("u", [12.0, 0.0], [18.0, 0.0]); // the east road's segment 2: east's
    west.gap(t0);
    let offer = west.sent().expect("an offer");
    assert!(matches!(&offer, Message::Offer { to, id, .. } if to == "east" && id == "u"), "{offer:?}");
    east.inbox.send(offer).unwrap();
    east.gap(t0);
    let accept = east.sent().expect("an accept");
    assert!(matches!(accept, Message::Accept { .. }), "{accept:?}");
    west.inbox.send(accept).unwrap();
    west.gap(t0);
    assert!(!west.owns("u"), "released");
    east.inbox.send(west.sent().expect("a release")).unwrap();
    east.gap(t0);
    assert!(east.owns("u") && !west.owns("u"), "one owner: east");
    // The stem is west's neighbour, not east's: an offer there is refused by name.
    let far = Message::Offer {
        from: "west".into(),
        to: "east".into(),
        id: "s".into(),
        seq: 9,
        uav: hovering([0.0, -10.0]),
    };
    east.inbox.send(far).unwrap();
    east.gap(t0);
    let answer = east.sent().expect("an answer");
    assert!(
        matches!(&answer, Message::Refuse { reason, .. } if reason.contains("not in or next to region `east`")),
        "{answer:?}"
    );
    // The east road's segment 1 (west's) is joined to east's first cell: an offer there is taken.
    let near = Message::Offer {
        from: "west".into(),
        to: "east".into(),
        id: "n".into(),
        seq: 10,
        uav: hovering([9.0, 0.0]),
    };
    east.inbox.send(near).unwrap();
    east.gap(t0);
    assert!(matches!(east.sent(), Some(Message::Accept { .. })));
}
