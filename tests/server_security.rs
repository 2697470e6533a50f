//! End-to-end tests of the server's security model against the real server on 127.0.0.1:0, as an
//! outsider would attack it: cross-site and DNS-rebinding requests, inputs that used to panic or
//! slip through, error answers without bodies, the audit log and the rate limit on wrong tokens.

mod support;

use serde_json::Value;
use support::{Running, Wire, config, exchange, request_text, small, start, start_with};

/// Every UAV's status in the current state.
async fn statuses(server: &Running) -> Vec<String> {
    let state = server.get("/api/state").await;
    state["uavs"].as_array().unwrap().iter().map(|u| u["status"].as_str().unwrap().to_string()).collect()
}

async fn send(server: &Running, method: &str, path: &str, headers: &[&str], body: &str) -> Wire {
    let host = format!("Host: {}", server.addr);
    let mut all = vec![host.as_str()];
    all.extend_from_slice(headers);
    exchange(server.addr, request_text(method, path, &all, body).as_bytes()).await
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_page_on_another_origin_cannot_change_anything() {
    let server = start(config(&small())).await;
    let paused = || async { server.get("/api/state").await["paused"] == true };
    for path in ["/api/fleet/stop", "/api/fleet/pause", "/api/fleet/land", "/api/uavs/a/land"] {
        // The "simple" request a page can send anywhere without asking: text/plain, foreign Origin.
        let w = send(&server, "POST", path, &["Origin: http://evil.example", "Content-Type: text/plain"], "")
            .await;
        assert_eq!(
            (w.status, w.json()["error"]["code"].as_str()),
            (403, Some("origin_not_allowed")),
            "{path}"
        );
        assert_eq!(w.json()["error"]["field"], "Origin");
        // Without an Origin (a script, not a page), text/plain is still refused.
        let w = send(&server, "POST", path, &["Content-Type: text/plain"], "").await;
        assert_eq!(
            (w.status, w.json()["error"]["code"].as_str()),
            (415, Some("unsupported_media_type")),
            "{path}"
        );
        let w = send(&server, "POST", path, &[], "").await;
        assert_eq!(w.status, 415, "{path}: no content type");
        // A form post from a browser that sends no Origin but says cross-site.
        let headers = ["Sec-Fetch-Site: cross-site", "Content-Type: application/json"];
        assert_eq!(send(&server, "POST", path, &headers, "").await.status, 403, "{path}");
    }
    assert!(!paused().await);
    assert!(statuses(&server).await.iter().all(|s| s != "stopped" && s != "landing"));
    // The same page with JSON: still refused by its Origin. The server's own page may.
    let json = "Content-Type: application/json";
    let w = send(
        &server,
        "PUT",
        "/api/uavs/a/goal",
        &["Origin: http://evil.example", json],
        r#"{"goal": [6, -1]}"#,
    )
    .await;
    assert_eq!(w.status, 403);
    let own = format!("Origin: http://{}", server.addr);
    let w = send(&server, "POST", "/api/fleet/pause", &[&own, json], "").await;
    assert_eq!(w.status, 200, "{}", w.body);
    assert!(paused().await);
    // A foreign page's WebSocket is refused; the server's own and a script's are accepted.
    let upgrade = [
        "Upgrade: websocket",
        "Connection: Upgrade",
        "Sec-WebSocket-Version: 13",
        "Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==",
    ];
    let mut foreign = upgrade.to_vec();
    foreign.push("Origin: http://evil.example");
    assert_eq!(send(&server, "GET", "/ws", &foreign, "").await.status, 403);
    let mut mine = upgrade.to_vec();
    mine.push(&own);
    let w = exchange_head(&server, "GET", "/ws", &mine).await;
    assert_eq!(w, 101);
    server.stop().await;
}

/// The status line of an exchange whose connection stays open (a WebSocket upgrade).
async fn exchange_head(server: &Running, method: &str, path: &str, headers: &[&str]) -> u16 {
    exchange_first(server, method, path, headers).await.0
}

/// The status and the first bytes of the answer to a request on a connection that stays open.
async fn exchange_first(server: &Running, method: &str, path: &str, headers: &[&str]) -> (u16, String) {
    use tokio::io::{AsyncReadExt, AsyncWriteExt};
    let host = format!("Host: {}", server.addr);
    let mut all = vec![host.as_str()];
    all.extend_from_slice(headers);
    let text = request_text(method, path, &all, "").replace("Connection: close\r\n", "");
    let mut stream = tokio::net::TcpStream::connect(server.addr).await.unwrap();
    stream.write_all(text.as_bytes()).await.unwrap();
    let mut buf = vec![0u8; 1024];
    let n = tokio::time::timeout(std::time::Duration::from_secs(5), stream.read(&mut buf))
        .await
        .unwrap()
        .unwrap();
    let head = String::from_utf8_lossy(&buf[..n]).into_owned();
    (head.split(' ').nth(1).and_then(|s| s.parse().ok()).unwrap_or(0), head)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn only_hosts_the_server_listens_on_are_served() {
    let server = start_with(&small(), |c| c.allow_hosts = vec!["ops.example.com".into()]).await;
    let port = server.addr.port();
    for (host, want) in [
        (format!("rebind.evil.example:{port}"), 421),
        ("rebind.evil.example:18180".to_string(), 421),
        (format!("127.0.0.2:{port}"), 421),
        (String::new(), 421),
        (format!("127.0.0.1:{port}"), 200),
        (format!("localhost:{port}"), 200),
        ("ops.example.com".to_string(), 200),
        // Published on another port (a container's `-p 127.0.0.1:18180:8080`): the name is what
        // DNS rebinding changes, not the port.
        (format!("127.0.0.1:{}", port.wrapping_add(1)), 200),
        ("localhost:18180".to_string(), 200),
    ] {
        let text = request_text("GET", "/api/state", &[&format!("Host: {host}")], "");
        let w = exchange(server.addr, text.as_bytes()).await;
        assert_eq!(w.status, want, "Host: {host}: {}", w.body);
        if want == 421 {
            assert_eq!(w.json()["error"]["code"], "host_not_allowed");
        }
    }
    // A rebound name cannot change anything either.
    let text = request_text(
        "POST",
        "/api/fleet/stop",
        &["Host: rebind.evil.example", "Content-Type: application/json"],
        "",
    );
    assert_eq!(exchange(server.addr, text.as_bytes()).await.status, 421);
    assert!(statuses(&server).await.iter().all(|s| s != "stopped"));
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_allowed_origin_may_change_and_the_dashboard_cannot_be_framed() {
    let server = start_with(&small(), |c| c.allow_origins = vec!["https://ops.example.com".into()]).await;
    let headers = ["Origin: https://ops.example.com", "Content-Type: application/json"];
    assert_eq!(send(&server, "POST", "/api/fleet/pause", &headers, "{}").await.status, 200);
    let page = send(&server, "GET", "/", &[], "").await;
    assert_eq!(page.status, 200);
    assert_eq!(page.header("x-frame-options"), Some("DENY"));
    let csp = page.header("content-security-policy").unwrap_or_default();
    assert!(csp.contains("frame-ancestors 'none'"), "{csp}");
    assert_eq!(page.header("x-content-type-options"), Some("nosniff"));
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn no_input_panics_and_every_error_has_a_json_body() {
    let server = start(config(&small())).await;
    // A vanishing rate used to panic in Duration::from_secs_f64.
    let upgrade = [
        "Upgrade: websocket",
        "Connection: Upgrade",
        "Sec-WebSocket-Version: 13",
        "Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==",
    ];
    for rate in ["1e-300", "4.9e-324", "1e-30"] {
        assert_eq!(
            exchange_head(&server, "GET", &format!("/ws?rate={rate}"), &upgrade).await,
            101,
            "rate={rate}"
        );
    }
    for rate in ["0", "-1", "NaN", "inf", "1e309", "x"] {
        let (status, body) = exchange_first(&server, "GET", &format!("/ws?rate={rate}"), &upgrade).await;
        assert_eq!(status, 422, "rate={rate}: {body}");
        assert!(body.contains("\"field\":\"rate\""), "rate={rate}: {body}");
    }
    // 405, 414, 431 and 404 answer with the API's error body.
    let w = send(&server, "PATCH", "/api/road", &["Content-Type: application/json"], "{}").await;
    assert_eq!(
        (w.status, w.json()["error"]["code"].as_str()),
        (405, Some("method_not_allowed")),
        "{}",
        w.body
    );
    assert!(w.header("allow").is_some_and(|a| a.contains("PUT")), "{:?}", w.headers);
    // Methods a route does not take are 405 too, with or without a JSON content type (never 415).
    let cases = [
        ("TRACE", "/api/fleet/stop", "POST"),
        ("BREW", "/api/fleet/stop", "POST"),
        ("PUT", "/api/metrics", "GET"),
    ];
    for (method, path, allowed) in cases {
        for headers in [&[][..], &["Content-Type: application/json"][..]] {
            let w = send(&server, method, path, headers, "").await;
            assert_eq!(
                (w.status, w.json()["error"]["code"].as_str()),
                (405, Some("method_not_allowed")),
                "{method} {headers:?}: {}",
                w.body
            );
            assert!(w.header("allow").is_some_and(|a| a.contains(allowed)), "{:?}", w.headers);
        }
    }
    assert!(
        server.get("/api/state").await["uavs"].as_array().unwrap().iter().all(|u| u["status"] != "stopped"),
        "a method no route takes stopped the fleet"
    );
    let long = format!("/api/state?x={}", "a".repeat(9000));
    let w = send(&server, "GET", &long, &[], "").await;
    assert_eq!((w.status, w.json()["error"]["code"].as_str()), (414, Some("uri_too_long")));
    let many: Vec<String> = (0..150).map(|i| format!("X-Filler-{i}: {i}")).collect();
    let many: Vec<&str> = many.iter().map(String::as_str).collect();
    let w = send(&server, "GET", "/api/state", &many, "").await;
    assert_eq!((w.status, w.json()["error"]["code"].as_str()), (431, Some("headers_too_large")));
    let big = format!("X-Big: {}", "b".repeat(40 << 10));
    let w = send(&server, "GET", "/api/state", &[&big], "").await;
    assert_eq!(w.status, 431);
    // Trailing data after a JSON document is malformed, as docs/api.md promises.
    let json = "Content-Type: application/json";
    let w = send(&server, "PUT", "/api/uavs/a/goal", &[json], r#"{"goal": [1, 0]} xyz"#).await;
    assert_eq!((w.status, w.json()["error"]["code"].as_str()), (400, Some("malformed_json")), "{}", w.body);
    assert_ne!(server.get("/api/uavs/a").await["goal"], serde_json::json!([1.0, 0.0]));
    // A change that takes no body accepts nothing or `{}`, and refuses anything else.
    assert_eq!(send(&server, "POST", "/api/fleet/pause", &[json], "{}").await.status, 200);
    let w = send(&server, "POST", "/api/fleet/resume", &[json], r#"{"now": true}"#).await;
    assert_eq!((w.status, w.json()["error"]["code"].as_str()), (422, Some("invalid_body")));
    assert_eq!(send(&server, "POST", "/api/fleet/resume", &[json], "").await.status, 200);
    let w = send(&server, "POST", "/api/fleet/resume", &[json], " \n").await;
    assert_eq!((w.status, w.json()["error"]["code"].as_str()), (400, Some("malformed_json")), "{}", w.body);
    // A chunked body (no length to budget) is refused.
    let w = send(&server, "POST", "/api/fleet/pause", &[json, "Transfer-Encoding: chunked"], "").await;
    assert_eq!(w.status, 411, "{}", w.body);
    assert_eq!(server.get("/healthz").await["status"], "ok");
    server.stop().await;
}

fn entries(log: &Value) -> Vec<&Value> {
    log["entries"].as_array().unwrap().iter().collect()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn changes_are_audited_and_wrong_tokens_are_rate_limited() {
    let server = start_with(&small(), |c| c.token = Some("s3cret-t0ken-for-tests".into())).await;
    let good = "Authorization: Bearer s3cret-t0ken-for-tests";
    let json = "Content-Type: application/json";
    let w = send(&server, "PUT", "/api/uavs/a/goal", &[good, json], r#"{"goal": [6, -1]}"#).await;
    assert_eq!(w.status, 200, "{}", w.body);
    let w = send(&server, "PUT", "/api/uavs/zz/goal", &[good, json], r#"{"goal": [6, -1]}"#).await;
    assert_eq!(w.status, 404);
    // Reading the log needs the token.
    assert_eq!(send(&server, "GET", "/api/audit", &[], "").await.status, 401);
    // A burst of wrong tokens: the first ones are 401 (the audit read above was the first of the
    // ten allowed failures), then 429 without looking at the token.
    let mut codes = Vec::new();
    for i in 0..40 {
        let bad = format!("Authorization: Bearer wrong-{i}");
        codes.push(send(&server, "POST", "/api/fleet/pause", &[&bad, json], "").await.status);
    }
    // (The allowance refills at 1/s, so a slow machine may see one more 401 later on.)
    let refused = codes.iter().filter(|c| **c == 401).count();
    assert!(codes[..9].iter().all(|c| *c == 401), "{codes:?}");
    assert!(codes.iter().filter(|c| **c == 429).count() >= 25, "{codes:?}");
    assert!(codes.iter().all(|c| *c == 401 || *c == 429), "{codes:?}");
    // Meanwhile this address may not even use the right token for ordinary changes...
    assert_eq!(send(&server, "POST", "/api/fleet/pause", &[good, json], "").await.status, 429);
    // ...but the emergency stop gets through with it, at most a second after its last check.
    let started = std::time::Instant::now();
    loop {
        let w = send(&server, "POST", "/api/fleet/stop", &[good, json], "").await;
        if w.status == 200 {
            break;
        }
        assert_eq!(w.status, 429, "{}", w.body);
        assert!(started.elapsed() < std::time::Duration::from_millis(1100), "the stop waited over a second");
        tokio::time::sleep(std::time::Duration::from_millis(20)).await;
    }
    let metrics = server.get("/api/metrics").await;
    assert_eq!(metrics["auth"]["refused"], refused as u64 + 1, "{}", metrics["auth"]);
    assert!(metrics["auth"]["rate_limited"].as_u64().unwrap() >= 25);

    // Every change request is in the log, newest first, with its route, client and outcome (read
    // once this address has regained an attempt: about a second).
    let mut log = Value::Null;
    for _ in 0..100 {
        let w = send(&server, "GET", "/api/audit?limit=1000", &[good], "").await;
        if w.status == 429 {
            tokio::time::sleep(std::time::Duration::from_millis(100)).await;
            continue;
        }
        assert_eq!(w.status, 200, "{}", w.body);
        log = w.json();
        if entries(&log).iter().any(|e| e["route"] == "/api/fleet/stop") {
            break;
        }
        tokio::time::sleep(std::time::Duration::from_millis(50)).await;
    }
    let all = entries(&log);
    let goal = all.iter().find(|e| e["route"] == "/api/uavs/a/goal").expect("the goal change is logged");
    assert_eq!(
        (goal["method"].as_str(), goal["status"].as_u64(), goal["outcome"].as_str()),
        (Some("PUT"), Some(200), Some("applied"))
    );
    assert!(goal["remote"].as_str().unwrap().starts_with("127.0.0.1:"), "{goal}");
    assert!(goal["detail"].as_str().unwrap().contains("goal of `a`"), "{goal}");
    let missing = all.iter().find(|e| e["route"] == "/api/uavs/zz/goal").unwrap();
    assert_eq!((missing["status"].as_u64(), missing["outcome"].as_str()), (Some(404), Some("unknown_uav")));
    assert_eq!(all.iter().filter(|e| e["outcome"] == "unauthorized").count(), refused);
    assert!(all.iter().any(|e| e["outcome"] == "too_many_auth_failures"));
    let stop = all.iter().find(|e| e["route"] == "/api/fleet/stop").unwrap();
    assert_eq!(stop["status"], 200);
    assert!(all.windows(2).all(|w| w[0]["seq"].as_i64() > w[1]["seq"].as_i64()), "newest first");
    // Following the log: entries after a sequence number, oldest first.
    let first = all.last().unwrap()["seq"].as_i64().unwrap();
    let w = send(&server, "GET", &format!("/api/audit?after={first}&limit=2"), &[good], "").await;
    let tail = w.json();
    let seqs: Vec<i64> = entries(&tail).iter().map(|e| e["seq"].as_i64().unwrap()).collect();
    assert_eq!(seqs, vec![first + 1, first + 2]);
    assert_eq!(send(&server, "GET", "/api/audit?limit=0", &[good], "").await.status, 422);
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn every_route_applies_the_same_rule_to_each_input() {
    let server = start_with(&small(), |c| c.link_rules.udp_hosts = vec!["10.0.0.5".parse().unwrap()]).await;
    let ids_before = server.get("/api/state").await["uavs"].as_array().unwrap().len();
    let scenario = |id: &str, link: Option<&str>, dt: f64| {
        let mut s = small();
        s["uavs"][1]["id"] = serde_json::json!(id);
        if let Some(link) = link {
            s["uavs"][1]["link"] = serde_json::json!(link);
        }
        s["params"] = serde_json::json!({"dt": dt});
        s.to_string()
    };
    let uav = |id: &str, link: Option<&str>| {
        let mut u = serde_json::json!({"id": id, "position": [8.0, 0.0]});
        if let Some(link) = link {
            u["link"] = serde_json::json!(link);
        }
        u.to_string()
    };
    for id in ["a/b", "with space", "bell\u{7}", "rtl\u{202e}x", "", &"x".repeat(65)] {
        let (status, body) = server.call("POST", "/api/scenario", Some(&scenario(id, None, 0.05))).await;
        assert_eq!((status, body["error"]["field"].as_str()), (422, Some("uavs[1].id")), "{id:?}: {body}");
        let (status, body) = server.call("POST", "/api/uavs", Some(&uav(id, None))).await;
        assert_eq!((status, body["error"]["field"].as_str()), (422, Some("id")), "{id:?}: {body}");
    }
    for link in [
        "udp://127.0.0.1:99999",
        "udp://192.168.1.9:19850",
        "udp://example.com:1",
        "radio://0/126/2M/E7E7E7E7E7",
    ] {
        let (status, body) =
            server.call("POST", "/api/scenario", Some(&scenario("b", Some(link), 0.05))).await;
        assert_eq!((status, body["error"]["field"].as_str()), (422, Some("uavs[1].link")), "{link}: {body}");
        let (status, body) = server.call("POST", "/api/uavs", Some(&uav("c", Some(link)))).await;
        assert_eq!((status, body["error"]["field"].as_str()), (422, Some("link")), "{link}: {body}");
    }
    // A remote simulator host the server was told to allow.
    let (status, body) =
        server.call("POST", "/api/uavs", Some(&uav("c", Some("udp://10.0.0.5:19850")))).await;
    assert_eq!(status, 201, "{body}");
    let (status, _) = server.call("DELETE", "/api/uavs/c", None).await;
    assert_eq!(status, 204);
    // A control period that would make an emergency stop wait a whole second.
    let (status, body) = server.call("POST", "/api/scenario", Some(&scenario("b", None, 1.0))).await;
    assert_eq!((status, body["error"]["field"].as_str()), (422, Some("params.dt")), "{body}");
    assert_eq!(server.get("/api/state").await["uavs"].as_array().unwrap().len(), ids_before);
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn while_changes_cannot_be_saved_health_says_so_and_they_are_refused() {
    let server = start(config(&small())).await;
    // An empty fleet: no position writes that could succeed and clear the state below.
    for id in ["a", "b"] {
        assert_eq!(server.call("DELETE", &format!("/api/uavs/{id}"), None).await.0, 204);
    }
    tokio::time::sleep(std::time::Duration::from_millis(300)).await;
    // The state writer's verdict after a failed commit (as a full disk gives it).
    server.state.engine.storage.degrade("database or disk is full".into());
    let health = server.get("/healthz").await;
    assert_eq!(health["status"], "degraded", "{health}");
    assert!(health["problems"][0].as_str().unwrap().contains("disk is full"), "{health}");
    let metrics = server.get("/api/metrics").await;
    assert_eq!(metrics["storage"]["degraded"], true, "{}", metrics["storage"]);
    let (status, body) = server.call("POST", "/api/fleet/pause", None).await;
    assert_eq!((status, body["error"]["code"].as_str()), (503, Some("not_durable")), "{body}");
    assert_eq!(server.get("/api/state").await["paused"], false, "nothing changed");
    // The next successful commit (here: the audit entry of that request) clears it.
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(10);
    while server.get("/healthz").await["status"] != "ok" {
        assert!(std::time::Instant::now() < deadline, "still degraded after a successful commit");
        tokio::time::sleep(std::time::Duration::from_millis(50)).await;
    }
    server.stop().await;
}
