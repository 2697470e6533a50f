//! `neighbours_of` on a road (regions whose ranges touch) and on a network (regions a passage
//! joins), and its errors naming the region and the known ones.

use super::{neighbours_of, test_network};
use roads::{Airspace, Region, Road, RoadLayout};

fn road_of_three() -> Airspace {
    let mut layout = RoadLayout::straight(0.0, 30.0, 4.0, 6);
    let region = |name: &str, first, last| Region { name: name.into(), segments: [first, last] };
    layout.regions = Some(vec![region("c", 4, 5), region("a", 0, 1), region("b", 2, 3)]);
    Road::new(layout).unwrap().into() // a valid layout: three regions covering six segments
}

#[test]
fn neighbours_are_the_regions_whose_ranges_touch() {
    let road = road_of_three();
    assert_eq!(neighbours_of(&road, "a").unwrap(), ["b"]);
    assert_eq!(neighbours_of(&road, "b").unwrap(), ["a", "c"]);
    assert_eq!(neighbours_of(&road, "c").unwrap(), ["b"]);
    let e = neighbours_of(&road, "d").unwrap_err();
    assert!(e.contains("`d`") && e.contains("known: c, a, b"), "{e}");
    let plain = Road::new(RoadLayout::straight(0.0, 30.0, 4.0, 6)).unwrap().into(); // valid
    assert!(neighbours_of(&plain, "a").unwrap_err().contains("road has no regions"));
}

#[test]
fn on_a_network_neighbours_are_joined_by_a_passage() {
    let net = test_network::tee_in_three();
    assert_eq!(neighbours_of(&net, "stem").unwrap(), ["west"]);
    assert_eq!(neighbours_of(&net, "west").unwrap(), ["stem", "east"]);
    assert_eq!(neighbours_of(&net, "east").unwrap(), ["west"]);
    let e = neighbours_of(&net, "north").unwrap_err();
    assert!(e.contains("network has no such region (known: stem, west, east)"), "{e}");
}
