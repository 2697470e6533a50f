//! End-to-end tests of the REST API against the real server on 127.0.0.1:0: every endpoint, its
//! error cases (status, `{"error": {"code", "message", "field"}}`), and that refused changes change
//! nothing.

mod support;

use serde_json::{Value, json};
use support::{Running, config, small, start};

fn error_field(body: &Value) -> &str {
    body["error"]["field"].as_str().unwrap_or_default()
}

async fn uav_ids(server: &Running) -> Vec<String> {
    let uavs = server.get("/api/uavs").await;
    uavs.as_array().unwrap().iter().map(|u| u["id"].as_str().unwrap().to_string()).collect()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn health_openapi_state_and_metrics() {
    let server = start(config(&small())).await;
    let health = server.get("/healthz").await;
    assert_eq!(health["status"], "ok");
    let doc = server.get("/api/openapi.json").await;
    assert_eq!(doc["openapi"], "3.1.0");
    for path in
        ["/api/road", "/api/uavs", "/api/uavs/{id}/goal", "/api/scenario", "/api/fleet/pause", "/api/state"]
    {
        assert!(doc["paths"][path].is_object(), "{path} missing from the OpenAPI document");
    }
    let state = server.wait_for(5.0, |s| s["tick"].as_u64().unwrap_or(0) >= 3).await;
    let uav = &state["uavs"][0];
    for key in ["id", "p", "v", "u_ref", "u", "target", "goal", "arrived", "active_rows", "slack", "status"] {
        assert!(!uav[key].is_null() || key == "goal", "state.uavs[0].{key} missing: {uav}");
    }
    assert!(state["time"].as_f64().unwrap() > 0.0);
    let metrics = server.get("/api/metrics").await;
    assert!(metrics["ticks"].as_u64().unwrap() >= 3, "{metrics}");
    assert!(metrics["tick"]["p99_us"].as_f64().unwrap() > 0.0, "{metrics}");
    assert_eq!(metrics["qp"]["failures"], 0);
    // Where the ticks went: every stage measured, the fleet's and the snapshot's adding up to the
    // mean tick (at most the longest).
    let stages = &metrics["stages"];
    let stage = |key: &str| stages[key].as_f64().unwrap_or_else(|| panic!("stages.{key} missing: {metrics}"));
    let in_tick =
        ["read_us", "neighbours_us", "navigation_us", "policies_us", "rows_us", "filter_us", "send_us"]
            .iter()
            .chain(&["snapshot_us", "other_us"])
            .map(|key| stage(key))
            .inspect(|&us| assert!(us >= 0.0, "{metrics}"))
            .sum::<f64>();
    assert!(stage("filter_us") > 0.0 && stage("snapshot_us") > 0.0 && stage("publish_us") > 0.0, "{metrics}");
    assert!(in_tick <= metrics["tick"]["max_us"].as_f64().unwrap() + 1.0, "{metrics}");
    // Stalls are measured (nothing stalls here in the first ticks).
    assert_eq!(
        (metrics["stalled_uavs"].as_u64(), metrics["longest_stall_s"].as_f64()),
        (Some(0), Some(0.0)),
        "{metrics}"
    );
    assert!(metrics["stall_s"].as_f64().is_some_and(|s| s >= 0.0), "{metrics}");
    let (status, body) = server.call("GET", "/api/nowhere", None).await;
    assert_eq!((status, body["error"]["code"].as_str()), (404, Some("not_found")));
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn road_is_validated_and_refused_when_a_uav_would_be_outside() {
    let server = start(config(&small())).await;
    let road = server.get("/api/road").await;
    assert_eq!(road["segments"].as_array().unwrap().len(), 2);

    // A non-convex segment: 422 naming the segment and the rule; the road is unchanged.
    let mut bad = road.clone();
    bad["segments"][1][0] = json!([11.0, -2.0]);
    bad["segments"][1][1] = json!([20.0, -2.0]);
    let (status, body) = server.call("PUT", "/api/road", Some(&bad.to_string())).await;
    assert_eq!(status, 422, "{body}");
    assert_eq!(body["error"]["code"], "invalid_road");
    assert_eq!(error_field(&body), "segments[1]");
    assert!(body["error"]["rule"].is_string(), "{body}");
    assert_eq!(server.get("/api/road").await, road);

    // A valid road that leaves the UAVs (at x = 2) outside: 409, unchanged.
    let far = json!({"segments": roads::RoadLayout::straight(10.0, 30.0, 4.0, 2).segments});
    let (status, body) = server.call("PUT", "/api/road", Some(&far.to_string())).await;
    assert_eq!((status, body["error"]["code"].as_str()), (409, Some("unsafe_road")), "{body}");
    assert_eq!(server.get("/api/road").await, road);

    // A longer road that keeps them inside: applied, version up, goals kept.
    let longer = json!({"segments": roads::RoadLayout::straight(0.0, 30.0, 4.0, 3).segments});
    let (status, body) = server.call("PUT", "/api/road", Some(&longer.to_string())).await;
    assert_eq!(status, 200, "{body}");
    assert_eq!(body["cleared_goals"], json!([]));
    assert_eq!(server.get("/api/road").await, longer);
    assert_eq!(server.get("/api/road/geometry").await["version"], body["version"]);

    // Malformed, empty, wrong type, unknown key, NaN-like and huge numbers: 4xx, nothing changes.
    let before = server.get("/api/road").await;
    for (text, want) in [
        ("{\"segments\": [", 400),
        ("", 400),
        ("{\"segments\": 3}", 422),
        ("{\"segments\": [], \"extra\": 1}", 422),
        ("{\"segments\": [[[NaN, 0], [0, 0], [0, 1], [1, 1]]]}", 400),
        ("{\"segments\": [[[1e999, 0], [0, 0], [0, 1], [1, 1]]]}", 400),
        ("{\"segments\": [[[1e300, 0], [0, 0], [0, 1], [1, 1]]]}", 422),
        ("{\"segments\": []}", 422),
    ] {
        let json = [("Content-Type", "application/json")];
        let (status, body) = server.call_with("PUT", "/api/road", Some(text), &json).await;
        assert_eq!(status, want, "PUT /api/road {text:?}: {body}");
        assert!(body["error"]["message"].is_string(), "{body}");
    }
    let (status, _) =
        server.call_with("PUT", "/api/road", Some("{}"), &[("Content-Type", "text/plain")]).await;
    assert_eq!(status, 415);
    assert_eq!(server.get("/api/road").await, before);
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn road_regions_are_validated_stored_and_returned() {
    let server = start(config(&small())).await;
    let plain = server.get("/api/road").await;
    assert!(plain.get("regions").is_none(), "a layout without regions has no `regions` key: {plain}");

    // Four segments in two regions, listed out of order: applied and returned as sent.
    let segments = roads::RoadLayout::straight(0.0, 40.0, 4.0, 4).segments;
    let regions = json!([{"name": "east", "segments": [2, 3]}, {"name": "west", "segments": [0, 1]}]);
    let divided = json!({"segments": segments, "regions": regions});
    let (status, body) = server.call("PUT", "/api/road", Some(&divided.to_string())).await;
    assert_eq!(status, 200, "{body}");
    assert_eq!(server.get("/api/road").await, divided);
    assert_eq!(server.get("/api/road/geometry").await["layout"], divided);

    // 422 `invalid_road` naming the region's field and the rule; the road is unchanged.
    for (regions, field, rule) in [
        (
            json!([{"name": "west", "segments": [0, 1]}, {"name": "east", "segments": [1, 3]}]),
            "regions[1].segments",
            "region_overlap",
        ),
        (
            json!([{"name": "west", "segments": [0, 1]}, {"name": "east", "segments": [2, 4]}]),
            "regions[1].segments",
            "region_out_of_range",
        ),
        (
            json!([{"name": "west", "segments": [0, 1]}, {"name": "east", "segments": [3, 2]}]),
            "regions[1].segments",
            "reversed_region",
        ),
        (
            json!([{"name": "west", "segments": [0, 0]}, {"name": "east", "segments": [2, 3]}]),
            "regions",
            "region_gap",
        ),
        (
            json!([{"name": "west", "segments": [0, 1]}, {"name": "we/st", "segments": [2, 3]}]),
            "regions[1].name",
            "invalid_region_name",
        ),
        (
            json!([{"name": "west", "segments": [0, 1]}, {"name": "west", "segments": [2, 3]}]),
            "regions[1].name",
            "duplicate_region_name",
        ),
        (json!([]), "regions", "empty_regions"),
    ] {
        let bad = json!({"segments": segments, "regions": regions});
        let (status, body) = server.call("PUT", "/api/road", Some(&bad.to_string())).await;
        assert_eq!((status, body["error"]["code"].as_str()), (422, Some("invalid_road")), "{body}");
        assert_eq!((error_field(&body), body["error"]["rule"].as_str()), (field, Some(rule)), "{body}");
    }
    let (status, body) = server
        .call("PUT", "/api/road", Some(&json!({"segments": segments, "regions": null}).to_string()))
        .await;
    assert_eq!((status, error_field(&body)), (422, "regions"), "{body}");
    assert_eq!(server.get("/api/road").await, divided);

    // A road without regions drops them.
    let (status, body) = server.call("PUT", "/api/road", Some(&plain.to_string())).await;
    assert_eq!(status, 200, "{body}");
    assert_eq!(server.get("/api/road").await, plain);
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_road_that_drops_goals_clears_them_and_the_uavs_hover() {
    let server = start(config(&small())).await;
    // Right after the start the UAVs are still near x = 2: a road ending at x = 4 keeps them, not their goals.
    let short = json!({"segments": roads::RoadLayout::straight(-2.0, 4.0, 4.0, 1).segments});
    let (status, body) = server.call("PUT", "/api/road", Some(&short.to_string())).await;
    assert_eq!(status, 200, "{body}");
    assert_eq!(body["cleared_goals"], json!(["a", "b"]));
    let speed = |u: &Value| u["v"][0].as_f64().unwrap().hypot(u["v"][1].as_f64().unwrap());
    let state = server.wait_for(8.0, |s| s["uavs"].as_array().unwrap().iter().all(|u| speed(u) < 1e-3)).await;
    for u in state["uavs"].as_array().unwrap() {
        assert!(u["goal"].is_null() && speed(u) < 1e-3, "{u}");
        assert!(u["p"][0].as_f64().unwrap() < 4.0 - 0.1, "{u}");
    }
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn uavs_goals_policies_and_pause() {
    let server = start(config(&small())).await;
    let (status, body) = server
        .call("POST", "/api/uavs", Some(&json!({"id": "c", "position": [10.0, 0.0]}).to_string()))
        .await;
    assert_eq!(status, 201, "{body}");
    server.wait_for(2.0, |s| s["uavs"].as_array().unwrap().len() == 3).await;
    assert_eq!(uav_ids(&server).await, ["a", "b", "c"]);

    for (body, status, field) in [
        (json!({"id": "c", "position": [12.0, 0.0]}), 409, "id"),
        (json!({"id": "d", "position": [12.0, 5.0]}), 422, "position"),
        (json!({"id": "d", "position": [10.1, 0.0]}), 422, "position"),
        (json!({"id": "d", "position": [12.0, 1.95]}), 422, "position"),
        (json!({"id": "d e", "position": [12.0, 0.0]}), 422, "id"),
        (json!({"id": "", "position": [12.0, 0.0]}), 422, "id"),
        (json!({"id": "d", "position": [12.0, 0.0], "policy": "nope"}), 422, "policy"),
        (json!({"id": "d", "position": [12.0, 0.0], "goal": [50.0, 0.0]}), 422, "goal"),
        (json!({"id": "d", "position": [12.0]}), 422, "position"),
        (json!({"id": "d"}), 422, ""),
    ] {
        let (got, reply) = server.call("POST", "/api/uavs", Some(&body.to_string())).await;
        assert_eq!(got, status, "POST {body}: {reply}");
        assert_eq!(error_field(&reply), field, "POST {body}: {reply}");
    }
    tokio::time::sleep(std::time::Duration::from_millis(120)).await;
    assert_eq!(uav_ids(&server).await, ["a", "b", "c"], "refused additions change nothing");

    let goal = |g: Value| json!({"goal": g}).to_string();
    let (status, body) = server.call("PUT", "/api/uavs/zz/goal", Some(&goal(json!([3.0, 0.0])))).await;
    assert_eq!((status, error_field(&body)), (404, "id"));
    let (status, body) = server.call("PUT", "/api/uavs/c/goal", Some(&goal(json!([40.0, 0.0])))).await;
    assert_eq!((status, error_field(&body)), (422, "goal"), "{body}");
    let (status, body) = server.call("PUT", "/api/uavs/c/goal", Some(&goal(json!([14.0, 0.5])))).await;
    assert_eq!(status, 200, "{body}");
    let state = server.wait_for(2.0, |s| s["uavs"][2]["goal"] == json!([14.0, 0.5])).await;
    assert_eq!(state["uavs"][2]["goal"], json!([14.0, 0.5]));
    let (status, _) = server.call("DELETE", "/api/uavs/c/goal", None).await;
    assert_eq!(status, 204);
    server.wait_for(2.0, |s| s["uavs"][2]["goal"].is_null()).await;

    let (status, body) = server.call("PUT", "/api/uavs/c/policy", Some("{\"policy\": \"rl\"}")).await;
    assert_eq!(status, 200, "{body}");
    let (status, body) = server.call("PUT", "/api/uavs/c/policy", Some("{\"policy\": \"x\"}")).await;
    assert_eq!((status, error_field(&body)), (422, "policy"));
    assert_eq!(server.get("/api/policies").await["default"], "pd");

    let (status, body) = server.call("POST", "/api/fleet/pause", None).await;
    assert_eq!((status, &body["paused"]), (200, &json!(true)));
    server.wait_for(2.0, |s| s["paused"] == json!(true)).await;
    let (status, _) = server.call("POST", "/api/fleet/resume", None).await;
    assert_eq!(status, 200);
    server.wait_for(2.0, |s| s["paused"] == json!(false)).await;

    let (status, _) = server.call("DELETE", "/api/uavs/c", None).await;
    assert_eq!(status, 204);
    let (status, body) = server.call("DELETE", "/api/uavs/c", None).await;
    assert_eq!((status, body["error"]["code"].as_str()), (404, Some("unknown_uav")));
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn scenario_over_rest_is_validated() {
    let server = start(config(&small())).await;
    let mut bad = support::shipped("lab3.json");
    bad["uavs"][1]["start"] = json!([100.0, 0.0]);
    let (status, body) = server.call("POST", "/api/scenario", Some(&bad.to_string())).await;
    assert_eq!((status, error_field(&body)), (422, "uavs[1].start"), "{body}");
    let mut bad = support::shipped("lab3.json");
    bad["params"]["delta"] = json!(-1.0);
    let (status, body) = server.call("POST", "/api/scenario", Some(&bad.to_string())).await;
    assert_eq!((status, error_field(&body)), (422, "params.delta"), "{body}");
    assert_eq!(uav_ids(&server).await, ["a", "b"]);
    // A road network loads as well (tests/server_network.rs flies one).
    let network = support::shipped("depot.json");
    let (status, body) = server.call("POST", "/api/scenario", Some(&network.to_string())).await;
    assert_eq!((status, body["uavs"].as_u64()), (200, Some(16)), "{body}");
    let (status, body) =
        server.call("POST", "/api/scenario", Some(&support::shipped("lab3.json").to_string())).await;
    assert_eq!(status, 200, "{body}");
    assert_eq!(body["uavs"], 3);
    server.wait_for(2.0, |s| s["uavs"].as_array().unwrap().len() == 3).await;
    assert_eq!(uav_ids(&server).await, ["cf1", "cf2", "cf3"]);
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_configured_token_guards_changes_but_not_reads() {
    let mut cfg = config(&small());
    cfg.token = Some("s3cret-t0ken-for-tests".into());
    let server = start(cfg).await;
    let body = json!({"id": "c", "position": [10.0, 0.0]}).to_string();
    let (status, reply) = server.call("POST", "/api/uavs", Some(&body)).await;
    assert_eq!((status, reply["error"]["code"].as_str()), (401, Some("unauthorized")));
    let wrong = [("Authorization", "Bearer nope")];
    assert_eq!(server.call_with("POST", "/api/fleet/pause", None, &wrong).await.0, 401);
    let right = [("Authorization", "Bearer s3cret-t0ken-for-tests")];
    assert_eq!(server.call_with("POST", "/api/uavs", Some(&body), &right).await.0, 201);
    assert_eq!(server.call("GET", "/api/uavs", None).await.0, 200);
    assert_eq!(server.call("GET", "/api/state", None).await.0, 200);
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_uav_list_comes_in_pages_and_by_viewport() {
    // 25 UAVs on a 40 m road, five rows of five; pages of 10 walk the fleet in order.
    let uavs: Vec<Value> = (0..25)
        .map(|k| {
            let at = [2.0 + 7.0 * f64::from(k % 5), -1.2 + 0.6 * f64::from(k / 5)];
            json!({"id": format!("u{k:02}"), "start": at, "goal": at})
        })
        .collect();
    let scenario = json!({"name": "pages", "segments": roads::RoadLayout::straight(0.0, 40.0, 4.0, 4).segments, "uavs": uavs});
    let server = start(config(&scenario)).await;
    let all = server.get("/api/uavs").await;
    assert_eq!(all.as_array().unwrap().len(), 25, "without parameters: the whole fleet, as before");
    // Without regions both scopes are this server's fleet; any other scope is refused.
    let ids_of = |list: &Value| list.as_array().unwrap().iter().map(|u| u["id"].clone()).collect::<Vec<_>>();
    assert_eq!(ids_of(&server.get("/api/uavs?scope=region").await), ids_of(&all));
    assert_eq!(ids_of(&server.get("/api/uavs?scope=fleet").await), ids_of(&all));
    let (status, body) = support::raw(server.addr, "GET", "/api/uavs?scope=world", None, &[]).await;
    assert!(status == 422 && body.contains("\"scope\""), "{status} {body}");
    let mut walked = Vec::new();
    let mut after = String::new();
    loop {
        let page = server.get(&format!("/api/uavs?limit=10{after}")).await;
        let page = page.as_array().unwrap();
        assert!(page.len() <= 10);
        if page.is_empty() {
            break;
        }
        walked.extend(page.iter().map(|u| u["id"].as_str().unwrap().to_string()));
        after = format!("&after={}", walked.last().unwrap());
    }
    let ids: Vec<String> =
        all.as_array().unwrap().iter().map(|u| u["id"].as_str().unwrap().to_string()).collect();
    assert_eq!(walked, ids, "three pages, every UAV once, in fleet order");
    // The first column (x ≈ 2 m) through a viewport, fleet order kept.
    let column = server.get("/api/uavs?bbox=0,-3,4,3").await;
    let column: Vec<&str> = column.as_array().unwrap().iter().map(|u| u["id"].as_str().unwrap()).collect();
    assert_eq!(column, ["u00", "u05", "u10", "u15", "u20"]);
    for (query, field) in [
        ("limit=0", "limit"),
        ("limit=1001", "limit"),
        ("limit=-1", "limit"),
        ("after=nobody", "after"),
        ("bbox=1,1,0,0", "bbox"),
        ("bbox=0,0,inf,1", "bbox"),
    ] {
        let (status, reply) = server.call("GET", &format!("/api/uavs?{query}"), None).await;
        assert_eq!((status, reply["error"]["field"].as_str()), (422, Some(field)), "{query}: {reply}");
    }
    // Lookups by id follow the roster: every UAV after one removed in the middle moves up a place.
    let (status, _) = server.call("DELETE", "/api/uavs/u07", None).await;
    assert_eq!(status, 204);
    let (status, _) = server.call("GET", "/api/uavs/u07", None).await;
    assert_eq!(status, 404, "a removed UAV is gone at once");
    for id in ["u00", "u06", "u08", "u24"] {
        assert_eq!(server.get(&format!("/api/uavs/{id}")).await["id"], id);
    }
    let (status, _) =
        server.call("PUT", "/api/uavs/u08/goal", Some(&json!({"goal": [30.0, 0.0]}).to_string())).await;
    assert_eq!(status, 200);
    assert_eq!(server.get("/api/uavs/u08").await["goal"], json!([30.0, 0.0]));
    assert_eq!(server.get("/api/uavs?limit=1&after=u06").await[0]["id"], "u08");
    server.stop().await;
}
