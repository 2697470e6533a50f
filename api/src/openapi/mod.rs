//! The OpenAPI 3.1 document of the REST API, served at `GET /api/openapi.json`, generated: its paths
//! are `routes::ROUTES`, each with its [`Doc`]; its schemas are derived from the types the handlers
//! take and answer (`schemars`, with the limits the validators check); the refusals every route
//! shares follow from its access, its body and its reach among regions ([`refusals`]).

pub mod docs;
mod refusals;
mod stream;

use crate::error::ErrorBody;
use crate::routes::{ROUTES, Route};
use schemars::generate::SchemaSettings;
use schemars::transform::{RecursiveTransform, Transform};
use schemars::{JsonSchema, Schema, SchemaGenerator};
use serde_json::{Map, Value, json};
use std::sync::LazyLock;

/// Writes the schema of a type into a generator's definitions and answers its reference.
pub type SchemaOf = fn(&mut SchemaGenerator) -> Schema;

/// The [`SchemaOf`] of `T`.
pub fn schema_of<T: JsonSchema>(generator: &mut SchemaGenerator) -> Schema {
    generator.subschema_for::<T>()
}

/// What a route's body is.
#[derive(Clone, Copy)]
pub enum Body {
    /// A read: none.
    None,
    /// A change without data: nothing, or `{}`, with `Content-Type: application/json`.
    Empty,
    /// A JSON document of this schema.
    Json(SchemaOf),
}

/// One answer of a route: its status, what it means, and its body's schema (None: no body).
#[derive(Clone, Copy)]
pub struct Answer {
    /// HTTP status.
    pub status: u16,
    /// What it means.
    pub description: &'static str,
    /// Its body (None: empty).
    pub schema: Option<SchemaOf>,
}

/// An answer with a body of `T`.
pub const fn answer(status: u16, description: &'static str, schema: SchemaOf) -> Answer {
    Answer { status, description, schema: Some(schema) }
}

/// An error answer (`{"error": ...}`) of a route.
pub const fn refusal(status: u16, description: &'static str) -> Answer {
    Answer { status, description, schema: Some(schema_of::<ErrorBody>) }
}

/// What the document says about one route beyond its method, path and access.
pub struct Doc {
    /// `operationId`.
    pub id: &'static str,
    /// One line.
    pub summary: &'static str,
    /// What the schemas cannot state (None: nothing).
    pub description: Option<&'static str>,
    /// Types whose fields are its query parameters.
    pub query: &'static [SchemaOf],
    /// Its body.
    pub body: Body,
    /// Its answers: the success first, then the refusals of its own (they replace the shared
    /// ones of the same status).
    pub answers: &'static [Answer],
}

/// The document as served.
pub fn text() -> &'static str {
    static TEXT: LazyLock<String> = LazyLock::new(|| document().to_string());
    &TEXT
}

/// The document.
pub fn document() -> Value {
    let settings = |s: SchemaSettings| {
        s.with(|s| s.definitions_path = "/components/schemas".into())
            .with_transform(RecursiveTransform(tidy as fn(&mut Schema)))
    };
    // Bodies are read (absent defaulted fields are optional); answers are written (skipped fields are).
    let mut bodies = settings(SchemaSettings::draft2020_12().for_deserialize()).into_generator();
    let mut answers = settings(SchemaSettings::draft2020_12().for_serialize()).into_generator();
    let mut paths = Map::new();
    for route in ROUTES {
        let operation = operation(route, &mut bodies, &mut answers);
        let item = paths.entry(route.path).or_insert_with(|| json!({}));
        item[route.verb.name()] = operation;
    }
    let mut schemas = answers.take_definitions(true);
    // A type both read and written (a road layout) keeps its body's schema: it also says which
    // members are refused, and what the server writes is within it.
    schemas.extend(bodies.take_definitions(true));
    json!({
        "openapi": "3.1.0",
        "info": {
            "title": "airroads ground-control API",
            "version": env!("CARGO_PKG_VERSION"),
            "description": INTRODUCTION,
        },
        "paths": paths,
        "components": {
            "schemas": schemas,
            "securitySchemes": {"bearer": {"type": "http", "scheme": "bearer"}},
        },
        "x-websocket": stream::description(),
    })
}

const INTRODUCTION: &str = "REST API of `airroads serve`. Every request must carry a `Host` the server listens on. Changes (POST, PUT, DELETE) need `Content-Type: application/json` (also without a body), no `Origin` but the server's own, and `Authorization: Bearer <token>` when the server has a token; reads are open except `/api/audit`. A 2xx answer to a change means it is applied and on disk. Errors are `{\"error\": {\"code\", \"message\", \"field\"?}}`. `GET /ws[?rate=HZ][&format=json|bin][&bbox=x0,y0,x1,y1]` streams the `GET /api/state` document as WebSocket text frames, or with `format=bin` the binary format of `x-websocket` (docs/streams.md, Binary stream); `bbox` (binary only) sends only the UAVs inside the viewport. Bad parameters answer the handshake with 422 naming the field.";

