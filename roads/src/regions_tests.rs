//! Regions of a layout: each validation rule with its field, segment and message, the JSON format
//! (absent stays absent), `Road::region_of`, and on random partitions of up to 200 segments that
//! every partition validates and every single moved or removed boundary is named.

use crate::layout::RoadLayout;
use crate::regions::{MAX_REGION_NAME, Region, check_regions};
use crate::road::Road;
use crate::validate::{RoadError, RoadRule};
use proptest::prelude::*;
use proptest::sample::Index;

fn region(name: &str, first: usize, last: usize) -> Region {
    Region { name: name.into(), segments: [first, last] }
}

/// A straight road of five segments divided into `regions`.
fn five(regions: Vec<Region>) -> RoadLayout {
    RoadLayout { regions: Some(regions), ..RoadLayout::straight(0.0, 50.0, 4.0, 5) }
}

fn rejected(layout: RoadLayout) -> RoadError {
    Road::new(layout).expect_err("the regions must be rejected")
}

/// Asserts the error's field, rule and segment, and that its message contains `words`.
fn assert_error(e: &RoadError, field: &str, rule: RoadRule, segment: Option<usize>, words: &[&str]) {
    assert_eq!((e.field.as_str(), e.rule, e.segment), (field, rule, segment), "{e}");
    for w in words {
        assert!(e.message.contains(w), "`{w}` missing from: {e}");
    }
}

