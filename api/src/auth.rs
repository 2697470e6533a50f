//! Access control: when a token is configured, every request that may change something (any method
//! but GET, HEAD and OPTIONS) and `GET /api/audit` need `Authorization: Bearer <token>`; other reads
//! stay open.
//!
//! Wrong (or missing) tokens are rate-limited twice, on every route:
//! - per client *network* (IPv4 /24, IPv6 /64: rotating source addresses inside one network gains
//!   nothing): a burst of [`FAILURE_BURST`], refilled at [`FAILURES_PER_SECOND`];
//! - for all clients together: a burst of [`GLOBAL_FAILURE_BURST`], refilled at
//!   [`GLOBAL_FAILURES_PER_SECOND`] (many networks gain nothing either).
//!
//! A request whose network's bucket, or the global one, is empty is rate-limited: on an ordinary
//! route it gets 429 without its token being looked at (while the global bucket is empty, that is
//! every client's ordinary changes: the price of a bound on guessing from many networks). On the
//! emergency stop and land routes its token is still checked, but only [`SAFETY_CHECK_EVERY`] after
//! the network's last check (the operator's stop gets through at most that much later, a guesser
//! learns one answer per second); beyond that, 429 without looking. A wrong token checked while the
//! network is rate-limited is answered 429, never 401: 401 only within the allowance (the burst,
//! then the attempt regained each second).

use super::error::ApiError;
use super::guard::is_change;
use super::routes::Access;
use super::state::AppState;
use axum::extract::{Request, State};
use axum::http::{HeaderValue, Method, StatusCode, header};
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};
use std::collections::HashMap;
use std::net::{IpAddr, Ipv4Addr, Ipv6Addr};
use std::sync::atomic::{AtomicU64, Ordering::Relaxed};
use std::sync::{Mutex, PoisonError};
use std::time::{Duration, Instant};

/// Wrong tokens a client network may send at once.
pub const FAILURE_BURST: f64 = 10.0;
/// Wrong tokens a client network regains per second.
pub const FAILURES_PER_SECOND: f64 = 1.0;
/// Wrong tokens all clients together may send at once.
pub const GLOBAL_FAILURE_BURST: f64 = 100.0;
/// Wrong tokens all clients together regain per second.
pub const GLOBAL_FAILURES_PER_SECOND: f64 = 10.0;
/// Prefix length of the network an IPv4 client is counted in.
pub const IPV4_NETWORK_BITS: u32 = 24;
/// Prefix length of the network an IPv6 client is counted in.
pub const IPV6_NETWORK_BITS: u32 = 64;
/// On the stop and land routes, a rate-limited network's token is checked at most this often.
pub const SAFETY_CHECK_EVERY: Duration = Duration::from_secs(1);
/// Fewest characters of a token given at start.
pub const MIN_TOKEN_CHARS: usize = 16;
/// Most characters of a token given at start.
pub const MAX_TOKEN_CHARS: usize = 256;
/// Client networks tracked; the least suspicious ones are forgotten beyond this.
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

/// Checks a token given on the command line or in `AIRROADS_TOKEN`: [`MIN_TOKEN_CHARS`] to
/// [`MAX_TOKEN_CHARS`] characters that can travel in a bearer header unchanged (RFC 6750: letters,
/// digits and `-._~+/`, then `=` padding).
pub fn check_token(token: &str) -> Result<(), String> {
    let body = token.trim_end_matches('=');
    let travels = !body.is_empty()
        && body
            .bytes()
            .all(|b| b.is_ascii_alphanumeric() || matches!(b, b'-' | b'.' | b'_' | b'~' | b'+' | b'/'));
    if !travels {
        return Err(format!(
            "must be {MIN_TOKEN_CHARS} to {MAX_TOKEN_CHARS} characters from A-Z, a-z, 0-9, -._~+/ \
             (then = padding); no spaces"
        ));
    }
    // Only ASCII is left: bytes are characters.
    match token.len() {
        n if n < MIN_TOKEN_CHARS => Err(format!(
            "is {n} characters; at least {MIN_TOKEN_CHARS} are needed (random ones: a short token can \
             be guessed)"
        )),
        n if n > MAX_TOKEN_CHARS => Err(format!("is {n} characters; at most {MAX_TOKEN_CHARS} are accepted")),
        _ => Ok(()),
    }
}

