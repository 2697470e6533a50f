//! Access control: when a token is configured, every request that may change something (any method
//! but GET, HEAD and OPTIONS) and `GET /api/audit` need `Authorization: Bearer <token>`; other reads
//! stay open. Failed attempts are rate-limited per client address: beyond a burst of
//! [`FAILURE_BURST`] (refilled at [`FAILURES_PER_SECOND`]) a client gets 429 without its token being
//! looked at, except on the emergency stop and land routes, where a correct token always passes.

use super::error::ApiError;
use super::guard::is_change;
use super::state::AppState;
use axum::extract::{Request, State};
use axum::http::{HeaderValue, StatusCode, header};
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};
use std::collections::HashMap;
use std::net::{IpAddr, Ipv4Addr};
use std::sync::atomic::{AtomicU64, Ordering::Relaxed};
use std::sync::{Mutex, PoisonError};
use std::time::Instant;

/// Failed attempts a client may make at once.
pub const FAILURE_BURST: f64 = 10.0;
/// Failed attempts a client regains per second.
pub const FAILURES_PER_SECOND: f64 = 1.0;
/// Client addresses tracked; the least recently failing ones are forgotten beyond this.
const TRACKED: usize = 4096;

/// Compares in time independent of where the strings differ (no early exit on the first byte).
fn same(a: &[u8], b: &[u8]) -> bool {
    a.len() == b.len() && a.iter().zip(b).fold(0u8, |acc, (x, y)| acc | (x ^ y)) == 0
}

/// True when `value` is `Bearer <token>`.
pub fn authorised(value: Option<&HeaderValue>, token: &str) -> bool {
    let Some(value) = value.and_then(|v| v.to_str().ok()) else {
        return false;
    };
    let Some((scheme, given)) = value.split_once(' ') else {
        return false;
    };
    scheme.eq_ignore_ascii_case("bearer") && same(given.trim().as_bytes(), token.as_bytes())
}

/// Checks a token given on the command line or in `AIRROADS_TOKEN`: 1 to 256 characters that can
/// travel in a bearer header unchanged (RFC 6750: letters, digits and `-._~+/`, then `=` padding).
pub fn check_token(token: &str) -> Result<(), String> {
    let body = token.trim_end_matches('=');
    let ok = (1..=256).contains(&token.len())
        && !body.is_empty()
        && body
            .bytes()
            .all(|b| b.is_ascii_alphanumeric() || matches!(b, b'-' | b'.' | b'_' | b'~' | b'+' | b'/'));
    if ok {
        Ok(())
    } else {
        Err("must be 1 to 256 characters from A-Z, a-z, 0-9, -._~+/ (then = padding); no spaces".into())
    }
}

#[derive(Debug, Clone, Copy)]
struct Allowance {
    left: f64,
    at: Instant,
}

/// Failed authentication attempts per client address (a token bucket each).
#[derive(Debug, Default)]
pub struct AuthFailures {
    buckets: Mutex<HashMap<IpAddr, Allowance>>,
    /// Requests refused for a missing or wrong token.
    pub refused: AtomicU64,
    /// Requests refused with 429 without looking at the token.
    pub rate_limited: AtomicU64,
}

impl AuthFailures {
    fn allowance(&self, ip: IpAddr, now: Instant) -> f64 {
        let buckets = self.buckets.lock().unwrap_or_else(PoisonError::into_inner);
        buckets.get(&ip).map_or(FAILURE_BURST, |a| {
            (a.left + now.duration_since(a.at).as_secs_f64() * FAILURES_PER_SECOND).min(FAILURE_BURST)
        })
    }

    /// True when `ip` has no failed attempt left now.
    pub fn exhausted(&self, ip: IpAddr) -> bool {
        self.allowance(ip, Instant::now()) < 1.0
    }

