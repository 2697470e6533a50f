//! The `regions` of a scenario: a chain road's segment ranges (`{"name", "segments"}`) or a road
//! network's sets of cells (`{"name", "roads"?, "junctions"?}`), told apart by their keys.

use roads::Region;
use roads::network::NetworkRegion;
use schemars::{JsonSchema, Schema, SchemaGenerator, json_schema};
use serde::{Deserialize, Serialize};
use std::borrow::Cow;

/// A scenario's regions, as its road's layout takes them.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(untagged)]
pub enum ScenarioRegions {
    /// A chain road's: named segment ranges.
    Road(Vec<Region>),
    /// A network's: named sets of cells.
    Network(Vec<NetworkRegion>),
}

impl<'de> Deserialize<'de> for ScenarioRegions {
    /// A list whose entries all have `segments` is a chain's (the empty list too), any other a
    /// network's; each is then read with its own type's messages (unknown keys refused).
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let entries = Vec::<serde_json::Value>::deserialize(d)?;
        let chain = entries.iter().all(|r| r.get("segments").is_some());
        let list = serde_json::Value::Array(entries);
        let read = if chain {
            serde_json::from_value(list).map(ScenarioRegions::Road)
        } else {
            serde_json::from_value(list).map(ScenarioRegions::Network)
        };
        // The path (`regions`) names the field; the message is serde's own, as for any other field.
        read.map_err(serde::de::Error::custom)
    }
}

impl JsonSchema for ScenarioRegions {
    fn schema_name() -> Cow<'static, str> {
        "ScenarioRegions".into()
    }

    fn json_schema(generator: &mut SchemaGenerator) -> Schema {
        json_schema!({
            "anyOf": [
                generator.subschema_for::<roads::schema::Regions>(),
                generator.subschema_for::<roads::schema::NetworkRegions>()
            ],
            "description": "as in the layout of the scenario's road: segment ranges (`segments`) on one road, sets of cells (`roads`, `junctions`) on a network"
        })
    }
}

impl ScenarioRegions {
    /// A chain road's, when they are (an empty list is either).
    pub fn road(&self) -> Option<Vec<Region>> {
        match self {
            ScenarioRegions::Road(list) => Some(list.clone()),
            ScenarioRegions::Network(list) => list.is_empty().then(Vec::new),
        }
    }

    /// A network's, when they are (an empty list is either).
    pub fn network(&self) -> Option<Vec<NetworkRegion>> {
        match self {
            ScenarioRegions::Network(list) => Some(list.clone()),
            ScenarioRegions::Road(list) => list.is_empty().then(Vec::new),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_list_is_read_as_a_chains_or_a_networks_by_its_keys() {
        let chain: ScenarioRegions = serde_json::from_str(r#"[{"name": "a", "segments": [0, 1]}]"#).unwrap();
        assert!(matches!(&chain, ScenarioRegions::Road(r) if r[0].segments == [0, 1]));
        assert!(chain.network().is_none());
        let text = r#"[{"name": "a", "roads": [{"road": "t", "segments": [0, 1]}]}, {"name": "b", "junctions": ["j"]}]"#;
        let net: ScenarioRegions = serde_json::from_str(text).unwrap();
        assert!(matches!(&net, ScenarioRegions::Network(r) if r[1].junctions == ["j"]));
        assert!(net.road().is_none());
        assert_eq!(
            serde_json::from_str::<ScenarioRegions>(&serde_json::to_string(&net).unwrap()).unwrap(),
            net
        );
        // Unknown keys are refused with the type's own message.
        let e = serde_json::from_str::<ScenarioRegions>(r#"[{"name": "a", "segments": [0, 1], "x": 1}]"#);
        assert!(e.unwrap_err().to_string().contains("unknown field `x`"));
        let e = serde_json::from_str::<ScenarioRegions>(r#"[{"name": "a", "roads": [], "cells": 1}]"#);
        assert!(e.unwrap_err().to_string().contains("unknown field `cells`"));
        // A whole number written with a fraction: serde's own message, first (as the API's fuzzing
        // hooks recognise it, tests/schemathesis/hooks.py).
        let text = r#"[{"name": "a", "roads": [{"road": "t", "segments": [0, 3.0]}]}]"#;
        let e = serde_json::from_str::<ScenarioRegions>(text).unwrap_err().to_string();
        assert!(e.starts_with("invalid type: floating point `3.0`, expected usize"), "{e}");
    }
}
