//! The OpenAPI 3.1 document of the REST API, served at `GET /api/openapi.json` (the file is
//! `openapi.json` beside this one; a test checks that it lists exactly the router's routes).

/// The document, as served.
pub const DOCUMENT: &str = include_str!("openapi.json");
