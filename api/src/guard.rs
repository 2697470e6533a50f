//! What every request passes before a handler sees it (docs/security.md):
//! - a request line and head of bounded size (414/431 with a JSON body);
//! - a `Host` that names the server, whatever its port (an IP literal of its address, any IP
//!   literal when it listens on all addresses, `localhost` on loopback, or `--allow-host`), which
//!   defeats DNS rebinding;
//! - for every change (any method but GET, HEAD, OPTIONS) and for `/ws`: no `Origin` but the server's
//!   own or `--allow-origin`, and no `Sec-Fetch-Site: cross-site`, so no page on another origin can
//!   act on the server; every change must also say `Content-Type: application/json` (a browser sends
//!   that cross-origin only after a CORS preflight, which this server never grants);
//! - a body with a declared length within the limit and within the budget of bodies in flight;
//! - on a reserve connection (taken when every ordinary one is busy, see [`super::listener`]), only
//!   the emergency stop and land routes (`503 busy` otherwise).
//!
//! The outermost layer ([`finish`]) turns a panic into a 500, gives every error a JSON body, and
//! adds the security headers (no framing, a strict content policy).

use super::error::{ApiError, MAX_BODY_BYTES};
use super::state::AppState;
use axum::extract::{Request, State};
use axum::http::{HeaderMap, HeaderValue, Method, StatusCode, header};
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};
use futures_util::FutureExt as _;
use std::net::{IpAddr, SocketAddr};
use std::panic::AssertUnwindSafe;
use std::sync::Arc;

/// Longest request target (path and query) answered normally; longer ones get 414.
pub const MAX_URI_BYTES: usize = 8 << 10;
/// Most header lines; more get 431.
pub const MAX_HEADER_LINES: usize = 100;
/// Most header bytes (names and values); more get 431.
pub const MAX_HEADER_BYTES: usize = 32 << 10;
/// Request bodies in flight at once (bytes): larger uploads wait for none, they get 503.
pub const BODY_BUDGET_BYTES: usize = 32 << 20;

/// Which `Host` and `Origin` values the server accepts (its own, plus the allow-lists).
#[derive(Debug, Clone, PartialEq)]
pub struct AccessRules {
    /// The address the server listens on.
    pub listen: SocketAddr,
    /// Extra `Host` values (`--allow-host`, e.g. a reverse proxy's name), `name` or `name:port`.
    pub hosts: Vec<String>,
    /// Extra origins allowed to make changes and open `/ws` (`--allow-origin`).
    pub origins: Vec<String>,
}

/// `name` and port of a `Host` value (`[v6]:port` keeps its brackets); None when malformed.
fn split_host(host: &str) -> Option<(&str, Option<u16>)> {
    let (name, port) = match host.rfind(':') {
        Some(i) if !host[i..].contains(']') => (&host[..i], Some(host[i + 1..].parse().ok()?)),
        _ => (host, None),
    };
    let valid = !name.is_empty()
        && name
            .bytes()
            .all(|b| b.is_ascii_alphanumeric() || matches!(b, b'.' | b'-' | b'_' | b'[' | b']' | b':'));
    valid.then_some((name, port))
}

impl AccessRules {
    /// The rules of a server listening on `listen` with the given allow-lists (lower-cased).
    pub fn new(listen: SocketAddr, hosts: &[String], origins: &[String]) -> Self {
        let lower = |v: &[String]| v.iter().map(|s| s.trim().to_ascii_lowercase()).collect();
        Self { listen, hosts: lower(hosts), origins: lower(origins) }
    }

