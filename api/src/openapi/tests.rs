use super::document;
use serde_json::Value;
use std::collections::BTreeSet;

fn refs<'v>(value: &'v Value, found: &mut Vec<&'v str>) {
    match value {
        Value::Object(map) => {
            if let Some(Value::String(r)) = map.get("$ref") {
                found.push(r);
            }
            map.values().for_each(|v| refs(v, found));
        }
        Value::Array(items) => items.iter().for_each(|v| refs(v, found)),
        _ => {}
    }
}

#[test]
fn every_reference_names_a_schema_of_the_document() {
    let doc = document();
    let mut found = Vec::new();
    refs(&doc, &mut found);
    assert!(found.len() > 40, "{} references", found.len());
    for r in found {
        let name =
            r.strip_prefix("#/components/schemas/").unwrap_or_else(|| panic!("{r} is not a component"));
        assert!(doc["components"]["schemas"].get(name).is_some(), "{r} names no schema");
    }
}

#[test]
fn every_operation_has_one_id_a_success_and_the_shared_refusals() {
    let doc = document();
    let mut ids = BTreeSet::new();
    for route in crate::routes::ROUTES {
        let op = &doc["paths"][route.path][route.verb.name()];
        assert!(ids.insert(op["operationId"].as_str().unwrap().to_string()), "{} twice", op["operationId"]);
        let statuses: Vec<&String> = op["responses"].as_object().unwrap().keys().collect();
        assert!(
            statuses.iter().any(|s| s.starts_with('2')),
            "{} {}: no success",
            route.verb.name(),
            route.path
        );
        for listener in ["414", "421", "431"] {
            assert!(statuses.contains(&&listener.to_string()), "{} lacks {listener}", route.path);
        }
        let change = route.verb != crate::routes::Verb::Get;
        assert_eq!(op.get("requestBody").is_some(), change, "{} {}", route.verb.name(), route.path);
        for guard in ["401", "403", "408", "411", "413", "415", "429", "503"] {
            assert_eq!(
                statuses.contains(&&guard.to_string()),
                change
                    || guard == "401" && route.path == "/api/audit"
                    || guard == "429" && route.path == "/api/audit"
                    || guard == "503" && matches!(route.path, "/healthz" | "/api/audit" | "/api/uavs/{id}"),
                "{} {} and {guard}",
                route.verb.name(),
                route.path
            );
        }
    }
}

#[test]
fn the_limits_the_validators_check_are_in_the_schemas() {
    let doc = document();
    let schemas = &doc["components"]["schemas"];
    for range in uav::PARAM_RANGES {
        let property = &schemas["Params"]["properties"][range.key];
        let low = if range.above_min { "exclusiveMinimum" } else { "minimum" };
        assert_eq!(property[low].as_f64(), Some(range.min), "{}", range.key);
        assert_eq!(property["maximum"].as_f64(), Some(range.max), "{}", range.key);
    }
    assert_eq!(schemas["Point"]["items"]["maximum"].as_f64(), Some(roads::MAX_COORDINATE_M));
    assert_eq!(schemas["Segments"]["maxItems"].as_u64(), Some(roads::MAX_SEGMENTS as u64));
    assert_eq!(schemas["RoadLayout"]["additionalProperties"], Value::Bool(false));
    assert_eq!(schemas["RoadLayout"]["required"], serde_json::json!(["segments"]));
    let new_uav = &schemas["NewUav"];
    assert_eq!(new_uav["required"], serde_json::json!(["id", "position"]));
    assert_eq!(new_uav["properties"]["id"]["$ref"], "#/components/schemas/UavId");
    assert_eq!(schemas["RerunSelection"]["properties"]["ids"]["maxItems"].as_u64(), Some(64));
}

#[test]
fn the_road_and_the_scenario_document_a_chain_and_a_network() {
    let doc = document();
    let schemas = &doc["components"]["schemas"];
    let body = &doc["paths"]["/api/road"]["put"]["requestBody"]["content"]["application/json"]["schema"];
    assert_eq!(body["$ref"], "#/components/schemas/RoadOrNetwork");
    let forms: Vec<&str> = schemas["RoadOrNetwork"]["anyOf"]
        .as_array()
        .unwrap()
        .iter()
        .map(|f| f["$ref"].as_str().unwrap())
        .collect();
    assert_eq!(forms, ["#/components/schemas/RoadLayout", "#/components/schemas/NetworkLayout"]);
    let network = &schemas["NetworkLayout"];
    assert_eq!(network["additionalProperties"], Value::Bool(false));
    assert_eq!(network["required"], serde_json::json!(["roads"]));
    assert!(
        network["properties"]["roads"]["description"].as_str().unwrap().contains("more than 20000 cells")
    );
    assert_eq!(schemas["SpeedLimit"]["maximum"].as_f64(), Some(roads::network::MAX_SPEED_LIMIT));
    assert_eq!(schemas["Junction"]["properties"]["polygon"]["minItems"].as_u64(), Some(3));
    // The geometry rules no schema states are in the 422 description.
    let refusal = doc["paths"]["/api/road"]["put"]["responses"]["422"]["description"].as_str().unwrap();
    for rule in [
        "duplicate_name",
        "shared_by_three",
        "partial_edge",
        "disconnected",
        "narrow_passage",
        "sharp_corner",
    ] {
        assert!(refusal.contains(rule), "{rule} is not documented: {refusal}");
    }
    // A scenario: `segments` without `roads`, or `roads` without `segments` and `regions`.
    let scenario = &schemas["Scenario"];
    let required: Vec<&Value> =
        scenario["anyOf"].as_array().unwrap().iter().map(|f| &f["required"]).collect();
    assert_eq!(required, [&serde_json::json!(["segments"]), &serde_json::json!(["roads"])]);
    assert!(scenario["properties"]["roads"].is_object() && scenario["properties"]["junctions"].is_object());
    assert!(!scenario["required"].as_array().unwrap().iter().any(|r| r == "segments"));
}

#[test]
fn the_stream_lists_every_status_at_its_number() {
    let doc = document();
    let codes = doc["x-websocket"]["status_codes"].as_array().unwrap();
    for status in engine::snapshot::UavStatus::ALL {
        let name = serde_json::to_value(status).unwrap();
        assert_eq!(codes[usize::from(engine::snapshot::status_code(status))], name);
    }
}
