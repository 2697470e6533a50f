//! End-to-end tests of the rate limit on wrong tokens against the real server on 127.0.0.1:0, as a
//! guesser would attack it: on the emergency stop and land routes (which must stay reachable for
//! the operator), from many addresses of one network, and from many networks (source addresses
//! across 127/8).

mod support;

use api::auth::{FAILURE_BURST, GLOBAL_FAILURE_BURST, GLOBAL_FAILURES_PER_SECOND};
use std::net::{IpAddr, SocketAddr};
use std::time::{Duration, Instant};
use support::{Running, Wire, request_text, small, start_with};
use tokio::io::{AsyncReadExt, AsyncWriteExt};

const TOKEN: &str = "s3cret-t0ken-for-tests";
const JSON: &str = "Content-Type: application/json";

/// Sends `request` from the local address `source` and reads the answer until the server closes.
async fn exchange_from(source: IpAddr, addr: SocketAddr, request: &[u8]) -> Wire {
    let socket = tokio::net::TcpSocket::new_v4().unwrap();
    socket.bind(SocketAddr::new(source, 0)).unwrap();
    let mut stream = socket.connect(addr).await.unwrap();
    stream.write_all(request).await.unwrap();
    let mut response = Vec::new();
    let read = tokio::time::timeout(Duration::from_secs(10), stream.read_to_end(&mut response)).await;
    assert!(read.is_ok(), "no complete answer within 10 s");
    let text = String::from_utf8_lossy(&response).into_owned();
    let Some((head, body)) = text.split_once("\r\n\r\n") else {
        return Wire { status: 0, headers: Vec::new(), body: text };
    };
    let status = head.split(' ').nth(1).and_then(|s| s.parse().ok()).unwrap_or(0);
    Wire { status, headers: Vec::new(), body: body.to_string() }
}

/// `POST path` with `Authorization: Bearer token` from `source`.
async fn post_from(server: &Running, source: &str, path: &str, token: &str) -> Wire {
    let host = format!("Host: {}", server.addr);
    let auth = format!("Authorization: Bearer {token}");
    let text = request_text("POST", path, &[&host, &auth, JSON], "");
    exchange_from(source.parse().unwrap(), server.addr, text.as_bytes()).await
}

/// How many of `codes` are `code`.
fn count(codes: &[u16], code: u16) -> usize {
    codes.iter().filter(|c| **c == code).count()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn wrong_tokens_on_the_stop_and_land_routes_are_rate_limited_too() {
    let server = start_with(&small(), |c| c.token = Some(TOKEN.into())).await;
    let land = "/api/uavs/NO-SUCH-UAV/land";
    let mut codes = Vec::new();
    for i in 0..FAILURE_BURST as usize {
        codes.push(post_from(&server, "127.0.0.1", land, &format!("wrong-{i}")).await.status);
    }
    assert_eq!(count(&codes, 401), codes.len(), "the burst: {codes:?}");
    // Then guesses: 429, the token looked at about once a second (a wrong one answered 401 only
    // with the attempt the network regains each second).
    let refused = |m: serde_json::Value| m["auth"]["refused"].as_u64().unwrap();
    let before = refused(server.get("/api/metrics").await);
    let started = Instant::now();
    let mut codes = Vec::new();
    for i in 0..300 {
        codes.push(post_from(&server, "127.0.0.1", land, &format!("guess-{i}")).await.status);
    }
    let seconds = started.elapsed().as_secs_f64();
    let looked_at = refused(server.get("/api/metrics").await) - before;
    assert!((looked_at as f64) <= seconds.ceil() + 1.0, "{looked_at} guesses looked at in {seconds} s");
    assert!(codes.iter().all(|c| *c == 401 || *c == 429), "{codes:?}");
    assert!((count(&codes, 401) as f64) <= seconds.ceil() + 1.0, "{codes:?} in {seconds} s");
    // The right token on the same route: checked at most once a second too (404: no such UAV)...
    let started = Instant::now();
    let mut codes = Vec::new();
    for _ in 0..100 {
        codes.push(post_from(&server, "127.0.0.1", land, TOKEN).await.status);
    }
    let seconds = started.elapsed().as_secs_f64();
    assert!(codes.iter().all(|c| *c == 404 || *c == 429), "{codes:?}");
    assert!((count(&codes, 404) as f64) <= seconds.ceil() + 1.0, "{codes:?} in {seconds} s");
    // ...so the operator's emergency stop gets through within a second.
    let started = Instant::now();
    loop {
        let w = post_from(&server, "127.0.0.1", "/api/fleet/stop", TOKEN).await;
        if w.status == 200 {
            break;
        }
        assert_eq!(w.status, 429, "{}", w.body);
        assert!(started.elapsed() < Duration::from_millis(1100), "the stop waited more than a second");
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn rotating_source_addresses_gains_nothing() {
    let server = start_with(&small(), |c| c.token = Some(TOKEN.into())).await;
    // Many addresses of one /24 share its allowance.
    let mut codes = Vec::new();
    for i in 1..=20 {
        codes.push(post_from(&server, &format!("127.0.0.{i}"), "/api/fleet/pause", "wrong").await.status);
    }
    assert_eq!(count(&codes[..FAILURE_BURST as usize], 401), FAILURE_BURST as usize, "{codes:?}");
    assert!(count(&codes, 429) >= 9, "one /24 is one client: {codes:?}");
    // Many /24s: one wrong token each, never exhausting their own allowance, until the global one
    // is empty: 429 without the token looked at.
    let started = Instant::now();
    let mut codes = Vec::new();
    for i in 1..=200 {
        let source = format!("127.{}.{}.1", i / 250 + 1, i % 250);
        codes.push(post_from(&server, &source, "/api/fleet/pause", "wrong").await.status);
    }
    let seconds = started.elapsed().as_secs_f64();
    assert!(codes.iter().all(|c| *c == 401 || *c == 429), "{codes:?}");
    let allowed = GLOBAL_FAILURE_BURST - FAILURE_BURST + GLOBAL_FAILURES_PER_SECOND * (seconds + 1.0);
    let looked_at = count(&codes, 401);
    assert!((looked_at as f64) <= allowed, "{looked_at} wrong tokens looked at in {seconds} s: {codes:?}");
    assert!(count(&codes, 429) >= 1, "{codes:?}");
    // Meanwhile the emergency stop from yet another network is checked, and passes.
    let w = post_from(&server, "127.9.9.9", "/api/fleet/stop", TOKEN).await;
    assert_eq!(w.status, 200, "{}", w.body);
    let auth = server.get("/api/metrics").await["auth"].clone();
    assert!(auth["rate_limited_global"].as_u64().unwrap() >= 1, "{auth}");
    assert!(auth["networks_tracked"].as_u64().unwrap() >= 2, "{auth}");
    server.stop().await;
}
