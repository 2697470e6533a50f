//! Scenario files: `{"name", "params"?, "segments", "regions"?, "uavs": [{"id", "start", "goal"}]}`
//! on one road, or `{"name", "params"?, "roads", "junctions"?, "regions"?, "uavs"}` on a network.

use links::LinkRules;
use roads::network::{Junction, Network, NetworkLayout, NetworkRoad};
use roads::{Airspace, AirspaceLayout, CLEARANCE_MARGIN_M, Road, RoadLayout};
use serde::{Deserialize, Serialize};
use std::collections::HashMap;

pub use crate::scenario_regions::ScenarioRegions;
use uav::{Params, Vec2};

/// A scenario as written in JSON.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
#[schemars(transform = road_or_network_schema)]
pub struct Scenario {
    /// Scenario name (reported in the metrics).
    pub name: String,
    /// Parameters; missing keys take their defaults, unknown keys are an error.
    #[serde(default)]
    pub params: Params,
    /// Road segments, as in a road layout (one road; or `roads` instead, a network). When given, at
    /// least one (the empty list is refused, also beside `roads`).
    #[serde(default, skip_serializing_if = "Vec::is_empty", deserialize_with = "some_segments")]
    #[schemars(with = "roads::schema::Segments")]
    pub segments: Vec<[[f64; 2]; 4]>,
    /// A network's roads (instead of `segments`): named chains of segments.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schemars(with = "Option<Vec<NetworkRoad>>", length(min = 1))]
    #[schemars(
        description = "a road network's roads (instead of `segments`), as in a network layout of `PUT /api/road`, which states the rules beyond the schema"
    )]
    pub roads: Option<Vec<NetworkRoad>>,
    /// A network's junctions (with `roads`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schemars(with = "Option<Vec<Junction>>")]
    #[schemars(description = "a road network's junctions (with `roads`); null or absent: none")]
    pub junctions: Option<Vec<Junction>>,
    /// The road's or network's regions, as in its layout (`airroads serve --region`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schemars(
        description = "optional, as in the layout of the road or network (null or absent: it is not divided)"
    )]
    pub regions: Option<ScenarioRegions>,
    /// The fleet.
    #[schemars(length(min = 1))]
    #[schemars(
        description = "the fleet, at least one UAV with unique ids; beyond the schema each start and goal must be inside this scenario's road at least D_s from its walls and the starts D_c apart, and the fleet must not exceed `--max-uavs`"
    )]
    pub uavs: Vec<ScenarioUav>,
}

/// The REST schema of a scenario flies one road or a network: `segments` (with `regions`, without
/// `roads` and `junctions`) or `roads` (with `junctions`, without `segments` and `regions`).
fn road_or_network_schema(schema: &mut schemars::Schema) {
    let object = schema.ensure_object();
    // Null is what an absent optional member may also be written as.
    let road = serde_json::json!({
        "required": ["segments"],
        "properties": {"roads": {"type": "null"}, "junctions": {"type": "null"}}
    });
    let network = serde_json::json!({
        "required": ["roads"],
        "not": {"required": ["segments"]},
        "properties": {"roads": {"type": "array"}}
    });
    object.insert("anyOf".into(), serde_json::json!([road, network]));
}

/// `segments` when the key is there: a non-empty list (a scenario without a road has no key).
fn some_segments<'de, D: serde::Deserializer<'de>>(d: D) -> Result<Vec<[[f64; 2]; 4]>, D::Error> {
    let segments = Vec::<[[f64; 2]; 4]>::deserialize(d)?;
    if segments.is_empty() {
        return Err(serde::de::Error::invalid_length(0, &"at least one segment"));
    }
    Ok(segments)
}

/// One UAV of a scenario as written in JSON.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct ScenarioUav {
    /// Unique id.
    #[schemars(with = "uav::schema::UavId")]
    pub id: String,
    /// Start position [x, y] (m), at rest.
    #[schemars(with = "roads::schema::Point")]
    pub start: [f64; 2],
    /// Goal position [x, y] (m).
    #[schemars(with = "roads::schema::Point")]
    pub goal: [f64; 2],
    /// How it is flown: `sim` (default, in-process) or a Crazyflie URI (`radio://…`, `udp://…`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schemars(with = "Option<links::schema::LinkText>")]
    pub link: Option<String>,
}

/// A UAV of a validated scenario.
#[derive(Debug, Clone, PartialEq)]
pub struct UavSpec {
    /// Unique id.
    pub id: String,
    /// Start position (m).
    pub start: Vec2,
    /// Goal position (m).
    pub goal: Vec2,
    /// Its link (None: in-process simulator).
    pub link: Option<String>,
}

