//! One fleet to the operator: two `airroads serve --region` processes on loopback, and every
//! request sent to either answers for the whole deployment. Reads merge both regions (each UAV
//! tagged with its region, the regions that answered listed); a change about a UAV of the other
//! region is applied by its owner and answered as the owner answers it (errors included); a new
//! UAV goes to the region of its position; a fleet-wide command reaches both; `?scope=region`
//! keeps a read local; and a region that is gone is named (`regions[].answered`, 503
//! `region_unavailable`), never silently left out.

mod support;

use serde_json::{Value, json};
use std::net::SocketAddr;
use std::time::{Duration, Instant};
use support::procs::{self, free_endpoint, get, serve};

/// `METHOD path` with a JSON body; status and body as JSON.
async fn send(addr: SocketAddr, method: &str, path: &str, body: Option<Value>) -> (u16, Value) {
    let text = body.map(|b| b.to_string());
    let headers: &[(&str, &str)] = if text.is_some() { &[("content-type", "application/json")] } else { &[] };
    let (status, body) = support::raw(addr, method, path, text.as_deref(), headers).await;
    (status, serde_json::from_str(&body).unwrap_or(Value::Null))
}

/// The ids of a list of UAVs (`/api/uavs`, or a state's `uavs`), in order.
fn ids(list: &Value) -> Vec<String> {
    list.as_array().unwrap().iter().map(|u| u["id"].as_str().unwrap().to_string()).collect()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn any_region_answers_for_the_whole_fleet() {
    let dir = procs::scratch("federation", "two");
    let scenario = json!({
        "name": "federation",
        "segments": roads::RoadLayout::straight(0.0, 40.0, 4.0, 8).segments,
        "regions": [{"name": "west", "segments": [0, 3]}, {"name": "east", "segments": [4, 7]}],
        "uavs": [
            {"id": "w1", "start": [5.0, 0.0], "goal": [5.0, 0.0]},
            {"id": "w2", "start": [10.0, 1.0], "goal": [10.0, 1.0]},
            {"id": "e1", "start": [30.0, 0.0], "goal": [30.0, 0.0]},
            {"id": "e2", "start": [35.0, -1.0], "goal": [35.0, -1.0]}
        ]
    });
    let path = dir.join("federation.json");
    std::fs::write(&path, scenario.to_string()).unwrap();
    let scenario = path.to_str().unwrap();
    let endpoint = free_endpoint();
    let (_west, w, _) = serve(&["--scenario", scenario, "--region", "west", "--zenoh-listen", &endpoint]);
    let (mut east_proc, e, _) =
        serve(&["--scenario", scenario, "--region", "east", "--zenoh-connect", &endpoint]);
    // Until the two sessions found each other.
    let started = Instant::now();
    let mut state = get(w, "/api/state").await;
    while state["uavs"].as_array().unwrap().len() < 4 {
        assert!(started.elapsed() < Duration::from_secs(15), "never merged: {state}");
        tokio::time::sleep(Duration::from_millis(100)).await;
        state = get(w, "/api/state").await;
    }
    // Reads: both regions, each UAV tagged with its own; a scoped read stays local.
    let mut all = ids(&state["uavs"]);
    all.sort();
    assert_eq!(all, ["e1", "e2", "w1", "w2"]);
    for u in state["uavs"].as_array().unwrap() {
        let region = if u["id"].as_str().unwrap().starts_with('w') { "west" } else { "east" };
        assert_eq!(u["region"], region, "{u}");
    }
    let names: Vec<(&str, bool)> = state["regions"]
        .as_array()
        .unwrap()
        .iter()
        .map(|r| (r["name"].as_str().unwrap(), r["answered"] == true))
        .collect();
    assert_eq!(names, [("west", true), ("east", true)]);
    assert_eq!(ids(&get(w, "/api/state?scope=region").await["uavs"]), ["w1", "w2"]);
    assert_eq!(ids(&get(e, "/api/uavs").await), ["w1", "w2", "e1", "e2"], "the road's region order");
    assert_eq!(ids(&get(w, "/api/uavs?limit=1&after=w2").await), ["e1"]);
    assert_eq!(ids(&get(w, "/api/uavs?bbox=25,-2,40,2").await), ["e1", "e2"]);
    let (status, body) = send(w, "GET", "/api/state?scope=everything", None).await;
    assert_eq!((status, &body["error"]["field"]), (422, &json!("scope")), "{body}");
    assert_eq!(get(w, "/api/uavs/e2").await["id"], "e2");
    // A change about the other region's UAV is applied there, and answered as there.
    let (status, body) = send(w, "PUT", "/api/uavs/e1/goal", Some(json!({"goal": [38.0, 0.0]}))).await;
    assert_eq!((status, body.clone()), (200, json!({"id": "e1", "goal": [38.0, 0.0]})), "{body}");
    assert_eq!(get(e, "/api/uavs/e1?scope=region").await["goal"], json!([38.0, 0.0]));
    let outside = json!({"goal": [100.0, 0.0]});
    let via_west = send(w, "PUT", "/api/uavs/e1/goal", Some(outside.clone())).await;
    let at_east = send(e, "PUT", "/api/uavs/e1/goal", Some(outside)).await;
    assert!(via_west.0 >= 400 && via_west.0 < 500, "{via_west:?}");
    assert_eq!(via_west, at_east, "an error keeps its meaning");
    let (status, body) = send(w, "DELETE", "/api/uavs/nobody", None).await;
    assert_eq!((status, &body["error"]["code"]), (404, &json!("unknown_uav")), "{body}");
    // A new UAV goes to the region of its position.
    let (status, body) =
        send(w, "POST", "/api/uavs", Some(json!({"id": "n1", "position": [32.0, 1.5]}))).await;
    assert_eq!(status, 201, "{body}");
    assert!(ids(&get(e, "/api/uavs?scope=region").await).contains(&"n1".to_string()));
    assert!(!ids(&get(w, "/api/uavs?scope=region").await).contains(&"n1".to_string()));
    // A fleet-wide command reaches both regions.
    let (status, body) = send(e, "POST", "/api/fleet/pause", None).await;
    assert_eq!(status, 200, "{body}");
    assert_eq!(
        (body["regions"]["west"]["status"].clone(), body["regions"]["east"]["status"].clone()),
        (json!(200), json!(200))
    );
    for addr in [w, e] {
        assert_eq!(get(addr, "/api/state?scope=region").await["paused"], true);
    }
    assert_eq!(send(w, "POST", "/api/fleet/resume", None).await.0, 200);
    assert_eq!(get(e, "/api/state?scope=region").await["paused"], false);
    // A region that is gone is named, and a change for its UAV is not taken for unknown.
    east_proc.kill();
    let state = get(w, "/api/state").await;
    assert_eq!(ids(&state["uavs"]), ["w1", "w2"]);
    assert_eq!(state["regions"][1], json!({"name": "east", "answered": false}), "{}", state["regions"]);
    let (status, body) = send(w, "PUT", "/api/uavs/e1/goal", Some(json!({"goal": [38.0, 1.0]}))).await;
    assert_eq!(
        (status, &body["error"]["code"], &body["error"]["region"]),
        (503, &json!("region_unavailable"), &json!("east")),
        "{body}"
    );
}

/// A straight road x ∈ [0, 40] of 8 segments, `width` wide, in the regions west (0–3) and east (4–7).
fn road(width: f64) -> Value {
    json!({
        "segments": roads::RoadLayout::straight(0.0, 40.0, width, 8).segments,
        "regions": [{"name": "west", "segments": [0, 3]}, {"name": "east", "segments": [4, 7]}]
    })
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_road_or_a_scenario_sent_to_any_region_switches_every_region_or_none() {
    let dir = procs::scratch("federation", "deploy");
    let mut scenario = road(4.0);
    scenario["name"] = json!("deploy");
    scenario["uavs"] = json!([
        {"id": "w1", "start": [5.0, 0.0], "goal": [5.0, 0.0]},
        {"id": "w2", "start": [10.0, 0.5], "goal": [10.0, 0.5]},
        {"id": "e1", "start": [30.0, 0.0], "goal": [30.0, 0.0]},
        {"id": "e2", "start": [35.0, -1.5], "goal": [35.0, -1.5]}
    ]);
    let path = dir.join("deploy.json");
    std::fs::write(&path, scenario.to_string()).unwrap();
    let scenario = path.to_str().unwrap();
    let endpoint = free_endpoint();
    let (_west, w, _) = serve(&["--scenario", scenario, "--region", "west", "--zenoh-listen", &endpoint]);
    let (_east, e, _) = serve(&["--scenario", scenario, "--region", "east", "--zenoh-connect", &endpoint]);
    let started = Instant::now();
    while get(w, "/api/state").await["uavs"].as_array().unwrap().len() < 4 {
        assert!(started.elapsed() < Duration::from_secs(15), "the regions never met");
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    let version = |doc: &Value| doc["version"].as_u64().unwrap();
    let segments = |doc: &Value| doc["segments"].clone();
    let before = (version(&get(w, "/api/road/geometry").await), version(&get(e, "/api/road/geometry").await));
    // A wider road sent to the west: both regions switch, at one instant announced in the answer.
    let (status, body) = send(w, "PUT", "/api/road", Some(road(6.0))).await;
    assert_eq!(status, 200, "{body}");
    // One tick boundary for all (a multiple of dt = 50 ms), and every region switched in its gap:
    // within half a tick of it on this one machine's clock.
    let at = body["switch_at_ms"].as_u64().unwrap();
    assert_eq!(at % 50, 0, "{body}");
    for region in ["west", "east"] {
        let switched = body["regions"][region]["body"]["switched_at_ms"].as_u64().unwrap();
        assert!(switched.abs_diff(at) < 25, "{region} switched at {switched}, the boundary is {at}");
    }
    assert_eq!(
        (body["regions"]["west"]["status"].clone(), body["regions"]["east"]["status"].clone()),
        (json!(200), json!(200))
    );
    for addr in [w, e] {
        assert_eq!(segments(&get(addr, "/api/road").await), road(6.0)["segments"], "switched");
    }
    let after = (version(&get(w, "/api/road/geometry").await), version(&get(e, "/api/road/geometry").await));
    assert!(after.0 > before.0 && after.1 > before.1, "{before:?} → {after:?}");
    // A road that e2 (y = -1.5) would be outside of: the east refuses, so neither switches.
    let (status, body) = send(w, "PUT", "/api/road", Some(road(2.4))).await;
    assert_eq!((status, &body["error"]["region"]), (409, &json!("east")), "{body}");
    for addr in [w, e] {
        assert_eq!(segments(&get(addr, "/api/road").await), road(6.0)["segments"], "unchanged");
        assert_eq!(
            version(&get(addr, "/api/road/geometry").await),
            if addr == w { after.0 } else { after.1 }
        );
    }
    // A road without the deployment's regions is refused before anyone is asked.
    let plain = json!({"segments": roads::RoadLayout::straight(0.0, 40.0, 6.0, 8).segments});
    let (status, body) = send(e, "PUT", "/api/road", Some(plain)).await;
    assert_eq!((status, &body["error"]["field"]), (422, &json!("regions")), "{body}");
    // A scenario sent to the east: each region takes the UAVs that start in it.
    let mut next = road(4.0);
    next["name"] = json!("next");
    next["uavs"] = json!([
        {"id": "a1", "start": [8.0, 0.0], "goal": [8.0, 0.0]},
        {"id": "b1", "start": [28.0, 0.0], "goal": [28.0, 0.0]},
        {"id": "b2", "start": [32.0, 0.0], "goal": [32.0, 0.0]}
    ]);
    let (status, body) = send(e, "POST", "/api/scenario", Some(next)).await;
    assert_eq!(status, 200, "{body}");
    assert_eq!(
        (body["name"].clone(), body["uavs"].clone()),
        (json!("next"), json!(2)),
        "the east's share: {body}"
    );
    assert_eq!(ids(&get(w, "/api/uavs?scope=region").await), ["a1"]);
    assert_eq!(ids(&get(e, "/api/uavs?scope=region").await), ["b1", "b2"]);
    assert_eq!(segments(&get(w, "/api/road").await), road(4.0)["segments"]);
}