#[test]
fn absent_regions_keep_the_json_as_it_was_and_present_ones_round_trip() {
    let plain = RoadLayout::straight(0.0, 20.0, 4.0, 2);
    let text = serde_json::to_string(&plain).unwrap();
    assert_eq!(text, format!("{{\"segments\":{}}}", serde_json::to_string(&plain.segments).unwrap()));
    assert_eq!(serde_json::from_str::<RoadLayout>(&text).unwrap(), plain);

    let divided = five(vec![region("west", 0, 1), region("east", 2, 4)]);
    let text = serde_json::to_string(&divided).unwrap();
    assert!(
        text.ends_with(r#""regions":[{"name":"west","segments":[0,1]},{"name":"east","segments":[2,4]}]}"#)
    );
    assert_eq!(serde_json::from_str::<RoadLayout>(&text).unwrap(), divided);

    // `null` is neither absent nor a list; unknown keys of a region are refused like the layout's.
    for bad in [
        r#"{"segments": [], "regions": null}"#,
        r#"{"segments": [], "regions": [{"name": "a", "segments": [0, 0], "x": 1}]}"#,
    ] {
        assert!(serde_json::from_str::<RoadLayout>(bad).is_err(), "{bad}");
    }
}

#[test]
fn valid_regions_are_accepted_in_any_order_and_region_of_finds_them() {
    let road = Road::new(five(vec![region("c", 4, 4), region("a-1", 0, 1), region("B_2", 2, 3)])).unwrap();
    let names: Vec<_> = (0..5).map(|s| road.region_of(s).map(|r| r.name.as_str())).collect();
    assert_eq!(names, [Some("a-1"), Some("a-1"), Some("B_2"), Some("B_2"), Some("c")]);
    assert_eq!(road.region_of(5), None);
    assert_eq!(road.region_of(usize::MAX), None);
    let whole = Road::new(five(vec![region(&"x".repeat(MAX_REGION_NAME), 0, 4)])).unwrap();
    assert_eq!(whole.region_of(3).map(|r| r.segments), Some([0, 4]));
    assert_eq!(Road::new(RoadLayout::straight(0.0, 50.0, 4.0, 5)).unwrap().region_of(0), None);
}

#[test]
fn an_empty_list_and_bad_names_are_named() {
    assert_error(
        &rejected(five(vec![])),
        "regions",
        RoadRule::EmptyRegions,
        None,
        &["leave it out", "0 to 4"],
    );
    let e = rejected(five(vec![region("a", 0, 1), region("", 2, 4)]));
    assert_error(&e, "regions[1].name", RoadRule::EmptyRegionName, None, &["needs a name"]);
    let long = "y".repeat(MAX_REGION_NAME + 1);
    let e = rejected(five(vec![region(&long, 0, 4)]));
    assert_error(&e, "regions[0].name", RoadRule::InvalidRegionName, None, &["65 characters", "at most 64"]);
    for (name, c) in
        [("west/1", "'/'"), ("a*", "'*'"), ("$x", "'$'"), ("a b", "' '"), ("é", "'é'"), ("a.b", "'.'")]
    {
        let e = rejected(five(vec![region("ok", 0, 1), region(name, 2, 4)]));
        assert_error(&e, "regions[1].name", RoadRule::InvalidRegionName, None, &[c, "A-Z a-z 0-9 _ -"]);
    }
    let e = rejected(five(vec![region("a", 0, 1), region("b", 2, 2), region("a", 3, 4)]));
    assert_error(&e, "regions[2].name", RoadRule::DuplicateRegionName, None, &["`a`", "regions[0]"]);
}

#[test]
fn reversed_and_out_of_range_segments_are_named() {
    let e = rejected(five(vec![region("a", 0, 0), region("b", 3, 1)]));
    assert_error(
        &e,
        "regions[1].segments",
        RoadRule::ReversedRegion,
        None,
        &["first segment 3", "last segment 1"],
    );
    let e = rejected(five(vec![region("a", 0, 2), region("b", 3, 5)]));
    assert_error(
        &e,
        "regions[1].segments",
        RoadRule::RegionOutOfRange,
        None,
        &["segment 5 is out of range", "0 to 4"],
    );
    let e = rejected(five(vec![region("a", 6, 9), region("b", 0, 4)]));
    assert_error(&e, "regions[0].segments", RoadRule::RegionOutOfRange, None, &["segments 6 to 9 are"]);
}

#[test]
fn overlaps_name_both_regions_and_gaps_name_the_segments() {
    let e = rejected(five(vec![region("west", 0, 2), region("east", 2, 4)]));
    assert_error(
        &e,
        "regions[1].segments",
        RoadRule::RegionOverlap,
        Some(2),
        &["`east`", "segment 2 ", "`west` (regions[0])"],
    );
    // The region that starts later is the one reported, whatever the list order.
    let e = rejected(five(vec![region("east", 1, 4), region("west", 0, 3)]));
    assert_error(
        &e,
        "regions[0].segments",
        RoadRule::RegionOverlap,
        Some(1),
        &["`east` shares segments 1 to 3 with region `west` (regions[1])"],
    );
    let e = rejected(five(vec![region("a", 0, 1), region("b", 0, 4)]));
    assert_error(
        &e,
        "regions[1].segments",
        RoadRule::RegionOverlap,
        Some(0),
        &["segments 0 to 1", "(regions[0])"],
    );

    let e = rejected(five(vec![region("a", 0, 1), region("b", 3, 4)]));
    assert_error(&e, "regions", RoadRule::RegionGap, Some(2), &["segment 2 is in no region"]);
    let e = rejected(five(vec![region("a", 0, 2)]));
    assert_error(&e, "regions", RoadRule::RegionGap, Some(3), &["segments 3 to 4 are in no region"]);
    let e = rejected(five(vec![region("a", 1, 4)]));
    assert_error(&e, "regions", RoadRule::RegionGap, Some(0), &["segment 0 is in no region"]);
}

#[test]
fn errors_print_their_field_and_rule() {
    let e = rejected(five(vec![region("a", 0, 1), region("b", 3, 4)]));
    assert_eq!(e.to_string(), "regions (region_gap): segment 2 is in no region");
    let mut broken = RoadLayout::straight(0.0, 20.0, 4.0, 2);
    broken.segments[1][1] = [9.0, -2.0];
    let e = Road::new(broken).unwrap_err();
    assert!(e.to_string().starts_with("segments[1] (seamless_join): "), "{e}");
    assert_eq!(e.field, "segments[1]");
}

/// `n` segments (1 to 200) cut into ranges with a random density of cuts, named uniquely with
/// random valid prefixes, listed in random order.
fn partition() -> impl Strategy<Value = (usize, Vec<Region>)> {
    (1usize..=200, 0.0f64..=1.0)
        .prop_flat_map(|(n, density)| {
            let cuts = proptest::collection::vec(proptest::bool::weighted(density), n - 1);
            let prefixes = proptest::collection::vec("[A-Za-z0-9_-]{1,8}", n);
            (Just(n), cuts, prefixes)
        })
        .prop_flat_map(|(n, cuts, prefixes)| {
            let mut ranges = Vec::new();
            let mut start = 0;
            for (i, _) in cuts.iter().enumerate().filter(|(_, cut)| **cut) {
                ranges.push([start, i]);
                start = i + 1;
            }
            ranges.push([start, n - 1]);
            let regions: Vec<Region> = ranges
                .iter()
                .enumerate()
                .map(|(k, r)| Region { name: format!("{}-{k}", prefixes[k]), segments: *r })
                .collect();
            (Just(n), Just(regions).prop_shuffle())
        })
}

/// The list indices of `regions` sorted by first segment.
fn sorted(regions: &[Region]) -> Vec<usize> {
    let mut order: Vec<usize> = (0..regions.len()).collect();
    order.sort_by_key(|&k| regions[k].segments[0]);
    order
}

/// `segment a is in no region` or `segments a to b are in no region`.
fn gap_words(a: usize, b: usize) -> String {
    if a == b {
        format!("segment {a} is in no region")
    } else {
        format!("segments {a} to {b} are in no region")
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(512))]

    #[test]
    fn every_partition_validates_and_region_of_matches_a_scan((n, regions) in partition()) {
        let order = check_regions(Some(&regions), n).map_err(|e| TestCaseError::fail(e.to_string()))?;
        for s in 0..n + 2 {
            let scan = regions.iter().position(|r| r.segments[0] <= s && s <= r.segments[1]);
            prop_assert_eq!(order.find(&regions, s), scan, "segment {}", s);
        }
    }

    #[test]
    fn a_removed_or_moved_boundary_is_named(
        (n, mut regions) in partition(),
        kind in 0u8..5,
        pick in any::<Index>(),
        by in any::<Index>(),
    ) {
        let order = sorted(&regions);
        let m = order.len();
        let error = |regions: &[Region]| check_regions(Some(regions), n).err();
        match kind {
            // Remove one region: its segments are the gap (or the list is empty).
            0 => {
                let t = pick.index(m);
                let [f, l] = regions[order[t]].segments;
                regions.remove(order[t]);
                let e = error(&regions).expect("a removed region leaves a gap");
                if m == 1 {
                    prop_assert_eq!((e.field.as_str(), e.rule), ("regions", RoadRule::EmptyRegions));
                } else {
                    prop_assert_eq!((e.field.as_str(), e.rule, e.segment), ("regions", RoadRule::RegionGap, Some(f)));
                    prop_assert_eq!(e.message, gap_words(f, l));
                }
            }
            // Move a last segment down, or a first one up (within the region): a gap.
            1 | 2 => {
                let long: Vec<usize> = order.iter().copied().filter(|&k| regions[k].segments[1] > regions[k].segments[0]).collect();
                if long.is_empty() {
                    return Ok(());
                }
                let k = long[pick.index(long.len())];
                let [f, l] = regions[k].segments;
                let d = 1 + by.index(l - f);
                let (a, b) = if kind == 1 { (l - d + 1, l) } else { (f, f + d - 1) };
                regions[k].segments = if kind == 1 { [f, l - d] } else { [f + d, l] };
                let e = error(&regions).expect("a moved boundary leaves a gap");
                prop_assert_eq!((e.field.as_str(), e.rule, e.segment), ("regions", RoadRule::RegionGap, Some(a)));
                prop_assert_eq!(e.message, gap_words(a, b));
            }
            // Move a last segment up: into the next region (overlap), or off the road's end.
            3 => {
                let t = pick.index(m);
                let k = order[t];
                let last = regions[k].segments[1] + 1 + by.index(n);
                regions[k].segments[1] = last;
                let e = error(&regions).expect("a moved boundary overlaps or leaves the road");
                if last >= n {
                    prop_assert_eq!((e.field, e.rule), (format!("regions[{k}].segments"), RoadRule::RegionOutOfRange));
                } else {
                    let next = order[t + 1];
                    let first = regions[next].segments[0];
                    prop_assert_eq!(
                        (e.field, e.rule, e.segment),
                        (format!("regions[{next}].segments"), RoadRule::RegionOverlap, Some(first))
                    );
                    prop_assert!(e.message.contains(&format!("`{}`", regions[k].name)), "{}", e.message);
                    prop_assert!(e.message.contains(&format!("`{}`", regions[next].name)), "{}", e.message);
                }
            }
            // Move a first segment down into an earlier region: an overlap with the region there.
            _ => {
                if m == 1 {
                    return Ok(());
                }
                let t = 1 + pick.index(m - 1);
                let k = order[t];
                let first = regions[k].segments[0] - 1 - by.index(regions[k].segments[0]);
                let u = order.iter().copied().find(|&j| regions[j].segments[0] <= first && first <= regions[j].segments[1]).expect("a partition covers every segment");
                regions[k].segments[0] = first;
                // The later of the two in segment order (ties in list order) is reported.
                let reported = if regions[u].segments[0] < first || u < k { k } else { u };
                let e = error(&regions).expect("a moved boundary overlaps");
                prop_assert_eq!(
                    (e.field, e.rule, e.segment),
                    (format!("regions[{reported}].segments"), RoadRule::RegionOverlap, Some(first))
                );
                prop_assert!(e.message.contains(&format!("`{}`", regions[k].name)), "{}", e.message);
                prop_assert!(e.message.contains(&format!("`{}`", regions[u].name)), "{}", e.message);
            }
        }
    }
}