/// The network a client address is counted in (IPv4 /24, IPv6 /64; an IPv4-mapped IPv6 address as
/// its IPv4 address).
pub fn network(ip: IpAddr) -> IpAddr {
    match ip {
        IpAddr::V4(v4) => {
            let mask = u32::MAX.checked_shl(32 - IPV4_NETWORK_BITS.min(32)).unwrap_or(0);
            IpAddr::V4(Ipv4Addr::from(u32::from(v4) & mask))
        }
        IpAddr::V6(v6) => match v6.to_ipv4_mapped() {
            Some(v4) => network(IpAddr::V4(v4)),
            None => {
                let mask = u128::MAX.checked_shl(128 - IPV6_NETWORK_BITS.min(128)).unwrap_or(0);
                IpAddr::V6(Ipv6Addr::from(u128::from(v6) & mask))
            }
        },
    }
}

/// A token bucket of wrong tokens.
#[derive(Debug, Clone, Copy)]
struct Bucket {
    left: f64,
    at: Instant,
}

impl Bucket {
    fn full(burst: f64, now: Instant) -> Self {
        Self { left: burst, at: now }
    }

    /// Attempts left at `now`.
    fn level(&self, now: Instant, burst: f64, rate: f64) -> f64 {
        (self.left + now.saturating_duration_since(self.at).as_secs_f64() * rate).min(burst)
    }

    /// Takes one attempt (never below empty: a network regains its first attempt one refill after
    /// it stops failing).
    fn take(&mut self, now: Instant, burst: f64, rate: f64) {
        self.left = (self.level(now, burst, rate) - 1.0).max(0.0);
        self.at = now;
    }
}

/// What is known about one client network.
#[derive(Debug, Clone, Copy)]
struct Network {
    bucket: Bucket,
    /// When its token was last checked (a rate-limited one is checked on the stop and land routes
    /// only a second after that).
    checked: Option<Instant>,
}

impl Network {
    fn new(now: Instant) -> Self {
        Self { bucket: Bucket::full(FAILURE_BURST, now), checked: None }
    }

    fn level(&self, now: Instant) -> f64 {
        self.bucket.level(now, FAILURE_BURST, FAILURES_PER_SECOND)
    }
}

#[derive(Debug)]
struct Buckets {
    networks: HashMap<IpAddr, Network>,
    global: Bucket,
}

impl Buckets {
    /// The entry of `net`, made room for among the tracked ones.
    fn entry(&mut self, net: IpAddr, now: Instant) -> &mut Network {
        if self.networks.len() >= TRACKED && !self.networks.contains_key(&net) {
            // Forget the network that has the most attempts left (the least suspicious).
            let forget = self
                .networks
                .iter()
                .max_by(|a, b| a.1.level(now).total_cmp(&b.1.level(now)))
                .map(|(n, _)| *n);
            if let Some(forget) = forget {
                self.networks.remove(&forget);
            }
        }
        self.networks.entry(net).or_insert_with(|| Network::new(now))
    }

    fn global_level(&self, now: Instant) -> f64 {
        self.global.level(now, GLOBAL_FAILURE_BURST, GLOBAL_FAILURES_PER_SECOND)
    }
}

/// What the token check does with a request (see the module documentation).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Admission {
    /// Check the token; `limited`: the client is rate-limited (a wrong token gets 429, not 401).
    Check {
        /// The client's network, or every client, has no attempt left.
        limited: bool,
    },
    /// 429 without looking at the token; `global`: because the global bucket is empty.
    Refuse {
        /// Refused for the global bucket (the client's network has attempts left).
        global: bool,
    },
}

/// Wrong tokens per client network and for all clients (token buckets).
#[derive(Debug)]
pub struct AuthFailures {
    buckets: Mutex<Buckets>,
    /// Requests refused for a missing or wrong token.
    pub refused: AtomicU64,
    /// Requests refused with 429 without looking at the token.
    pub rate_limited: AtomicU64,
    /// Of those, refused because the global bucket was empty (the network had attempts left).
    pub rate_limited_global: AtomicU64,
    /// Tokens checked on a stop or land route while their client was rate-limited.
    pub safety_checks: AtomicU64,
}

