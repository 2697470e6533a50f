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
