//! End-to-end tests of the bounds on what clients can hold, against the real server: slow and idle
//! sockets, half-sent bodies, oversized WebSocket messages and too many stream clients. In every
//! case the emergency stop stays reachable.

mod support;

use futures_util::SinkExt;
use std::time::{Duration, Instant};
use support::{Running, exchange, request_text, small, start_with};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::TcpStream;

/// `POST /api/fleet/stop` must answer 200 within `within`.
async fn stop_within(server: &Running, within: Duration) {
    let started = Instant::now();
    let text = request_text(
        "POST",
        "/api/fleet/stop",
        &[&format!("Host: {}", server.addr), "Content-Type: application/json"],
        "",
    );
    let w = tokio::time::timeout(within, exchange(server.addr, text.as_bytes()))
        .await
        .unwrap_or_else(|_| panic!("the emergency stop did not answer within {within:?}"));
    assert_eq!(w.status, 200, "{}", w.body);
    assert!(started.elapsed() < within);
}

/// A socket that sent the start of a request head and then nothing (a slowloris client).
async fn slowloris(addr: std::net::SocketAddr) -> TcpStream {
    let mut s = TcpStream::connect(addr).await.unwrap();
    s.write_all(format!("GET /api/state HTTP/1.1\r\nHost: {addr}\r\nX-Slow: ").as_bytes()).await.unwrap();
    s
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn slow_and_idle_sockets_cannot_lock_the_operator_out() {
    let server = start_with(&small(), |c| {
        c.limits.max_connections = 16;
        c.limits.header_timeout = Duration::from_secs(60);
    })
    .await;
    let mut held = Vec::new();
    for i in 0..40 {
        if i % 2 == 0 {
            held.push(slowloris(server.addr).await);
        } else {
            held.push(TcpStream::connect(server.addr).await.unwrap());
        }
    }
    tokio::time::sleep(Duration::from_millis(200)).await;
    stop_within(&server, Duration::from_secs(5)).await;
    let metrics = server.get("/api/metrics").await;
    let connections = &metrics["connections"];
    assert!(connections["open"].as_u64().unwrap() <= 16, "{connections}");
    assert!(connections["evicted"].as_u64().unwrap() >= 24, "{connections}");
    drop(held);
    server.stop().await;
}

/// One request (`Connection: close`) that must be answered `want` within `within`.
async fn answered_within(
    server: &Running,
    method: &str,
    path: &str,
    headers: &[&str],
    want: u16,
    within: Duration,
) {
    let host = format!("Host: {}", server.addr);
    let mut all = vec![host.as_str(), "Content-Type: application/json"];
    all.extend_from_slice(headers);
    let text = request_text(method, path, &all, "");
    let w = tokio::time::timeout(within, exchange(server.addr, text.as_bytes()))
        .await
        .unwrap_or_else(|_| panic!("{method} {path} did not answer within {within:?}"));
    assert_eq!(w.status, want, "{method} {path}: {}", w.body);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn slow_bodies_sent_with_the_token_cannot_lock_the_operator_out() {
    const TOKEN: &str = "s3cret-t0ken-for-tests";
    let server = start_with(&small(), |c| {
        c.token = Some(TOKEN.into());
        c.limits.max_connections = 16;
    })
    .await;
    let auth = format!("Authorization: Bearer {TOKEN}");
    // 40 uploads with the token that send their head and the first byte of a 100 KB body, then
    // nothing more: more than every connection.
    let mut held = Vec::new();
    for _ in 0..40 {
        let Ok(mut s) = TcpStream::connect(server.addr).await else { continue };
        let head = format!(
            "PUT /api/road HTTP/1.1\r\nHost: {}\r\n{auth}\r\nContent-Type: application/json\r\nContent-Length: 100000\r\n\r\n{{",
            server.addr
        );
        let _ = s.write_all(head.as_bytes()).await;
        held.push(s);
    }
    tokio::time::sleep(Duration::from_millis(100)).await;
    // The operator's stop, five times in the next two seconds (before and after the bodies are
    // a second old): answered every time, each within a second.
    for _ in 0..5 {
        answered_within(&server, "POST", "/api/fleet/stop", &[&auth], 200, Duration::from_secs(1)).await;
        tokio::time::sleep(Duration::from_millis(400)).await;
    }
    // Bodies slower than a second give way to any new connection once every one is taken.
    answered_within(&server, "GET", "/api/state", &[], 200, Duration::from_secs(1)).await;
    let metrics = server.get("/api/metrics").await;
    let connections = &metrics["connections"];
    assert!(connections["open"].as_u64().unwrap() <= 16, "{connections}");
    assert!(connections["evicted_slow_bodies"].as_u64().unwrap() >= 1, "{connections}");
    assert!(connections["reserve_accepted"].as_u64().unwrap() >= 1, "{connections}");
    drop(held);
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_request_head_that_never_ends_is_closed_after_the_header_timeout() {
    let server = start_with(&small(), |c| c.limits.header_timeout = Duration::from_secs(1)).await;
    let mut idle = TcpStream::connect(server.addr).await.unwrap();
    let mut slow = slowloris(server.addr).await;
    for socket in [&mut idle, &mut slow] {
        let mut buf = [0u8; 256];
        let read = tokio::time::timeout(Duration::from_secs(10), socket.read(&mut buf)).await;
        // Closed (0 bytes or a reset), perhaps after a 408: never held open.
        if let Ok(n) = read.expect("closed within 10 s") {
            assert!(n == 0 || String::from_utf8_lossy(&buf[..n]).starts_with("HTTP/1.1 408"));
        }
    }
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn half_sent_bodies_share_a_bounded_budget() {
    let server = start_with(&small(), |_| {}).await;
    // Each declares 3 MB and sends 1 KB: together they may reserve at most 32 MiB.
    let mut held = Vec::new();
    let mut refused = 0;
    for _ in 0..14 {
        let mut s = TcpStream::connect(server.addr).await.unwrap();
        let head = format!(
            "PUT /api/road HTTP/1.1\r\nHost: {}\r\nContent-Type: application/json\r\nContent-Length: 3000000\r\n\r\n",
            server.addr
        );
        s.write_all(head.as_bytes()).await.unwrap();
        s.write_all(&[b' '; 1024]).await.unwrap();
        let mut buf = [0u8; 512];
        // An admitted upload waits for the rest of its body; a refused one is answered at once.
        if let Ok(Ok(n)) = tokio::time::timeout(Duration::from_millis(300), s.read(&mut buf)).await {
            let answer = String::from_utf8_lossy(&buf[..n]);
            assert!(answer.starts_with("HTTP/1.1 503"), "{answer}");
            assert!(answer.contains("\"busy\""), "{answer}");
            refused += 1;
        }
        held.push(s);
    }
    assert_eq!(refused, 3, "11 uploads of 3 MB fit in 32 MiB, the other 3 are refused");
    stop_within(&server, Duration::from_secs(5)).await;
    drop(held);
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn stream_clients_are_capped_and_may_not_send_large_messages() {
    let server = start_with(&small(), |c| c.max_stream_clients = 4).await;
    let url = format!("ws://{}/ws", server.addr);
    let mut clients = Vec::new();
    for _ in 0..4 {
        clients.push(tokio_tungstenite::connect_async(&url).await.unwrap().0);
    }
    // The fifth is refused with the API's error.
    let refused = tokio_tungstenite::connect_async(&url).await;
    match refused {
        Err(tokio_tungstenite::tungstenite::Error::Http(response)) => assert_eq!(response.status(), 503),
        other => panic!("a fifth client was not refused: {other:?}"),
    }
    // A client sending a 100 KB message is disconnected; the others stay.
    let mut big = clients.pop().unwrap();
    let _ = big.send(tokio_tungstenite::tungstenite::Message::text("x".repeat(100 << 10))).await;
    let closed = tokio::time::timeout(Duration::from_secs(5), async {
        use futures_util::StreamExt;
        while let Some(Ok(_)) = big.next().await {}
    })
    .await;
    assert!(closed.is_ok(), "the client sending a large message was not disconnected");
    stop_within(&server, Duration::from_secs(5)).await;
    let metrics = server.get("/api/metrics").await;
    assert!(metrics["stream"]["clients_refused"].as_u64().unwrap() >= 1);
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn concurrent_handshakes_cannot_exceed_the_stream_client_cap() {
    let server = start_with(&small(), |c| c.max_stream_clients = 4).await;
    let url = format!("ws://{}/ws?format=bin", server.addr);
    // Twelve handshakes at once: exactly four get a stream, the others the API's 503.
    let attempts = (0..12).map(|_| tokio_tungstenite::connect_async(url.clone()));
    let results = futures_util::future::join_all(attempts).await;
    let (mut open, mut refused) = (Vec::new(), 0);
    for r in results {
        match r {
            Ok((socket, _)) => open.push(socket),
            Err(tokio_tungstenite::tungstenite::Error::Http(response)) if response.status() == 503 => {
                refused += 1
            }
            Err(e) => panic!("unexpected handshake failure: {e}"),
        }
    }
    assert_eq!((open.len(), refused), (4, 8));
    // Their places come back when they leave.
    drop(open);
    let again = tokio::time::timeout(Duration::from_secs(5), async {
        loop {
            if let Ok((socket, _)) = tokio_tungstenite::connect_async(url.clone()).await {
                return socket;
            }
            tokio::time::sleep(Duration::from_millis(50)).await;
        }
    })
    .await;
    assert!(again.is_ok(), "no place came back after four clients left");
    server.stop().await;
}

/// A scenario of `count` UAVs on a grid, 0.6 m apart, on a straight road 1 km long and 40 m wide;
/// with `bad_last`, the last UAV starts outside the road.
fn crowd(count: usize, bad_last: bool) -> serde_json::Value {
    let uavs: Vec<serde_json::Value> = (0..count)
        .map(|i| {
            let (col, row) = (i / 60, i % 60);
            let mut start = [1.0 + col as f64 * 0.6, -18.0 + row as f64 * 0.6];
            if bad_last && i + 1 == count {
                start = [1.0, 30.0];
            }
            serde_json::json!({"id": format!("u{i}"), "start": start, "goal": start})
        })
        .collect();
    serde_json::json!({
        "name": "crowd",
        "segments": roads::RoadLayout::straight(0.0, 1000.0, 40.0, 50).segments,
        "uavs": uavs,
    })
}

async fn post_scenario(addr: std::net::SocketAddr, scenario: &str) -> (u16, serde_json::Value) {
    let (status, text) = support::raw(addr, "POST", "/api/scenario", Some(scenario), &[]).await;
    (status, serde_json::from_str(&text).unwrap_or(serde_json::Value::Null))
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_fleet_beyond_the_limit_is_refused_before_any_validation() {
    let server = start_with(&small(), |c| c.max_uavs = 1000).await;
    let huge = crowd(50_000, true).to_string();
    assert!(huge.len() < 4 << 20, "{} bytes", huge.len());
    let started = Instant::now();
    let (status, body) = post_scenario(server.addr, &huge).await;
    assert_eq!((status, body["error"]["code"].as_str()), (422, Some("fleet_full")), "{body}");
    assert_eq!(body["error"]["field"], "uavs");
    assert!(body["error"]["message"].as_str().unwrap().contains("1000"), "{body}");
    println!("refused in {:?}", started.elapsed());
    // One by one too.
    let metrics = server.get("/api/metrics").await;
    assert_eq!(metrics["max_uavs"], 1000);
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn large_validations_run_off_the_workers_and_the_stop_stays_reachable() {
    let server = start_with(&small(), |c| c.max_uavs = 100_000).await;
    let huge = std::sync::Arc::new(crowd(50_000, true).to_string());
    let addr = server.addr;
    let posts: Vec<_> = (0..2)
        .map(|_| {
            let huge = huge.clone();
            tokio::spawn(async move { post_scenario(addr, &huge).await })
        })
        .collect();
    tokio::time::sleep(Duration::from_millis(50)).await;
    stop_within(&server, Duration::from_secs(2)).await;
    assert_eq!(server.get("/healthz").await["status"], "ok");
    for post in posts {
        let (status, body) = post.await.unwrap();
        match status {
            422 => assert_eq!(body["error"]["field"], "uavs[49999].start", "{body}"),
            // The second validation may wait for the first longer than it is allowed to.
            503 => assert_eq!(body["error"]["code"], "busy", "{body}"),
            other => panic!("{other}: {body}"),
        }
    }
    assert_eq!(server.get("/api/state").await["uavs"].as_array().unwrap().len(), 2, "nothing changed");
    server.stop().await;
}

/// A policy that takes 1.5 s per call (and commands nothing): it stalls the loop.
struct Slow;

impl policies::Policy for Slow {
    fn act(
        &mut self,
        observations: &[policies::Observation],
        actions: &mut Vec<uav::Vec2>,
    ) -> Result<(), policies::PolicyError> {
        std::thread::sleep(Duration::from_millis(1500));
        actions.clear();
        actions.resize(observations.len(), uav::Vec2::zeros());
        Ok(())
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_stalled_loop_is_reported_and_an_applied_change_is_answered_as_applied() {
    let server = start_with(&small(), |c| c.policies.insert("slow", Box::new(Slow))).await;
    // The change is applied before the slow tick it causes: it is answered 200, however long the
    // answer waits for that tick.
    let (status, body) = server.call("PUT", "/api/uavs/a/policy", Some(r#"{"policy": "slow"}"#)).await;
    assert_eq!(status, 200, "{body}");
    let mut stalled = None;
    let deadline = Instant::now() + Duration::from_secs(20);
    while Instant::now() < deadline && stalled.is_none() {
        let (code, health) = support::raw(server.addr, "GET", "/healthz", None, &[]).await;
        let health: serde_json::Value = serde_json::from_str(&health).unwrap();
        if health["status"] == "stalled" {
            assert_eq!(code, 503);
            assert!(health["tick_age_ms"].as_f64().unwrap() > 1000.0, "{health}");
            stalled = Some(health);
        }
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    assert!(stalled.is_some(), "a loop taking 1.5 s per tick was never reported stalled");
    let metrics = server.get("/api/metrics").await;
    assert!(metrics["overruns"].as_u64().unwrap() >= 1, "{metrics}");
    assert!(metrics["longest_tick_us"].as_f64().unwrap() > 1.4e6, "{metrics}");
    let (status, body) = server.call("PUT", "/api/uavs/a/policy", Some(r#"{"policy": "pd"}"#)).await;
    assert_eq!(status, 200, "{body}");
    let deadline = Instant::now() + Duration::from_secs(20);
    while server.get("/healthz").await["status"] != "ok" {
        assert!(Instant::now() < deadline, "the loop did not recover");
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    server.stop().await;
}