impl Default for AuthFailures {
    fn default() -> Self {
        let buckets =
            Buckets { networks: HashMap::new(), global: Bucket::full(GLOBAL_FAILURE_BURST, Instant::now()) };
        Self {
            buckets: Mutex::new(buckets),
            refused: AtomicU64::default(),
            rate_limited: AtomicU64::default(),
            rate_limited_global: AtomicU64::default(),
            safety_checks: AtomicU64::default(),
        }
    }
}

impl AuthFailures {
    fn lock(&self) -> std::sync::MutexGuard<'_, Buckets> {
        self.buckets.lock().unwrap_or_else(PoisonError::into_inner)
    }

    /// Whether a request from `ip` (to a stop or land route: `safety`) has its token checked at
    /// `now`; a check granted to a rate-limited client on a safety route uses up its network's
    /// check for [`SAFETY_CHECK_EVERY`].
    pub fn admit(&self, ip: IpAddr, safety: bool, now: Instant) -> Admission {
        let net = network(ip);
        let mut buckets = self.lock();
        let own_empty = buckets.networks.get(&net).is_some_and(|n| n.level(now) < 1.0);
        let global_empty = buckets.global_level(now) < 1.0;
        if !own_empty && !global_empty {
            // A network that failed before: its next safety check is a second after this one, so
            // it never gets more than one answer per second once its burst is spent.
            if let Some(known) = buckets.networks.get_mut(&net) {
                known.checked = Some(now);
            }
            return Admission::Check { limited: false };
        }
        if safety {
            let entry = buckets.entry(net, now);
            if entry.checked.is_none_or(|at| now.saturating_duration_since(at) >= SAFETY_CHECK_EVERY) {
                entry.checked = Some(now);
                self.safety_checks.fetch_add(1, Relaxed);
                return Admission::Check { limited: true };
            }
        }
        Admission::Refuse { global: !own_empty }
    }

    /// True when `ip`'s network has no wrong token left now (the global bucket aside).
    pub fn exhausted(&self, ip: IpAddr) -> bool {
        let now = Instant::now();
        self.lock().networks.get(&network(ip)).is_some_and(|n| n.level(now) < 1.0)
    }

    /// Counts a wrong token of `ip` at `now`, against its network and against all clients.
    pub fn fail(&self, ip: IpAddr, now: Instant) {
        let mut buckets = self.lock();
        buckets.entry(network(ip), now).bucket.take(now, FAILURE_BURST, FAILURES_PER_SECOND);
        buckets.global.take(now, GLOBAL_FAILURE_BURST, GLOBAL_FAILURES_PER_SECOND);
    }

    /// The `auth` object of `/api/metrics`.
    pub fn report(&self) -> AuthReport {
        let now = Instant::now();
        let buckets = self.lock();
        let limited = buckets.networks.values().filter(|n| n.level(now) < 1.0).count();
        AuthReport {
            refused: self.refused.load(Relaxed),
            rate_limited: self.rate_limited.load(Relaxed),
            rate_limited_global: self.rate_limited_global.load(Relaxed),
            safety_checks: self.safety_checks.load(Relaxed),
            networks_tracked: buckets.networks.len(),
            networks_limited: limited,
            global_left: buckets.global_level(now).floor(),
            global_limited: buckets.global_level(now) < 1.0,
        }
    }
}

/// `auth` of `GET /api/metrics`.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, schemars::JsonSchema)]
pub struct AuthReport {
    /// Requests refused for a missing or wrong token.
    pub refused: u64,
    /// Requests refused (429) because their network, or everyone, failed too often.
    pub rate_limited: u64,
    /// Of those, refused because every network together failed too often.
    pub rate_limited_global: u64,
    /// Token checks granted to a rate-limited network on the stop and land routes.
    pub safety_checks: u64,
    /// Networks with failures remembered.
    pub networks_tracked: usize,
    /// Networks rate-limited now.
    pub networks_limited: usize,
    /// Failures everyone together may still make now.
    pub global_left: f64,
    /// Everyone is rate-limited now.
    pub global_limited: bool,
}

/// The routes an operator must always reach with the right token (land and stop: the route
/// table's [`Access::Urgent`]).
pub fn safety_route(method: &Method, path: &str) -> bool {
    super::routes::find(method, path).is_some_and(|(route, _)| route.access == Access::Urgent)
}

