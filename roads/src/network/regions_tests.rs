//! Regions of a network: each rule with its field, segment and message, the JSON format (absent
//! stays absent), `region_of` and the neighbours on a crossing; on random street grids with random
//! partitions that every partition validates and `region_of` matches the partition, and that a
//! partition with one range or junction moved into another region, dropped or misnamed is refused
//! naming that entry.

use super::tests::{crossing, grid};
use super::*;
use crate::airspace::Airspace;
use crate::validate::RoadRule;
use proptest::prelude::*;
use proptest::sample::Index;

fn range(road: &str, first: usize, last: usize) -> RoadRange {
    RoadRange { road: road.into(), segments: [first, last] }
}

fn region(name: &str, roads: Vec<RoadRange>, junctions: &[&str]) -> NetworkRegion {
    NetworkRegion { name: name.into(), roads, junctions: junctions.iter().map(|j| j.to_string()).collect() }
}

/// The crossing (roads east, west, north, south of 3 segments, junction `x`) in three regions:
/// `a` the junction and the west road, `b` the east road, `c` north and south.
fn three() -> Vec<NetworkRegion> {
    vec![
        region("a", vec![range("west", 0, 2)], &["x"]),
        region("b", vec![range("east", 0, 2)], &[]),
        region("c", vec![range("north", 0, 2), range("south", 0, 2)], &[]),
    ]
}

fn divided(regions: Vec<NetworkRegion>) -> NetworkLayout {
    NetworkLayout { regions: Some(regions), ..crossing() }
}

/// Asserts the refusal's field, rule and segment, and that its message contains `words`.
fn refused(regions: Vec<NetworkRegion>, field: &str, rule: RoadRule, segment: Option<usize>, words: &[&str]) {
    let e = Network::new(divided(regions), 0.5).expect_err("the regions must be refused");
    assert_eq!((e.field.as_str(), e.rule, e.segment), (field, rule, segment), "{e}");
    for w in words {
        assert!(e.message.contains(w), "`{w}` missing from: {e}");
    }
}

