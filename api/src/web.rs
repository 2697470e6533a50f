//! The browser dashboard (`web/` at the repository root), embedded in the binary and served at `/`.
//! Every file is listed here explicitly; a test checks that the list matches the directory.

use axum::Router;
use axum::http::header;
use axum::response::IntoResponse;
use axum::routing::get;

/// One embedded file: its URL path (without the leading `/`), content type and bytes.
struct Asset {
    name: &'static str,
    content_type: &'static str,
    body: &'static str,
}

macro_rules! asset {
    ($name:literal, $type:expr) => {
        Asset { name: $name, content_type: $type, body: include_str!(concat!("../../web/", $name)) }
    };
}

const JS: &str = "text/javascript; charset=utf-8";

const ASSETS: &[Asset] = &[
    asset!("index.html", "text/html; charset=utf-8"),
    asset!("style.css", "text/css; charset=utf-8"),
    asset!("app.js", JS),
    asset!("api.js", JS),
    asset!("stream.js", JS),
    asset!("binary.js", JS),
    asset!("camera.js", JS),
    asset!("geometry.js", JS),
    asset!("editor.js", JS),
    asset!("trails.js", JS),
    asset!("render.js", JS),
    asset!("plot.js", JS),
    asset!("input.js", JS),
    asset!("controls.js", JS),
    asset!("details.js", JS),
];

fn route(asset: &'static Asset) -> axum::routing::MethodRouter<super::state::AppState> {
    // `no-cache`: the browser revalidates, so a new binary's dashboard is picked up at once.
    get(move || async move {
        ([(header::CONTENT_TYPE, asset.content_type), (header::CACHE_CONTROL, "no-cache")], asset.body)
            .into_response()
    })
}

/// `/` (the page) and `/<file>` for every embedded file; other paths fall through to the JSON 404.
pub fn router() -> Router<super::state::AppState> {
    let mut router = Router::new();
    for asset in ASSETS {
        if asset.name == "index.html" {
            router = router.route("/", route(asset));
        }
        router = router.route(&format!("/{}", asset.name), route(asset));
    }
    router
}

#[cfg(test)]
mod tests {
    use super::ASSETS;

    #[test]
    fn every_file_of_web_is_embedded_once() {
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../web");
        let mut on_disk: Vec<String> = std::fs::read_dir(&dir)
            .expect("web/")
            .map(|e| e.expect("entry").file_name().to_string_lossy().into_owned())
            .collect();
        let mut embedded: Vec<String> = ASSETS.iter().map(|a| a.name.to_string()).collect();
        on_disk.sort();
        embedded.sort();
        assert_eq!(embedded, on_disk, "list every file of web/ in api/src/web.rs (and nothing else)");
    }

    #[test]
    fn modules_import_only_embedded_files() {
        for asset in ASSETS.iter().filter(|a| a.name.ends_with(".js")) {
            // Every module specifier, wherever the import statement breaks its lines.
            let specifiers = ["from \"./", "import \"./"].map(|m| asset.body.split(m).skip(1));
            for rest in specifiers.into_iter().flatten() {
                let target = rest.split('"').next().unwrap_or("");
                assert!(
                    ASSETS.iter().any(|a| a.name == target),
                    "{}: imports `{target}`, not embedded",
                    asset.name
                );
            }
        }
    }
}
