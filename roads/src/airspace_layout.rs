//! The layout of what a fleet flies as users write it: a chain layout (`{"segments", "regions"?}`)
//! or a network layout (`{"roads", "junctions"?}`), the body of `PUT /api/road` and what
//! `GET /api/road` gives back.

use crate::airspace::Airspace;
use crate::layout::RoadLayout;
use crate::network::{Network, NetworkLayout};
use crate::regions::Region;
use crate::road::Road;
use crate::validate::RoadError;
use schemars::{JsonSchema, Schema, SchemaGenerator, json_schema};
use serde::{Deserialize, Serialize};
use std::borrow::Cow;

/// A chain layout or a network layout; in JSON either object as it is (no tag: a network is the
/// object with `roads`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum AirspaceLayout {
    /// One road: `{"segments": [...], "regions"?: [...]}`.
    Road(RoadLayout),
    /// A network: `{"roads": [...], "junctions"?: [...]}`.
    Network(NetworkLayout),
}

impl From<RoadLayout> for AirspaceLayout {
    fn from(layout: RoadLayout) -> Self {
        AirspaceLayout::Road(layout)
    }
}

impl From<NetworkLayout> for AirspaceLayout {
    fn from(layout: NetworkLayout) -> Self {
        AirspaceLayout::Network(layout)
    }
}

impl AirspaceLayout {
    /// The chain layout, when it is one.
    pub fn road(&self) -> Option<&RoadLayout> {
        match self {
            AirspaceLayout::Road(layout) => Some(layout),
            AirspaceLayout::Network(_) => None,
        }
    }

    /// The network layout, when it is one.
    pub fn network(&self) -> Option<&NetworkLayout> {
        match self {
            AirspaceLayout::Road(_) => None,
            AirspaceLayout::Network(layout) => Some(layout),
        }
    }

    /// The regions of a chain layout (a network's are [`NetworkLayout::regions`]).
    pub fn regions(&self) -> Option<&[Region]> {
        self.road().and_then(|l| l.regions.as_deref())
    }

    /// The names of its regions (a chain's or a network's) in the layout's order; none when it is
    /// not divided.
    pub fn region_names(&self) -> Vec<&str> {
        match self {
            AirspaceLayout::Road(layout) => {
                layout.regions.iter().flatten().map(|r| r.name.as_str()).collect()
            }
            AirspaceLayout::Network(layout) => {
                layout.regions.iter().flatten().map(|r| r.name.as_str()).collect()
            }
        }
    }

    /// Its cells: a chain's segments, or a network's segments and junctions.
    pub fn cell_count(&self) -> usize {
        match self {
            AirspaceLayout::Road(layout) => layout.segments.len(),
            AirspaceLayout::Network(layout) => {
                layout.roads.iter().map(|r| r.segments.len()).sum::<usize>() + layout.junctions.len()
            }
        }
    }

    /// Validates it: a chain as [`Road::new`] does, a network as [`Network::new`] does with
    /// passages at least `min_passage_m` wide (O(n log n) either way).
    pub fn build(self, min_passage_m: f64) -> Result<Airspace, RoadError> {
        Ok(match self {
            AirspaceLayout::Road(layout) => Airspace::Road(Road::new(layout)?),
            AirspaceLayout::Network(layout) => Airspace::Network(Network::new(layout, min_passage_m)?),
        })
    }
}

impl Airspace {
    /// The layout it was built from.
    pub fn layout(&self) -> AirspaceLayout {
        match self {
            Airspace::Road(road) => AirspaceLayout::Road(road.layout().clone()),
            Airspace::Network(net) => AirspaceLayout::Network(net.layout().clone()),
        }
    }
}

impl JsonSchema for AirspaceLayout {
    fn schema_name() -> Cow<'static, str> {
        "RoadOrNetwork".into()
    }

    fn json_schema(generator: &mut SchemaGenerator) -> Schema {
        json_schema!({
            "anyOf": [generator.subschema_for::<RoadLayout>(), generator.subschema_for::<NetworkLayout>()],
            "description": "one road (a chain layout: `segments`, optional `regions`: segment ranges) or a road network (`roads`, optional `junctions` and `regions`: sets of cells)"
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn either_form_reads_back_as_written() {
        let chain = AirspaceLayout::Road(RoadLayout::straight(0.0, 10.0, 4.0, 2));
        let text = serde_json::to_string(&chain).unwrap();
        assert!(text.starts_with("{\"segments\""), "{text}");
        assert_eq!(serde_json::from_str::<AirspaceLayout>(&text).unwrap(), chain);
        let network = AirspaceLayout::Network(NetworkLayout::from(&RoadLayout::straight(0.0, 10.0, 4.0, 2)));
        let text = serde_json::to_string(&network).unwrap();
        assert!(text.starts_with("{\"roads\""), "{text}");
        assert_eq!(serde_json::from_str::<AirspaceLayout>(&text).unwrap(), network);
        assert_eq!(network.cell_count(), 2);
        assert!(network.regions().is_none());
        assert!(network.clone().build(1.0).unwrap().network().is_some());
        // A chain whose `roads` key would make it neither form is refused.
        assert!(serde_json::from_str::<AirspaceLayout>("{\"segments\": [], \"roads\": []}").is_err());
    }
}