    /// True when `host` (a `Host` header value) names this server. DNS rebinding is about the
    /// name, so the port is not compared (a container or a port forward publishes the server on
    /// another port than it listens on), except with an `--allow-host NAME:PORT` that gives one.
    pub fn host_allowed(&self, host: &str) -> bool {
        let host = host.trim().to_ascii_lowercase();
        let Some((name, port)) = split_host(&host) else {
            return false;
        };
        let listed = self
            .hosts
            .iter()
            .filter_map(|h| split_host(h))
            .any(|(n, p)| n == name && (p.is_none() || p == port));
        if listed {
            return true;
        }
        let ip = self.listen.ip();
        if name == "localhost" {
            return ip.is_loopback() || ip.is_unspecified();
        }
        // An IP literal cannot be rebound to another address by DNS.
        match name.trim_start_matches('[').trim_end_matches(']').parse::<IpAddr>() {
            Ok(literal) => ip.is_unspecified() || literal == ip,
            Err(_) => false,
        }
    }

    /// True when a request with this `Origin`, sent to `host`, comes from the server's own pages or
    /// an allowed origin.
    pub fn origin_allowed(&self, origin: &str, host: &str) -> bool {
        let origin = origin.trim().to_ascii_lowercase();
        if self.origins.contains(&origin) {
            return true;
        }
        let Some((scheme, authority)) = origin.split_once("://") else {
            return false;
        };
        let default = match scheme {
            "http" => 80,
            "https" => 443,
            _ => return false,
        };
        let host = host.trim().to_ascii_lowercase();
        match (split_host(authority), split_host(&host)) {
            (Some((on, op)), Some((hn, hp))) => on == hn && op.unwrap_or(default) == hp.unwrap_or(default),
            _ => false,
        }
    }
}

fn forbidden(code: &'static str, field: &str, message: String) -> Response {
    ApiError::new(StatusCode::FORBIDDEN, code, message).field(field).into_response()
}

/// True for methods that may change something (every route that changes takes one of these; any
/// other method, TRACE or an invented one, reaches no handler and is answered 405 by the router).
pub fn is_change(method: &Method) -> bool {
    matches!(*method, Method::POST | Method::PUT | Method::DELETE | Method::PATCH)
}

fn header_size(headers: &HeaderMap) -> usize {
    headers.iter().map(|(k, v)| k.as_str().len() + v.len() + 4).sum()
}

