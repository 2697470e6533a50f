//! JSON schemas of a layout's parts, for the OpenAPI document (`schemars`): marker types whose
//! schema states this crate's limits, used with `#[schemars(with = ...)]` on wire fields.

use crate::regions::{MAX_REGION_NAME, Region};
use crate::validate::{MAX_COORDINATE_M, MAX_SEGMENTS};
use schemars::{JsonSchema, Schema, SchemaGenerator, json_schema};
use std::borrow::Cow;

/// A point `[x, y]` (m) anywhere a request takes one: each coordinate within ±[`MAX_COORDINATE_M`].
pub struct Point;

impl JsonSchema for Point {
    fn schema_name() -> Cow<'static, str> {
        "Point".into()
    }

    fn json_schema(_: &mut SchemaGenerator) -> Schema {
        json_schema!({
            "type": "array",
            "items": {"type": "number", "minimum": -MAX_COORDINATE_M, "maximum": MAX_COORDINATE_M},
            "minItems": 2,
            "maxItems": 2,
            "description": "[x, y] (m), each coordinate within ±1e6 m (the range roads may have; anything farther is refused with 422 wherever a point is accepted)"
        })
    }
}

/// A segment's vertices `[p1, p2, p3, p4]`.
pub struct Quad;

impl JsonSchema for Quad {
    fn schema_name() -> Cow<'static, str> {
        "Quad".into()
    }

    fn json_schema(generator: &mut SchemaGenerator) -> Schema {
        json_schema!({
            "type": "array",
            "items": generator.subschema_for::<Point>(),
            "minItems": 4,
            "maxItems": 4,
            "description": "segment vertices [p1, p2, p3, p4]; barrier lines p2→p1 and p4→p3"
        })
    }
}

/// A road's segments in order: 1 to [`MAX_SEGMENTS`].
pub struct Segments;

impl JsonSchema for Segments {
    fn schema_name() -> Cow<'static, str> {
        "Segments".into()
    }

    fn json_schema(generator: &mut SchemaGenerator) -> Schema {
        json_schema!({
            "type": "array",
            "items": generator.subschema_for::<Quad>(),
            "minItems": 1,
            "maxItems": MAX_SEGMENTS,
            "description": "the road's segments in order, 1 to 10000. Beyond the schema a layout is refused with 422 (`rule` naming the rule in `PUT /api/road`) when a quad is not strictly convex or has an edge shorter than 1 mm, consecutive segments do not join seamlessly (p1, p3 of segment i are p2, p4 of segment i+1) or fold back, or two non-adjacent segments overlap"
        })
    }
}

/// A layout's regions: 1 to [`MAX_SEGMENTS`] named ranges.
pub struct Regions;

impl JsonSchema for Regions {
    fn schema_name() -> Cow<'static, str> {
        "Regions".into()
    }

    fn json_schema(generator: &mut SchemaGenerator) -> Schema {
        json_schema!({
            "type": "array",
            "items": generator.subschema_for::<Region>(),
            "minItems": 1,
            "maxItems": MAX_SEGMENTS,
            "description": "named inclusive segment ranges that cover every segment exactly once (the partition the regional servers will use), names unique; a range past the last segment, reversed, or overlapping another is refused with 422"
        })
    }
}

/// A network's regions: 1 to [`crate::network::MAX_CELLS`] named sets of cells.
pub struct NetworkRegions;

impl JsonSchema for NetworkRegions {
    fn schema_name() -> Cow<'static, str> {
        "NetworkRegions".into()
    }

    fn json_schema(generator: &mut SchemaGenerator) -> Schema {
        json_schema!({
            "type": "array",
            "items": generator.subschema_for::<crate::network::NetworkRegion>(),
            "minItems": 1,
            "maxItems": crate::network::MAX_CELLS,
            "description": "named sets of cells (segment ranges of named roads, whole junctions) that cover every cell exactly once, names unique; beyond the schema refused with 422 (`field` naming `regions[k].roads[j]` or `regions[k].junctions[j]`) for an unknown road or junction (unknown_name), a range reversed (reversed_region) or past the road's last segment (region_out_of_range), a cell in two regions (region_overlap) or in none (region_gap), a region with no cell (empty_region), an empty, invalid or repeated name"
        })
    }
}

/// The pattern of a region's name: 1 to [`MAX_REGION_NAME`] characters from `A-Z a-z 0-9 _ -`.
pub fn region_name_pattern() -> String {
    format!("^[A-Za-z0-9_-]{{1,{MAX_REGION_NAME}}}$")
}

/// A network road's speed limit (m/s): more than 0, at most [`crate::network::MAX_SPEED_LIMIT`].
pub struct SpeedLimit;

impl JsonSchema for SpeedLimit {
    fn schema_name() -> Cow<'static, str> {
        "SpeedLimit".into()
    }

    fn json_schema(_: &mut SchemaGenerator) -> Schema {
        json_schema!({
            "type": "number",
            "exclusiveMinimum": 0,
            "maximum": crate::network::MAX_SPEED_LIMIT,
            "description": "the road's speed limit (m/s), more than 0 and at most 100; null or absent: none"
        })
    }
}