#[test]
fn regions_are_optional_in_the_json_and_round_trip() {
    let plain = crossing();
    let text = serde_json::to_string(&plain).unwrap();
    assert!(!text.contains("regions"), "{text}");
    let layout = divided(three());
    let text = serde_json::to_string(&layout).unwrap();
    assert!(text.contains(r#"{"name":"b","roads":[{"road":"east","segments":[0,2]}]}"#), "{text}");
    assert_eq!(serde_json::from_str::<NetworkLayout>(&text).unwrap(), layout);
    let bad = r#"{"roads": [], "regions": [{"name": "a", "segments": [0, 1]}]}"#;
    assert!(serde_json::from_str::<NetworkLayout>(bad).is_err(), "a chain's region is not a network's");
}

#[test]
fn region_of_names_each_cell_and_neighbours_are_joined_by_a_passage() {
    let net = Network::new(divided(three()), 0.5).unwrap();
    let names: Vec<_> = (0..net.cells().len()).map(|c| net.region_of(c).unwrap().name.as_str()).collect();
    // Cells: east 0-2, west 0-2, north 0-2, south 0-2, then the junction.
    assert_eq!(names, ["b", "b", "b", "a", "a", "a", "c", "c", "c", "c", "c", "c", "a"]);
    assert!(net.region_of(13).is_none());
    let space = Airspace::from(net);
    assert_eq!(space.neighbour_regions("a").unwrap(), ["b", "c"]);
    assert_eq!(space.neighbour_regions("b").unwrap(), ["a"]);
    assert_eq!(space.neighbour_regions("c").unwrap(), ["a"]);
    assert!(space.neighbour_regions("d").is_none());
    assert_eq!(space.region_names(), ["a", "b", "c"]);
    assert_eq!(space.region_at(&uav::Vec2::new(5.0, 0.0)), Some("b"));
    assert_eq!(space.region_at(&uav::Vec2::new(0.0, 0.0)), Some("a"));
    assert_eq!(space.region_at(&uav::Vec2::new(0.0, -5.0)), Some("c"));
    assert_eq!(space.region_at(&uav::Vec2::new(5.0, 5.0)), None, "outside the network");
    // The junction's cell is next to every region; b's last segment only to b.
    assert!(space.in_or_next_to_region(12, "b") && space.in_or_next_to_region(12, "c"));
    assert!(space.in_or_next_to_region(0, "a") && !space.in_or_next_to_region(2, "a"));
    let undivided = Airspace::from(Network::new(crossing(), 0.5).unwrap());
    assert!(undivided.region_names().is_empty() && undivided.neighbour_regions("a").is_none());
}

#[test]
fn each_region_rule_is_named_with_the_field_at_fault() {
    let mut r = three();
    r[1].roads[0].road = "nowhere".into();
    refused(r, "regions[1].roads[0]", RoadRule::UnknownName, None, &["no road `nowhere`"]);
    let mut r = three();
    r[0].junctions[0] = "y".into();
    refused(r, "regions[0].junctions[0]", RoadRule::UnknownName, None, &["no junction `y`"]);
    let mut r = three();
    r[2].roads[1].segments = [2, 1];
    refused(r, "regions[2].roads[1]", RoadRule::ReversedRegion, None, &["2 is after the last segment 1"]);
    let mut r = three();
    r[1].roads[0].segments = [1, 4];
    refused(
        r,
        "regions[1].roads[0]",
        RoadRule::RegionOutOfRange,
        Some(4),
        &["segments 3 to 4 are", "`east`"],
    );
    let mut r = three();
    r[1].roads[0].segments = [1, 2];
    r[0].roads.push(range("east", 0, 1));
    refused(r, "regions[1].roads[0]", RoadRule::RegionOverlap, Some(1), &["segment 1 of road `east`", "`a`"]);
    let mut r = three();
    r[2].junctions.push("x".into());
    refused(r, "regions[2].junctions[0]", RoadRule::RegionOverlap, None, &["junction `x`", "regions[0]"]);
    let mut r = three();
    r[2].roads[1].segments = [0, 1];
    refused(r, "regions", RoadRule::RegionGap, Some(2), &["segment 2 of road `south` is in no region"]);
    let mut r = three();
    r[0].junctions.clear();
    refused(r, "regions", RoadRule::RegionGap, None, &["junction `x` is in no region"]);
    let mut r = three();
    r.push(region("d", vec![], &[]));
    refused(r, "regions[3]", RoadRule::EmptyRegion, None, &["`d` lists no road and no junction"]);
    refused(vec![], "regions", RoadRule::EmptyRegions, None, &[]);
    let mut r = three();
    r[2].name = "a".into();
    refused(r, "regions[2].name", RoadRule::DuplicateRegionName, None, &["regions[0]"]);
    let mut r = three();
    r[1].name = "b/c".into();
    refused(r, "regions[1].name", RoadRule::InvalidRegionName, None, &["'/'"]);
    let mut r = three();
    r[1].name = String::new();
    refused(r, "regions[1].name", RoadRule::EmptyRegionName, None, &[]);
}

/// Each cell of a grid labelled with one of `count` regions by `picks`, and the regions as a
/// layout lists them (each road's runs of one label as ranges, the junctions by name; labels that
/// hold no cell dropped). Returns the layout and each cell's region name.
fn partition(layout: &NetworkLayout, picks: &[usize], count: usize) -> (Vec<NetworkRegion>, Vec<String>) {
    let mut regions: Vec<NetworkRegion> = (0..count)
        .map(|k| NetworkRegion { name: format!("r{k}"), roads: vec![], junctions: vec![] })
        .collect();
    let mut labels = Vec::new();
    let mut cell = 0;
    for road in &layout.roads {
        let mut start = 0;
        for s in 0..road.segments.len() {
            let label = picks[cell % picks.len()] % count;
            labels.push(label);
            cell += 1;
            let ends = s + 1 == road.segments.len() || picks[cell % picks.len()] % count != label;
            if ends {
                regions[label].roads.push(range(&road.name, start, s));
                start = s + 1;
            }
        }
    }
    for junction in &layout.junctions {
        let label = picks[cell % picks.len()] % count;
        labels.push(label);
        cell += 1;
        regions[label].junctions.push(junction.name.clone());
    }
    let names = labels.iter().map(|&k| regions[k].name.clone()).collect();
    regions.retain(|r| !r.roads.is_empty() || !r.junctions.is_empty());
    (regions, names)
}

/// The field of item `i` of region `k`: its ranges first, then its junctions.
fn item_field(region: &NetworkRegion, k: usize, i: usize) -> String {
    if i < region.roads.len() {
        format!("regions[{k}].roads[{i}]")
    } else {
        format!("regions[{k}].junctions[{}]", i - region.roads.len())
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(1000))]

    /// Random partitions of random grids validate and `region_of` answers each cell's label.
    #[test]
    fn random_partitions_validate_and_region_of_matches_them(
        nx in 1usize..4, ny in 1usize..4, pieces in 1usize..4, count in 1usize..5,
        picks in prop::collection::vec(0usize..8, 1..40),
    ) {
        prop_assume!(nx * ny > 1);
        let layout = grid(nx, ny, 12.0, 2.0, pieces);
        let (regions, names) = partition(&layout, &picks, count);
        let net = Network::new(NetworkLayout { regions: Some(regions), ..layout }, 0.5).unwrap();
        for (cell, name) in names.iter().enumerate() {
            prop_assert_eq!(&net.region_of(cell).unwrap().name, name);
        }
        prop_assert!(net.region_of(names.len()).is_none());
    }

    /// One entry moved into the last region (overlap), dropped (gap) or renamed (unknown) is
    /// refused naming it.
    #[test]
    fn corrupted_partitions_are_refused_naming_the_entry(
        nx in 1usize..4, ny in 1usize..4, pieces in 1usize..4, count in 2usize..5,
        picks in prop::collection::vec(0usize..8, 1..40), which in any::<Index>(), how in 0usize..3,
    ) {
        prop_assume!(nx * ny > 1);
        let layout = grid(nx, ny, 12.0, 2.0, pieces);
        let (mut regions, _) = partition(&layout, &picks, count);
        // Every entry as (region, item), items of a region in its order.
        let entries: Vec<(usize, usize)> = regions
            .iter()
            .enumerate()
            .flat_map(|(k, r)| (0..r.roads.len() + r.junctions.len()).map(move |i| (k, i)))
            .collect();
        let (k, i) = entries[which.index(entries.len())];
        let last = regions.len() - 1;
        let rule = match how {
            0 => {
                prop_assume!(k != last);
                // A copy of the entry appended to the last region: the cell is then in two.
                let moved = regions[k].clone();
                let field;
                if i < moved.roads.len() {
                    field = format!("regions[{last}].roads[{}]", regions[last].roads.len());
                    regions[last].roads.push(moved.roads[i].clone());
                } else {
                    field = format!("regions[{last}].junctions[{}]", regions[last].junctions.len());
                    regions[last].junctions.push(moved.junctions[i - moved.roads.len()].clone());
                }
                (RoadRule::RegionOverlap, field)
            }
            1 => {
                prop_assume!(regions[k].roads.len() + regions[k].junctions.len() > 1);
                // Dropped: its cells (the only ones) are in no region.
                let segment = if i < regions[k].roads.len() {
                    Some(regions[k].roads.remove(i).segments[0])
                } else {
                    let j = i - regions[k].roads.len();
                    regions[k].junctions.remove(j);
                    None
                };
                let e = Network::new(NetworkLayout { regions: Some(regions), ..layout }, 0.5).unwrap_err();
                prop_assert_eq!((e.rule, e.field.as_str(), e.segment), (RoadRule::RegionGap, "regions", segment));
                return Ok(());
            }
            _ => {
                let field = item_field(&regions[k], k, i);
                if i < regions[k].roads.len() {
                    regions[k].roads[i].road = "nowhere".into();
                } else {
                    let j = i - regions[k].roads.len();
                    regions[k].junctions[j] = "nowhere".into();
                }
                (RoadRule::UnknownName, field)
            }
        };
        let e = Network::new(NetworkLayout { regions: Some(regions), ..layout }, 0.5).unwrap_err();
        prop_assert_eq!((e.rule, e.field), rule);
    }
}
