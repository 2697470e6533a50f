//! A deployment's layouts: a road or network read as written with the passage its network must
//! have, and a deployed road or network keeping the regions and their neighbours.

use super::*;
use roads::{Region, Road, RoadLayout};

fn road(regions: &[(&str, usize, usize)]) -> Airspace {
    let mut layout = RoadLayout::straight(0.0, 30.0, 4.0, 6);
    let region =
        |&(name, first, last): &(&str, usize, usize)| Region { name: name.into(), segments: [first, last] };
    layout.regions = Some(regions.iter().map(region).collect());
    Road::new(layout).unwrap().into() // the tests give ranges covering the six segments once
}

fn scenario(name: &str) -> String {
    let path = format!("{}/../scenarios/{name}.json", env!("CARGO_MANIFEST_DIR"));
    std::fs::read_to_string(path).unwrap()
}

/// The network of `scenarios/depot-regions.json` with its regions changed by `change`.
fn depot(change: impl FnOnce(&mut Vec<roads::network::NetworkRegion>)) -> Airspace {
    let (layout, _) = layout_of(Kind::Scenario, &scenario("depot-regions"), 1.0).unwrap();
    let mut layout = layout.network().unwrap().clone();
    change(layout.regions.as_mut().unwrap());
    roads::network::Network::new(layout, 1.0).unwrap().into()
}

#[test]
fn a_road_or_a_network_reads_as_written_with_its_passage() {
    let chain = RoadLayout::straight(0.0, 30.0, 4.0, 6);
    let network = roads::network::NetworkLayout::from(&chain);
    let text = serde_json::to_string(&network).unwrap();
    assert_eq!(layout_of(Kind::Road, &text, 0.7).unwrap(), (AirspaceLayout::Network(network), 0.7));
    let (depot, passage) = layout_of(Kind::Scenario, &scenario("depot-regions"), 9.0).unwrap();
    assert_eq!(depot.region_names(), ["west", "east", "branches"]);
    assert!(passage < 9.0, "the scenario's own parameters: {passage}");
    let (chain_back, _) = layout_of(Kind::Road, &serde_json::to_string(&chain).unwrap(), 0.7).unwrap();
    assert_eq!(chain_back, AirspaceLayout::Road(chain));
    // A network scenario with a chain's regions is refused naming `regions`.
    let mut bad: Value = serde_json::from_str(&scenario("depot")).unwrap();
    bad["regions"] = json!([{"name": "a", "segments": [0, 1]}]);
    let e = layout_of(Kind::Scenario, &bad.to_string(), 1.0).unwrap_err();
    assert_eq!((e.status, e.field.as_deref()), (StatusCode::UNPROCESSABLE_ENTITY, Some("regions")));
}

#[test]
fn a_deployed_road_keeps_the_regions_and_their_neighbours() {
    let old = road(&[("a", 0, 1), ("b", 2, 3), ("c", 4, 5)]);
    // Other ranges, the same neighbours: fine.
    assert!(check_same_regions(&old, &road(&[("a", 0, 0), ("b", 1, 4), ("c", 5, 5)])).is_ok());
    let renamed = check_same_regions(&old, &road(&[("a", 0, 1), ("b", 2, 3), ("d", 4, 5)])).unwrap_err();
    assert_eq!(renamed.field.as_deref(), Some("regions"));
    assert!(
        renamed.message.contains("(a, b, c)") && renamed.message.contains("(a, b, d)"),
        "{}",
        renamed.message
    );
    let reordered = check_same_regions(&old, &road(&[("b", 0, 1), ("a", 2, 3), ("c", 4, 5)])).unwrap_err();
    assert!(reordered.message.contains("neighbours of region `a`"), "{}", reordered.message);
}

#[test]
fn a_deployed_network_keeps_the_regions_and_their_neighbours() {
    let old = depot(|_| {});
    // The border moved along the trunk: the same neighbours.
    let moved = depot(|r| {
        r[0].roads[2].segments = [0, 3];
        r[1].roads[0].segments = [4, 5];
    });
    assert!(check_same_regions(&old, &moved).is_ok());
    // The fork given to the west: the west now borders the branches.
    let fork_west = depot(|r| {
        let fork = r[1].junctions.pop().unwrap();
        r[0].junctions.push(fork);
    });
    let e = check_same_regions(&old, &fork_west).unwrap_err();
    assert_eq!(e.field.as_deref(), Some("regions"));
    assert!(
        e.message.contains("neighbours of region `west` would change (east → east, branches)"),
        "{}",
        e.message
    );
    // A chain road with other regions than the network's.
    assert!(check_same_regions(&old, &road(&[("a", 0, 1), ("b", 2, 5)])).is_err());
}
