//! Regions of a road layout: named, inclusive ranges of segment indices that cover every segment
//! exactly once. They are the partition the regional servers (coming) will use; today they are only
//! validated, stored and looked up.

use crate::validate::{RoadError, RoadRule};
use serde::{Deserialize, Serialize};
use std::collections::HashMap;

/// Longest region name accepted (characters).
pub const MAX_REGION_NAME: usize = 64;

/// A named, inclusive range of segment indices (`{"name": "west", "segments": [first, last]}`).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Region {
    /// 1 to [`MAX_REGION_NAME`] characters from `A-Z a-z 0-9 _ -`, so that it is one chunk of a
    /// Zenoh key expression (`airroads/region/<name>/state`).
    #[schemars(pattern(crate::schema::region_name_pattern()))]
    #[schemars(description = "unique among the regions; one chunk of a key expression")]
    pub name: String,
    /// `[first, last]`: the region's segments, both included.
    #[schemars(inner(range(max = crate::validate::MAX_SEGMENTS - 1)))]
    #[schemars(
        description = "[first, last] segment indices, both included (first ≤ last < the number of segments), written as whole numbers without a fraction or exponent (`3`, not `3.0`: JSON Schema cannot tell them apart)"
    )]
    pub segments: [usize; 2],
}

impl Region {
    /// Its first segment.
    pub fn first(&self) -> usize {
        self.segments[0]
    }

    /// Its last segment (included).
    pub fn last(&self) -> usize {
        self.segments[1]
    }
}

/// The regions of a validated layout in segment order: `order[k]` is the index (in the layout's
/// list) of the region with the k-th lowest first segment. Empty when the layout has no regions.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub(crate) struct RegionOrder {
    order: Vec<usize>,
}

impl RegionOrder {
    /// The index in `regions` of the region holding `segment`, by binary search (O(log r)).
    /// `regions` must be the list this order was built from.
    pub(crate) fn find(&self, regions: &[Region], segment: usize) -> Option<usize> {
        let after = self.order.partition_point(|&k| regions[k].first() <= segment);
        let k = self.order[after.checked_sub(1)?];
        (segment <= regions[k].last()).then_some(k)
    }
}

pub(crate) fn err(field: String, segment: Option<usize>, rule: RoadRule, message: String) -> RoadError {
    RoadError { field, segment, rule, message }
}

/// `segment 4` or `segments 4 to 6`.
pub(crate) fn span(first: usize, last: usize) -> String {
    if first == last { format!("segment {first}") } else { format!("segments {first} to {last}") }
}

/// Checks `regions` against a road of `n` segments and returns them in segment order.
///
/// Each region is checked in list order (name: empty, too long, characters, taken by an earlier
/// region; range: reversed, out of range), then the coverage in segment order: the first segment
/// in no region or in two is reported. O(n + r) for r regions: names go through a hash map and the
/// ranges are sorted by first segment with a counting sort (every first segment is below n).
pub(crate) fn check_regions(regions: Option<&[Region]>, n: usize) -> Result<RegionOrder, RoadError> {
    let Some(regions) = regions else { return Ok(RegionOrder::default()) };
    if regions.is_empty() {
        let msg = format!("`regions` is empty: leave it out, or list regions that cover {}", all(n));
        return Err(err("regions".into(), None, RoadRule::EmptyRegions, msg));
    }
    let mut names: HashMap<&str, usize> = HashMap::with_capacity(regions.len());
    for (i, region) in regions.iter().enumerate() {
        check_name(i, &region.name)?;
        if let Some(j) = names.insert(&region.name, i) {
            let msg = format!("the name `{}` is already used by regions[{j}]", region.name);
            return Err(err(format!("regions[{i}].name"), None, RoadRule::DuplicateRegionName, msg));
        }
        let field = || format!("regions[{i}].segments");
        let [first, last] = region.segments;
        if first > last {
            let msg = format!("the first segment {first} is after the last segment {last}");
            return Err(err(field(), None, RoadRule::ReversedRegion, msg));
        }
        if last >= n {
            let beyond = span_is(first.max(n), last);
            let msg = format!("{beyond} out of range: the road has {}", all(n));
            return Err(err(field(), None, RoadRule::RegionOutOfRange, msg));
        }
    }
    let order = by_first_segment(regions, n);
    // Before the first error the regions seen so far cover 0..next exactly, the last of them
    // (`previous`) ending at next - 1.
    let mut next = 0;
    let mut previous: Option<usize> = None;
    for &k in &order {
        let [first, last] = regions[k].segments;
        if first > next {
            let msg = format!("{} in no region", span_is(next, first - 1));
            return Err(err("regions".into(), Some(next), RoadRule::RegionGap, msg));
        }
        if let Some(j) = previous.filter(|_| first < next) {
            let msg = format!(
                "region `{}` shares {} with region `{}` (regions[{j}])",
                regions[k].name,
                span(first, last.min(next - 1)),
                regions[j].name
            );
            let field = format!("regions[{k}].segments");
            return Err(err(field, Some(first), RoadRule::RegionOverlap, msg));
        }
        next = last + 1;
        previous = Some(k);
    }
    if next < n {
        let msg = format!("{} in no region", span_is(next, n - 1));
        return Err(err("regions".into(), Some(next), RoadRule::RegionGap, msg));
    }
    Ok(RegionOrder { order })
}

/// All segments of a road of `n`: `segments 0 to 4`, `segment 0` or `no segment`.
pub(crate) fn all(n: usize) -> String {
    n.checked_sub(1).map_or_else(|| "no segment".into(), |last| span(0, last))
}

/// `segment 4 is` or `segments 4 to 6 are`.
pub(crate) fn span_is(first: usize, last: usize) -> String {
    let verb = if first == last { "is" } else { "are" };
    format!("{} {verb}", span(first, last))
}

/// The region indices sorted by first segment (ties in list order), by counting sort; every first
/// segment is below `n` (checked before).
fn by_first_segment(regions: &[Region], n: usize) -> Vec<usize> {
    let mut starts = vec![0usize; n + 1];
    for r in regions {
        starts[r.first() + 1] += 1;
    }
    for f in 0..n {
        starts[f + 1] += starts[f];
    }
    let mut order = vec![0; regions.len()];
    for (k, r) in regions.iter().enumerate() {
        order[starts[r.first()]] = k;
        starts[r.first()] += 1;
    }
    order
}

/// A region name is 1 to [`MAX_REGION_NAME`] characters from `A-Z a-z 0-9 _ -`.
pub(crate) fn check_name(i: usize, name: &str) -> Result<(), RoadError> {
    let field = || format!("regions[{i}].name");
    if name.is_empty() {
        return Err(err(field(), None, RoadRule::EmptyRegionName, "a region needs a name".into()));
    }
    let chars = name.chars().count();
    if chars > MAX_REGION_NAME {
        let msg = format!("the name is {chars} characters long, at most {MAX_REGION_NAME} are accepted");
        return Err(err(field(), None, RoadRule::InvalidRegionName, msg));
    }
    if let Some(c) = name.chars().find(|c| !(c.is_ascii_alphanumeric() || *c == '_' || *c == '-')) {
        let msg = format!(
            "the name `{name}` has the character {c:?}; region names use only A-Z a-z 0-9 _ - \
             (they become part of key expressions)"
        );
        return Err(err(field(), None, RoadRule::InvalidRegionName, msg));
    }
    Ok(())
}
