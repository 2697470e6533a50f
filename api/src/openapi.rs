//! The OpenAPI 3.1 document of the REST API, served at `GET /api/openapi.json` (the file is
//! `openapi.json` beside this one; a test checks that it lists exactly the routes of
//! `routes::ROUTES`, from which the router is built).

/// The document, as served.
pub const DOCUMENT: &str = include_str!("openapi.json");

#[cfg(test)]
mod tests {
    use super::DOCUMENT;
    use std::collections::BTreeSet;

    const METHODS: [&str; 5] = ["get", "put", "post", "delete", "patch"];

    #[test]
    fn the_document_lists_exactly_the_route_tables_routes() {
        let doc: serde_json::Value = serde_json::from_str(DOCUMENT).expect("openapi.json is JSON");
        let paths = doc["paths"].as_object().expect("a paths object");
        let documented: BTreeSet<(String, String)> = paths
            .iter()
            .flat_map(|(path, ops)| {
                let ops = ops.as_object().into_iter().flat_map(|o| o.keys());
                ops.filter(|m| METHODS.contains(&m.as_str())).map(move |m| (path.clone(), m.clone()))
            })
            .collect();
        let routes: BTreeSet<(String, String)> =
            crate::routes::ROUTES.iter().map(|r| (r.path.to_string(), r.verb.name().to_string())).collect();
        let undocumented: Vec<_> = routes.difference(&documented).collect();
        let unrouted: Vec<_> = documented.difference(&routes).collect();
        assert!(
            undocumented.is_empty() && unrouted.is_empty(),
            "undocumented {undocumented:?}, not routed {unrouted:?}"
        );
    }
}