    /// Counts a failed attempt of `ip`.
    pub fn fail(&self, ip: IpAddr) {
        let now = Instant::now();
        let left = self.allowance(ip, now) - 1.0;
        let mut buckets = self.buckets.lock().unwrap_or_else(PoisonError::into_inner);
        if buckets.len() >= TRACKED && !buckets.contains_key(&ip) {
            // Forget the address that has the most attempts left (the least suspicious).
            let forget = buckets.iter().max_by(|a, b| a.1.left.total_cmp(&b.1.left)).map(|(ip, _)| *ip);
            if let Some(forget) = forget {
                buckets.remove(&forget);
            }
        }
        buckets.insert(ip, Allowance { left, at: now });
    }
}

/// The routes an operator must always reach with the right token.
fn safety_route(path: &str) -> bool {
    path == "/api/fleet/stop"
        || path == "/api/fleet/land"
        || (path.starts_with("/api/uavs/") && path.ends_with("/land"))
}

/// Middleware refusing unauthenticated changes with 401 (429 when the client failed too often).
pub async fn require_token(State(app): State<AppState>, request: Request, next: Next) -> Response {
    let Some(token) = &app.token else {
        return next.run(request).await;
    };
    let path = request.uri().path();
    if !is_change(request.method()) && path != "/api/audit" {
        return next.run(request).await;
    }
    let ip = super::listener::remote(&request).map_or(IpAddr::V4(Ipv4Addr::UNSPECIFIED), |a| a.ip());
    let failures = &app.auth_failures;
    if !safety_route(path) && failures.exhausted(ip) {
        failures.rate_limited.fetch_add(1, Relaxed);
        let mut response = ApiError::new(
            StatusCode::TOO_MANY_REQUESTS,
            "too_many_auth_failures",
            "too many requests with a wrong token from this address; wait and try again",
        )
        .into_response();
        response.headers_mut().insert(header::RETRY_AFTER, HeaderValue::from_static("1"));
        return response;
    }
    if authorised(request.headers().get(header::AUTHORIZATION), token) {
        return next.run(request).await;
    }
    failures.fail(ip);
    failures.refused.fetch_add(1, Relaxed);
    if failures.exhausted(ip) {
        tracing::warn!("{ip}: too many requests with a wrong token; refusing its changes for a while");
    }
    let mut response = ApiError::new(
        StatusCode::UNAUTHORIZED,
        "unauthorized",
        "this server needs `Authorization: Bearer <token>` for changes",
    )
    .into_response();
    response.headers_mut().insert(header::WWW_AUTHENTICATE, HeaderValue::from_static("Bearer"));
    response
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_the_exact_bearer_token_passes() {
        let ok = HeaderValue::from_static("Bearer s3cret");
        assert!(authorised(Some(&ok), "s3cret"));
        assert!(authorised(Some(&HeaderValue::from_static("bearer s3cret")), "s3cret"));
        for bad in ["Bearer s3cre", "Bearer s3cret2", "Basic s3cret", "s3cret", "Bearer "] {
            assert!(!authorised(Some(&HeaderValue::from_static(bad)), "s3cret"), "{bad}");
        }
        assert!(!authorised(None, "s3cret"));
    }

    #[test]
    fn tokens_that_cannot_travel_in_a_header_are_refused() {
        for ok in ["s3cret", "a-b.c_d~e+f/g==", &"x".repeat(256)] {
            assert!(check_token(ok).is_ok(), "{ok}");
        }
        for bad in ["", " s3cret", "s3cret ", "sé cret", "tab\tbed", "==", "a\"b", &"x".repeat(257)] {
            assert!(check_token(bad).is_err(), "{bad:?}");
        }
    }

    #[test]
    fn failures_beyond_the_burst_exhaust_an_address_only() {
        let failures = AuthFailures::default();
        let (a, b): (IpAddr, IpAddr) = ("10.0.0.1".parse().unwrap(), "10.0.0.2".parse().unwrap());
        for _ in 0..FAILURE_BURST as usize {
            assert!(!failures.exhausted(a));
            failures.fail(a);
        }
        assert!(failures.exhausted(a));
        assert!(!failures.exhausted(b));
        assert!(safety_route("/api/fleet/stop") && safety_route("/api/uavs/cf1/land"));
        assert!(!safety_route("/api/uavs/cf1/goal"));
    }
}
