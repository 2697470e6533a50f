//! The OpenAPI 3.1 document of the REST API, served at `GET /api/openapi.json` (the file is
//! `openapi.json` beside this one; a test checks that it lists exactly the router's routes).

use axum::http::Method;
use std::sync::LazyLock;

/// The document, as served.
pub const DOCUMENT: &str = include_str!("openapi.json");

/// The document's operations: each path template's segments (`{id}` matches any one segment) with
/// its methods.
static OPERATIONS: LazyLock<Vec<(Vec<String>, Vec<Method>)>> = LazyLock::new(|| {
    // The document is the compiled-in file, which a test parses: it is always JSON with paths.
    let doc: serde_json::Value = serde_json::from_str(DOCUMENT).expect("openapi.json is JSON");
    let paths = doc["paths"].as_object().expect("openapi.json has paths");
    paths
        .iter()
        .map(|(path, ops)| {
            let segments = path.split('/').map(str::to_string).collect();
            let methods = ops
                .as_object()
                .into_iter()
                .flat_map(|o| o.keys())
                .filter_map(|m| Method::from_bytes(m.to_ascii_uppercase().as_bytes()).ok())
                .collect();
            (segments, methods)
        })
        .collect()
});

/// True when an operation of the document (and so a route: a test keeps them equal) takes `method`
/// on `path`.
pub fn takes(method: &Method, path: &str) -> bool {
    let asked: Vec<&str> = path.split('/').collect();
    OPERATIONS.iter().any(|(segments, methods)| {
        methods.contains(method)
            && segments.len() == asked.len()
            && segments.iter().zip(&asked).all(|(s, a)| s == a || (s.starts_with('{') && !a.is_empty()))
    })
}

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
    fn an_operation_is_found_by_its_method_and_path() {
        use axum::http::Method;
        assert!(super::takes(&Method::POST, "/api/fleet/stop"));
        assert!(super::takes(&Method::PUT, "/api/uavs/uav-1/goal"));
        assert!(super::takes(&Method::DELETE, "/api/uavs/x"));
        assert!(!super::takes(&Method::PUT, "/api/metrics"));
        assert!(!super::takes(&Method::POST, "/api/uavs//land"));
        assert!(!super::takes(&Method::POST, "/api/uavs/a/b/land"));
        assert!(!super::takes(&Method::PATCH, "/api/road"));
        assert!(!super::takes(&Method::POST, "/nowhere"));
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