/// The checks of the module documentation, in that order.
pub async fn check(State(app): State<AppState>, request: Request, next: Next) -> Response {
    let uri_len = request.uri().path_and_query().map_or(0, |p| p.as_str().len());
    if uri_len > MAX_URI_BYTES {
        let message = format!("the request target is {uri_len} bytes, at most {MAX_URI_BYTES} are accepted");
        return ApiError::new(StatusCode::URI_TOO_LONG, "uri_too_long", message).into_response();
    }
    let headers = request.headers();
    if headers.len() > MAX_HEADER_LINES || header_size(headers) > MAX_HEADER_BYTES {
        let message =
            format!("at most {MAX_HEADER_LINES} header lines and {MAX_HEADER_BYTES} bytes of headers");
        return ApiError::new(StatusCode::REQUEST_HEADER_FIELDS_TOO_LARGE, "headers_too_large", message)
            .into_response();
    }
    if request.extensions().get::<super::listener::Reserved>().is_some()
        && !super::auth::safety_route(request.method(), request.uri().path())
    {
        return ApiError::busy(
            "every connection is taken; this one serves only the emergency stop and land routes",
        )
        .into_response();
    }
    let Some(rules) = app.access.get() else {
        return ApiError::new(StatusCode::SERVICE_UNAVAILABLE, "starting", "the server is starting")
            .into_response();
    };
    let host = headers.get(header::HOST).and_then(|h| h.to_str().ok()).unwrap_or("");
    if !rules.host_allowed(host) {
        let message = format!(
            "`Host: {host}` does not name this server (listening on {}); add it with --allow-host",
            rules.listen
        );
        return ApiError::new(StatusCode::MISDIRECTED_REQUEST, "host_not_allowed", message)
            .field("Host")
            .into_response();
    }
    let change = is_change(request.method());
    let stream = request.uri().path() == "/ws";
    if change || stream {
        if let Some(origin) = headers.get(header::ORIGIN) {
            let origin = origin.to_str().unwrap_or("null");
            if !rules.origin_allowed(origin, host) {
                let message = format!(
                    "requests from `{origin}` may not change anything here; add it with --allow-origin"
                );
                return forbidden("origin_not_allowed", "Origin", message);
            }
        } else if headers.get("sec-fetch-site").is_some_and(|s| s.as_bytes() == b"cross-site") {
            return forbidden(
                "origin_not_allowed",
                "Origin",
                "a cross-site request may not change anything".into(),
            );
        }
    }
    // A change no route takes gets the router's 404 or 405, not an error about its content.
    if !change || super::routes::find(request.method(), request.uri().path()).is_none() {
        return next.run(request).await;
    }
    if !super::error::is_json(headers) {
        return ApiError::new(
            StatusCode::UNSUPPORTED_MEDIA_TYPE,
            "unsupported_media_type",
            "every change must say `Content-Type: application/json`, also without a body",
        )
        .into_response();
    }
    if headers.contains_key(header::TRANSFER_ENCODING) {
        return ApiError::new(
            StatusCode::LENGTH_REQUIRED,
            "length_required",
            "send the body with a Content-Length",
        )
        .into_response();
    }
    let length = headers
        .get(header::CONTENT_LENGTH)
        .and_then(|v| v.to_str().ok())
        .and_then(|v| v.parse::<usize>().ok())
        .unwrap_or(0);
    if length > MAX_BODY_BYTES {
        let message = format!("the body is {length} bytes, at most {MAX_BODY_BYTES} are accepted");
        return ApiError::new(StatusCode::PAYLOAD_TOO_LARGE, "body_too_large", message).into_response();
    }
    // Bodies in flight share a budget (permits of 1 KiB): many slow uploads cannot take the memory.
    let permits = u32::try_from(length.div_ceil(1024)).unwrap_or(u32::MAX);
    let _permit = if permits > 0 {
        match Arc::clone(&app.body_budget).try_acquire_many_owned(permits) {
            Ok(permit) => Some(permit),
            Err(_) => {
                return ApiError::new(
                    StatusCode::SERVICE_UNAVAILABLE,
                    "busy",
                    "too many request bodies are being received; try again",
                )
                .into_response();
            }
        }
    } else {
        None
    };
    next.run(request).await
}

const CSP: &str = "default-src 'self'; script-src 'self'; style-src 'self'; img-src 'self' data:; \
                   connect-src 'self'; frame-ancestors 'none'; base-uri 'none'; form-action 'none'";