/// A scenario whose road, parameters and fleet passed validation.
#[derive(Debug, Clone)]
pub struct ValidScenario {
    /// Scenario name.
    pub name: String,
    /// Parameters.
    pub params: Params,
    /// The validated road or network.
    pub road: Airspace,
    /// The fleet.
    pub uavs: Vec<UavSpec>,
}

/// Why a scenario was rejected: the JSON path of the field and the reason.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ScenarioError {
    /// The text is not valid scenario JSON (syntax, types, unknown keys).
    #[error("line {line}, column {column}: {message}")]
    Parse {
        /// 1-based line.
        line: usize,
        /// 1-based column.
        column: usize,
        /// serde_json's message (names unknown or missing keys).
        message: String,
    },
    /// A field has an invalid value.
    #[error("{field}: {reason}")]
    Invalid {
        /// JSON path, e.g. `uavs[2].start`.
        field: String,
        /// What is wrong.
        reason: String,
    },
}

fn invalid(field: impl Into<String>, reason: impl Into<String>) -> ScenarioError {
    ScenarioError::Invalid { field: field.into(), reason: reason.into() }
}

/// The narrowest passage a network may have: what a UAV needs to cross it, 2·D_s + D_c and the
/// paths' clearance margin on both sides (as the filter keeps them, `Params::kept_d_s`, `kept_d_c`).
pub fn min_passage_m(params: &Params) -> f64 {
    2.0 * (params.kept_d_s() + CLEARANCE_MARGIN_M) + params.kept_d_c()
}

impl Scenario {
    /// A scenario on one road of `segments` (no regions).
    pub fn on_road(
        name: String,
        params: Params,
        segments: Vec<[[f64; 2]; 4]>,
        uavs: Vec<ScenarioUav>,
    ) -> Self {
        Self { name, params, segments, regions: None, roads: None, junctions: None, uavs }
    }

    /// The layout of its road (`segments`, `regions`) or network (`roads`, `junctions`, `regions`),
    /// not validated; a mix of the two is refused naming the field.
    pub fn layout(&self) -> Result<AirspaceLayout, ScenarioError> {
        let Some(roads) = &self.roads else {
            if self.junctions.is_some() {
                return Err(invalid("junctions", "junctions belong to a network: give its `roads` too"));
            }
            let regions = self.regions.as_ref().map(|r| {
                r.road().ok_or_else(|| {
                    invalid("regions", "regions of one road list `segments`, not roads and junctions")
                })
            });
            let layout =
                RoadLayout { regions: regions.transpose()?, ..RoadLayout::new(self.segments.clone()) };
            return Ok(AirspaceLayout::Road(layout));
        };
        if !self.segments.is_empty() {
            return Err(invalid("segments", "give `segments` (one road) or `roads` (a network), not both"));
        }
        let regions = self.regions.as_ref().map(|r| {
            r.network().ok_or_else(|| {
                invalid("regions", "regions of a network list `roads` (segment ranges of named roads) and `junctions`, not `segments`")
            })
        });
        Ok(AirspaceLayout::Network(NetworkLayout {
            roads: roads.clone(),
            junctions: self.junctions.clone().unwrap_or_default(),
            regions: regions.transpose()?,
        }))
    }

    /// The road or the network, validated.
    fn airspace(&self) -> Result<Airspace, ScenarioError> {
        let refused = |e: roads::RoadError| invalid(e.field, format!("{} ({})", e.message, e.rule.name()));
        Ok(match self.layout()? {
            AirspaceLayout::Road(layout) => Airspace::Road(Road::new(layout).map_err(refused)?),
            AirspaceLayout::Network(layout) => {
                Airspace::Network(Network::new(layout, min_passage_m(&self.params)).map_err(refused)?)
            }
        })
    }

    /// Parses scenario JSON text.
    pub fn from_json(text: &str) -> Result<Self, ScenarioError> {
        serde_json::from_str(text).map_err(|e| ScenarioError::Parse {
            line: e.line(),
            column: e.column(),
            message: e.to_string().split(" at line ").next().unwrap_or_default().to_string(),
        })
    }

    /// Validates parameters, road and fleet (docs/safety.md §5; the safe-set assumption for starts),
    /// with the default [`LinkRules`] (UDP links to loopback only).
    pub fn validate(&self) -> Result<ValidScenario, ScenarioError> {
        self.validate_with(&LinkRules::default())
    }