fn too_many() -> Response {
    let mut response = ApiError::new(
        StatusCode::TOO_MANY_REQUESTS,
        "too_many_auth_failures",
        "too many requests with a wrong token from this network (or from everywhere); wait and try again",
    )
    .field("Authorization")
    .into_response();
    response.headers_mut().insert(header::RETRY_AFTER, HeaderValue::from_static("1"));
    response
}

/// Middleware refusing unauthenticated changes with 401 (429 when rate-limited).
pub async fn require_token(State(app): State<AppState>, request: Request, next: Next) -> Response {
    let ip = super::listener::remote(&request).map(|a| a.ip());
    let given = request.headers().get(header::AUTHORIZATION);
    match refusal(&app, ip, request.method(), request.uri().path(), given) {
        None => next.run(request).await,
        Some(refused) => refused,
    }
}

/// The token check of a request `method path` from `ip` carrying `given` (a request another region
/// forwarded is checked here too, with the operator's address): its refusal, or None to go on.
pub fn refusal(
    app: &AppState,
    ip: Option<IpAddr>,
    method: &Method,
    path: &str,
    given: Option<&HeaderValue>,
) -> Option<Response> {
    let Some(token) = &app.token else { return None };
    let private = super::routes::find(method, path).is_some_and(|(r, _)| r.access == Access::PrivateRead);
    if !is_change(method) && !private {
        return None;
    }
    let ip = ip.unwrap_or(IpAddr::V4(Ipv4Addr::UNSPECIFIED));
    let failures = &app.auth_failures;
    let limited = match failures.admit(ip, safety_route(method, path), Instant::now()) {
        Admission::Check { limited } => limited,
        Admission::Refuse { global } => {
            failures.rate_limited.fetch_add(1, Relaxed);
            if global {
                failures.rate_limited_global.fetch_add(1, Relaxed);
            }
            return Some(too_many());
        }
    };
    if authorised(given, token) {
        return None;
    }
    failures.fail(ip, Instant::now());
    failures.refused.fetch_add(1, Relaxed);
    if limited {
        return Some(too_many());
    }
    if failures.exhausted(ip) {
        tracing::warn!(
            "{ip}: too many requests with a wrong token; refusing its network's changes for a while"
        );
    }
    let mut response = ApiError::new(
        StatusCode::UNAUTHORIZED,
        "unauthorized",
        "this server needs `Authorization: Bearer <token>` for changes",
    )
    .field("Authorization")
    .into_response();
    response.headers_mut().insert(header::WWW_AUTHENTICATE, HeaderValue::from_static("Bearer"));
    Some(response)
}

#[cfg(test)]
mod tests {
    use super::*;

    const TOKEN: &str = "s3cret-t0ken-for-tests";

    fn ip(text: &str) -> IpAddr {
        text.parse().unwrap_or_else(|e| panic!("{text}: {e}"))
    }

    #[test]
    fn only_the_exact_bearer_token_passes() {
        let ok = HeaderValue::from_static("Bearer s3cret-t0ken-for-tests");
        assert!(authorised(Some(&ok), TOKEN));
        assert!(authorised(Some(&HeaderValue::from_static("bearer s3cret-t0ken-for-tests")), TOKEN));
        for bad in [
            "Bearer s3cret-t0ken-for-test",
            "Bearer s3cret-t0ken-for-tests2",
            "Basic s3cret-t0ken-for-tests",
            "s3cret-t0ken-for-tests",
            "Bearer ",
        ] {
            assert!(!authorised(Some(&HeaderValue::from_static(bad)), TOKEN), "{bad}");
        }
        assert!(!authorised(None, TOKEN));
    }

    #[test]
    fn tokens_that_are_short_or_cannot_travel_in_a_header_are_refused() {
        for ok in [TOKEN, "a-b.c_d~e+f/g0123==", &"x".repeat(16), &"x".repeat(256)] {
            assert!(check_token(ok).is_ok(), "{ok}");
        }
        for bad in [
            "",
            " s3cret-t0ken-for-tests",
            "s3cret-t0ken-for-tests ",
            "sé cret-t0ken-for-tests",
            "tab\tbed-t0ken-for-tests",
            "================",
            "a\"b-t0ken-for-tests",
            &"x".repeat(257),
        ] {
            assert!(check_token(bad).is_err(), "{bad:?}");
        }
        // Too short, however well formed: the message names the minimum.
        for short in ["s3cret", "x", &"x".repeat(15), "abcdefghijklm=="] {
            let e = check_token(short).expect_err(short);
            assert!(e.contains("at least 16"), "{short}: {e}");
        }
    }