/// The outermost layer: a panic becomes a 500 (logged), every error without a body gets the API's
/// JSON error body, and every response the security headers.
pub async fn finish(request: Request, next: Next) -> Response {
    let (method, path) = (request.method().clone(), request.uri().path().to_string());
    let mut response = match AssertUnwindSafe(next.run(request)).catch_unwind().await {
        Ok(response) => response,
        Err(_) => {
            tracing::error!("{method} {path}: the handler panicked");
            ApiError::new(
                StatusCode::INTERNAL_SERVER_ERROR,
                "internal_error",
                "the server failed on this request",
            )
            .into_response()
        }
    };
    let status = response.status();
    if status.as_u16() >= 400 && !response.headers().contains_key(header::CONTENT_TYPE) {
        let reason = status.canonical_reason().unwrap_or("error");
        let code = match status {
            StatusCode::METHOD_NOT_ALLOWED => "method_not_allowed",
            StatusCode::NOT_FOUND => "not_found",
            _ => "http_error",
        };
        let mut json = ApiError::new(status, code, format!("{reason}: {method} {path}")).into_response();
        for (name, value) in response.headers() {
            if name != header::CONTENT_LENGTH {
                json.headers_mut().insert(name.clone(), value.clone());
            }
        }
        response = json;
    }
    let headers = response.headers_mut();
    headers.insert(header::X_FRAME_OPTIONS, HeaderValue::from_static("DENY"));
    headers.insert(header::CONTENT_SECURITY_POLICY, HeaderValue::from_static(CSP));
    headers.insert(header::X_CONTENT_TYPE_OPTIONS, HeaderValue::from_static("nosniff"));
    headers.insert(header::REFERRER_POLICY, HeaderValue::from_static("no-referrer"));
    headers.insert("cross-origin-resource-policy", HeaderValue::from_static("same-origin"));
    response
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rules(listen: &str) -> AccessRules {
        AccessRules::new(
            listen.parse().unwrap(),
            &["ops.example.com".into()],
            &["https://ops.example.com".into()],
        )
    }

    #[test]
    fn hosts_the_server_listens_on_and_nothing_else() {
        let r = rules("127.0.0.1:8080");
        for ok in [
            "127.0.0.1:8080",
            "localhost:8080",
            "LOCALHOST:8080",
            "ops.example.com",
            "ops.example.com:443",
            // Published on another port (a container's `-p 127.0.0.1:18180:8080`, a port forward).
            "127.0.0.1:18180",
            "localhost:18180",
            "127.0.0.1",
            "localhost",
        ] {
            assert!(r.host_allowed(ok), "{ok}");
        }
        for bad in [
            "evil.example:8080",
            "evil.example",
            "rebind.evil.example:18180",
            "10.0.0.1:8080",
            "127.0.0.2:8080",
            "",
            "localhost:80x",
            "a b:8080",
        ] {
            assert!(!r.host_allowed(bad), "{bad}");
        }
        // An allowed name with a port given is held to it.
        let with_port =
            AccessRules::new("127.0.0.1:8080".parse().unwrap(), &["ops.example.com:8443".into()], &[]);
        assert!(with_port.host_allowed("ops.example.com:8443"));
        assert!(!with_port.host_allowed("ops.example.com:9443"));
        // In a container: listening on every address, published on another port.
        let any = rules("0.0.0.0:8080");
        for ok in ["192.168.1.20", "[fe80::1]:80", "localhost", "127.0.0.1:18180", "localhost:18180"] {
            assert!(any.host_allowed(ok), "{ok}");
        }
        assert!(!any.host_allowed("rebind.evil.example") && !any.host_allowed("rebind.evil.example:8080"));
        let v6 = rules("[::1]:9000");
        assert!(v6.host_allowed("[::1]:9000") && v6.host_allowed("localhost:9000"));
        assert!(v6.host_allowed("[::1]:19000") && v6.host_allowed("localhost:19000"));
        assert!(!v6.host_allowed("127.0.0.1:9000"));
        // Not on loopback: `localhost` is not this server's name.
        let lan = rules("192.168.1.5:8080");
        assert!(lan.host_allowed("192.168.1.5:18080") && !lan.host_allowed("localhost:8080"));
    }

    #[test]
    fn only_the_own_origin_and_allowed_ones() {
        let r = rules("127.0.0.1:8080");
        assert!(r.origin_allowed("http://127.0.0.1:8080", "127.0.0.1:8080"));
        assert!(r.origin_allowed("http://localhost:8080", "localhost:8080"));
        assert!(r.origin_allowed("https://ops.example.com", "127.0.0.1:8080"));
        assert!(r.origin_allowed("http://ops.example.com", "ops.example.com"));
        for (origin, host) in [
            ("http://evil.example", "127.0.0.1:8080"),
            ("null", "127.0.0.1:8080"),
            ("http://localhost:8080", "127.0.0.1:8080"),
            ("http://127.0.0.1:8081", "127.0.0.1:8080"),
            ("file://", "127.0.0.1:8080"),
            ("", "127.0.0.1:8080"),
        ] {
            assert!(!r.origin_allowed(origin, host), "{origin} → {host}");
        }
    }
}