    /// Validates as [`Scenario::validate`] does, checking each UAV's link against `rules`.
    ///
    /// UAVs are checked in file order, each field in the order id, start, goal, separation, link, and
    /// the first failure is reported. It takes O(n log n) for n UAVs: ids go through a hash map,
    /// starts through a grid of cells D_c wide, and each point query through the road's index.
    pub fn validate_with(&self, rules: &LinkRules) -> Result<ValidScenario, ScenarioError> {
        self.params.validate().map_err(|e| invalid(format!("params.{}", e.field), e.detail()))?;
        let road = self.airspace()?;
        if self.uavs.is_empty() {
            return Err(invalid("uavs", "a scenario needs at least one UAV"));
        }
        let p = &self.params;
        let mut uavs: Vec<UavSpec> = Vec::with_capacity(self.uavs.len());
        let mut ids: HashMap<&str, usize> = HashMap::with_capacity(self.uavs.len());
        let mut starts = StartGrid::new(p.d_c);
        for (i, u) in self.uavs.iter().enumerate() {
            let field = |name: &str| format!("uavs[{i}].{name}");
            uav::check_uav_id(&u.id).map_err(|reason| invalid(field("id"), reason))?;
            if let Some(j) = ids.get(u.id.as_str()) {
                return Err(invalid(field("id"), format!("duplicate id `{}` (also uavs[{j}])", u.id)));
            }
            let start = check_point(&road, || field("start"), u.start, p.d_s)?;
            // The filter keeps every UAV D_s from the walls: a goal nearer to one is never reached.
            let goal = check_point(&road, || field("goal"), u.goal, p.d_s)?;
            if let Some(j) = starts.first_closer_than(&uavs, start) {
                let reason = format!("closer than D_c = {} m to uavs[{j}].start", p.d_c);
                return Err(invalid(field("start"), reason));
            }
            if let Some(link) = &u.link {
                links::check_link_with(link, rules).map_err(|reason| invalid(field("link"), reason))?;
            }
            ids.insert(&u.id, i);
            starts.insert(i, start);
            uavs.push(UavSpec { id: u.id.clone(), start, goal, link: u.link.clone() });
        }
        Ok(ValidScenario { name: self.name.clone(), params: self.params, road, uavs })
    }
}

/// The starts accepted so far, bucketed in square cells a little wider than D_c: every start closer
/// than D_c to a point is in the 3 × 3 cells around it. Accepted starts are D_c apart, so a cell
/// holds a handful.
struct StartGrid {
    d_c: f64,
    cell: f64,
    cells: HashMap<(i64, i64), Vec<usize>>,
}

impl StartGrid {
    fn new(d_c: f64) -> Self {
        // 0.1 % wider than D_c: a pair closer than D_c is then less than one cell apart on each axis
        // even after rounding, hence in neighbouring cells.
        Self { d_c, cell: d_c * 1.001, cells: HashMap::new() }
    }

    fn key(&self, x: Vec2) -> (i64, i64) {
        // Starts are inside the road (|x| ≤ 1e6 m) and D_c ≥ 1e-3 m: at most 1e9 cells per axis.
        ((x.x / self.cell).floor() as i64, (x.y / self.cell).floor() as i64)
    }

    fn insert(&mut self, i: usize, x: Vec2) {
        self.cells.entry(self.key(x)).or_default().push(i);
    }

    /// The lowest index among the accepted starts closer than D_c to `x`.
    fn first_closer_than(&self, uavs: &[UavSpec], x: Vec2) -> Option<usize> {
        let (cx, cy) = self.key(x);
        let near = (-1..=1).flat_map(|dx| (-1..=1).map(move |dy| (cx + dx, cy + dy)));
        near.filter_map(|k| self.cells.get(&k))
            .flatten()
            .copied()
            .filter(|&j| (uavs[j].start - x).norm() < self.d_c)
            .min()
    }
}

/// Checks that a point is finite, inside the road and at least `clearance` from every wall;
/// `field` names it in the error (built only then).
pub(crate) fn check_point(
    road: &Airspace,
    field: impl Fn() -> String,
    x: [f64; 2],
    clearance: f64,
) -> Result<Vec2, ScenarioError> {
    if !x[0].is_finite() || !x[1].is_finite() {
        return Err(invalid(field(), "must be two finite numbers"));
    }
    let v = Vec2::new(x[0], x[1]);
    let d = road.boundary_distance(&v);
    if d < 0.0 {
        return Err(invalid(field(), format!("[{}, {}] is outside the road", x[0], x[1])));
    }
    if d < clearance {
        return Err(invalid(
            field(),
            format!("[{}, {}] is {d:.3} m from a wall, closer than D_s = {clearance} m", x[0], x[1]),
        ));
    }
    Ok(v)
}