    #[test]
    fn clients_are_counted_by_network() {
        assert_eq!(network(ip("10.1.2.3")), ip("10.1.2.0"));
        assert_eq!(network(ip("::ffff:10.1.2.3")), ip("10.1.2.0"));
        assert_eq!(network(ip("2001:db8:1:2:3:4:5:6")), ip("2001:db8:1:2::"));
        let failures = AuthFailures::default();
        let now = Instant::now();
        for i in 0..FAILURE_BURST as u8 {
            assert!(!failures.exhausted(ip(&format!("10.0.0.{i}"))));
            failures.fail(ip(&format!("10.0.0.{i}")), now);
        }
        // Every address of that /24 is exhausted; the next /24 is not.
        assert!(failures.exhausted(ip("10.0.0.200")));
        assert!(!failures.exhausted(ip("10.0.1.1")));
        assert_eq!(failures.admit(ip("10.0.0.77"), false, now), Admission::Refuse { global: false });
        assert_eq!(failures.admit(ip("10.0.1.1"), false, now), Admission::Check { limited: false });
        assert!(safety_route(&Method::POST, "/api/fleet/stop"));
        assert!(
            safety_route(&Method::POST, "/api/fleet/land")
                && safety_route(&Method::POST, "/api/uavs/cf1/land")
        );
        assert!(
            !safety_route(&Method::PUT, "/api/uavs/cf1/goal")
                && !safety_route(&Method::GET, "/api/fleet/stop")
        );
    }

    #[test]
    fn a_limited_network_gets_one_check_per_second_on_the_safety_routes() {
        let failures = AuthFailures::default();
        let now = Instant::now();
        let a = ip("192.168.7.9");
        for _ in 0..FAILURE_BURST as usize {
            failures.fail(a, now);
        }
        // Never checked before: at once.
        assert_eq!(failures.admit(a, true, now), Admission::Check { limited: true });
        assert_eq!(failures.admit(a, true, now), Admission::Refuse { global: false });
        let later = now + Duration::from_millis(999);
        assert_eq!(failures.admit(a, true, later), Admission::Refuse { global: false });
        let second = now + SAFETY_CHECK_EVERY;
        // A second later the network has one attempt again: checked as an ordinary client, which
        // also counts as its check of that second.
        assert_eq!(failures.admit(a, true, second), Admission::Check { limited: false });
        failures.fail(a, second);
        assert_eq!(failures.admit(a, true, second), Admission::Refuse { global: false });
        // A network checked as an ordinary client just before its burst ran out waits a second too.
        let b = ip("192.168.8.9");
        for _ in 0..FAILURE_BURST as usize {
            assert_eq!(failures.admit(b, true, now), Admission::Check { limited: false });
            failures.fail(b, now);
        }
        assert_eq!(failures.admit(b, true, now), Admission::Refuse { global: false });
        let half = now + SAFETY_CHECK_EVERY / 2;
        assert_eq!(failures.admit(b, true, half), Admission::Refuse { global: false });
    }

    #[test]
    fn the_global_bucket_limits_many_networks_together() {
        let failures = AuthFailures::default();
        let now = Instant::now();
        // Two failures from each of 50 networks: none exhausted, the global bucket is.
        for i in 0..(GLOBAL_FAILURE_BURST as usize / 2) {
            let client = ip(&format!("127.{i}.1.1"));
            assert_eq!(failures.admit(client, false, now), Admission::Check { limited: false });
            failures.fail(client, now);
            failures.fail(client, now);
        }
        let fresh = ip("127.200.0.1");
        assert_eq!(failures.admit(fresh, false, now), Admission::Refuse { global: true });
        // The stop route still checks, once per second per network.
        assert_eq!(failures.admit(fresh, true, now), Admission::Check { limited: true });
        assert_eq!(failures.admit(fresh, true, now), Admission::Refuse { global: true });
        // It refills at its rate: an attempt after 1/rate seconds.
        let later = now + Duration::from_secs_f64(1.5 / GLOBAL_FAILURES_PER_SECOND);
        assert_eq!(failures.admit(ip("127.201.0.1"), false, later), Admission::Check { limited: false });
        assert_eq!(failures.report().networks_tracked, 51);
    }
}
