//! The OpenAPI 3.1 document of the REST API, served at `GET /api/openapi.json` (the file is
//! `openapi.json` beside this one; a test checks that it lists exactly the router's routes).

/// The document, as served.
pub const DOCUMENT: &str = include_str!("openapi.json");

#[cfg(test)]
mod tests {
    use super::DOCUMENT;
    use std::collections::BTreeSet;

    const METHODS: [&str; 5] = ["get", "put", "post", "delete", "patch"];

    /// The (path, method) pairs of `api::router`, read from its source: an axum `Router` cannot
    /// list its routes, and each route there is one `.route("PATH", routing::M(h).M2(h2))` line.
    fn router_routes() -> BTreeSet<(String, String)> {
        let mut routes = BTreeSet::new();
        for line in include_str!("api.rs").lines().map(str::trim) {
            let Some(rest) = line.strip_prefix(".route(\"") else { continue };
            let path = rest.split('"').next().unwrap_or_default();
            for method in METHODS {
                if line.contains(&format!("routing::{method}(")) || line.contains(&format!(").{method}(")) {
                    routes.insert((path.to_owned(), method.to_owned()));
                }
            }
        }
        routes
    }

    #[test]
    fn the_document_lists_exactly_the_routers_routes() {
        let doc: serde_json::Value = serde_json::from_str(DOCUMENT).expect("openapi.json is JSON");
        let paths = doc["paths"].as_object().expect("a paths object");
        let documented: BTreeSet<(String, String)> = paths
            .iter()
            .flat_map(|(path, ops)| {
                let ops = ops.as_object().into_iter().flat_map(|o| o.keys());
                ops.filter(|m| METHODS.contains(&m.as_str())).map(move |m| (path.clone(), m.clone()))
            })
            .collect();
        let routes = router_routes();
        // The source parse found the router (it has 18 paths with 22 methods today).
        assert!(routes.len() >= 22, "{routes:?}");
        let undocumented: Vec<_> = routes.difference(&documented).collect();
        let unrouted: Vec<_> = documented.difference(&routes).collect();
        assert!(
            undocumented.is_empty() && unrouted.is_empty(),
            "undocumented {undocumented:?}, not routed {unrouted:?}"
        );
    }
}