/// The operation object of `route`.
fn operation(route: &Route, bodies: &mut SchemaGenerator, answers: &mut SchemaGenerator) -> Value {
    let doc = route.doc;
    let mut op = json!({"operationId": doc.id, "summary": doc.summary});
    if let Some(description) = doc.description {
        op["description"] = description.into();
    }
    let mut parameters: Vec<Value> = Vec::new();
    if route.path.contains("{id}") {
        let id = uav::schema::UavId::json_schema(bodies);
        parameters.push(
            json!({"name": "id", "in": "path", "required": true, "schema": id, "description": "UAV id"}),
        );
    }
    for query in doc.query {
        parameters.extend(query_parameters(query(bodies), bodies));
    }
    if !parameters.is_empty() {
        op["parameters"] = parameters.into();
    }
    match doc.body {
        Body::None => {}
        Body::Empty => {
            op["requestBody"] = json!({
                "required": true,
                "description": "the empty object `{}`, sent with `Content-Type: application/json` like every change (an empty body with that content type is accepted too)",
                "content": {"application/json": {"schema": {"type": "object", "maxProperties": 0}}},
            });
        }
        Body::Json(schema) => {
            op["requestBody"] =
                json!({"required": true, "content": {"application/json": {"schema": schema(bodies)}}});
        }
    }
    let mut responses = Map::new();
    for answer in refusals::shared(route).iter().chain(doc.answers) {
        let mut response = json!({"description": answer.description});
        if let Some(schema) = answer.schema {
            response["content"] = json!({"application/json": {"schema": schema(answers)}});
        }
        responses.insert(answer.status.to_string(), response);
    }
    op["responses"] = responses.into();
    op
}

/// The query parameters of an object schema: one per property (the schema `$ref`erenced is looked
/// up and taken out of the generator's definitions: the parameters are the document's, not the
/// object).
fn query_parameters(schema: Schema, generator: &mut SchemaGenerator) -> Vec<Value> {
    let object = match schema.get("$ref").and_then(Value::as_str) {
        Some(reference) => {
            let name = reference.rsplit('/').next().unwrap_or_default();
            generator.definitions_mut().remove(name).unwrap_or_default()
        }
        None => schema.to_value(),
    };
    let mut object = Schema::try_from(object).unwrap_or_default();
    RecursiveTransform(tidy).transform(&mut object);
    let object = object.to_value();
    let required: Vec<&str> =
        object["required"].as_array().into_iter().flatten().filter_map(Value::as_str).collect();
    let Some(properties) = object["properties"].as_object() else { return Vec::new() };
    properties
        .iter()
        .map(|(name, property)| {
            let mut schema = property.clone();
            let description = schema.as_object_mut().and_then(|s| s.remove("description"));
            // An absent parameter is how a query says "none": the schema is the present value's.
            let schema = present(schema);
            let mut parameter = json!({"name": name, "in": "query", "required": required.contains(&name.as_str()), "schema": schema});
            if let Some(description) = description {
                parameter["description"] = description;
            }
            parameter
        })
        .collect()
}

/// Makes a schema derived from Rust read as the document's: a doc comment's line breaks joined
/// (paragraphs kept), its intra-doc links as plain code, and Rust's unsigned formats (`uint64`, no
/// format of OpenAPI's) dropped, their `minimum` saying it.
fn tidy(schema: &mut Schema) {
    if let Some(Value::String(text)) = schema.get_mut("description") {
        let paragraphs: Vec<String> =
            text.split("\n\n").map(|p| p.split('\n').collect::<Vec<_>>().join(" ")).collect();
        *text = paragraphs.join("\n\n").replace("[`", "`").replace("`]", "`");
    }
    if schema.get("format").and_then(Value::as_str).is_some_and(|f| f.starts_with("uint")) {
        schema.remove("format");
    }
}

/// The schema of an optional value when it is there: `null` taken out of its type or alternatives.
fn present(mut schema: Value) -> Value {
    if let Some(types) = schema.get_mut("type").and_then(Value::as_array_mut) {
        types.retain(|t| t != "null");
        if let [only] = &types[..] {
            schema["type"] = only.clone();
        }
    }
    for key in ["anyOf", "oneOf"] {
        if let Some(options) = schema.get_mut(key).and_then(Value::as_array_mut) {
            options.retain(|o| o.get("type") != Some(&json!("null")));
            if let [only] = &options[..] {
                let only = only.clone();
                let object = schema.as_object_mut().expect("it had anyOf or oneOf, so it is an object");
                object.remove(key);
                if let Some(fields) = only.as_object() {
                    object.extend(fields.clone());
                }
            }
        }
    }
    schema
}

#[cfg(test)]
mod tests;
