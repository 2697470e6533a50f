//! End-to-end tests of the server flying road networks: a network put over REST (and read back,
//! drawn, flown through its junctions by UAVs added over REST), refused when it or its regions are
//! broken, with nothing changed, loaded as a scenario, resumed after a restart, and served
//! from `serve --scenario` as a process.

mod support;

use serde_json::{Value, json};
use support::{Running, config, small, start};

/// The depot's network layout (`scenarios/depot.json`): six roads and two junctions.
fn depot_layout() -> Value {
    let depot = support::shipped("depot.json");
    json!({"roads": depot["roads"], "junctions": depot["junctions"]})
}

fn error_field(body: &Value) -> &str {
    body["error"]["field"].as_str().unwrap_or_default()
}

async fn put_road(server: &Running, layout: &Value) -> (u16, Value) {
    server.call("PUT", "/api/road", Some(&layout.to_string())).await
}

fn uav<'a>(state: &'a Value, id: &str) -> &'a Value {
    state["uavs"].as_array().unwrap().iter().find(|u| u["id"] == id).unwrap_or(&Value::Null)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_network_put_over_rest_is_read_back_drawn_and_flown_through_its_junctions() {
    let server = start(config(&small())).await;
    let before = server.get("/api/road/geometry").await;
    assert!(before.get("cells").is_none(), "a chain road has no cells: {before}");
    let layout = depot_layout();
    let (status, body) = put_road(&server, &layout).await;
    assert_eq!(status, 200, "{body}");
    assert!(body["version"].as_u64().unwrap() > before["version"].as_u64().unwrap(), "{body}");
    // Read back as put (the defaults written out: no junction is left out, one_way false).
    let road = server.get("/api/road").await;
    assert_eq!(road["junctions"], layout["junctions"]);
    let names: Vec<&str> =
        road["roads"].as_array().unwrap().iter().map(|r| r["name"].as_str().unwrap()).collect();
    assert_eq!(names, ["trunk", "west-spoke", "pads", "branch-north", "branch-south", "branch-east"]);
    for (k, r) in road["roads"].as_array().unwrap().iter().enumerate() {
        assert_eq!(r["segments"], layout["roads"][k]["segments"], "roads[{k}]");
    }
    // The geometry: every cell, the junctions by name, walls, no centre line.
    let geometry = server.get("/api/road/geometry").await;
    let cells = geometry["cells"].as_array().unwrap();
    assert_eq!(cells.len(), 6 + 5 + 3 + 5 + 5 + 5 + 2);
    let junctions: Vec<&str> =
        cells.iter().filter(|c| c["kind"] == "junction").map(|c| c["name"].as_str().unwrap()).collect();
    assert_eq!(junctions, ["depot", "fork"]);
    assert!(cells.iter().all(|c| c["polygon"].as_array().unwrap().len() >= 3));
    assert!(geometry["walls"].as_array().unwrap().len() > cells.len(), "{}", geometry["walls"]);
    assert_eq!(geometry["centerline"], json!([]));
    assert_eq!(geometry["layout"], road);
    assert!(geometry["min_passage_m"].as_f64().unwrap() > 0.0);

    // UAVs on different roads, each with a goal on another road, through the depot or the fork.
    let goals = [("a", [-8.0, -1.0]), ("b", [1.0, 9.0])];
    for (id, goal) in goals {
        let (status, body) = server
            .call("PUT", &format!("/api/uavs/{id}/goal"), Some(&json!({"goal": goal}).to_string()))
            .await;
        assert_eq!(status, 200, "{id}: {body}");
    }
    let added = [("c", [-7.0, 1.0], [-1.0, 12.0]), ("d", [40.0, 0.0], [30.0, 9.0])];
    for (id, position, goal) in added {
        let new = json!({"id": id, "position": position, "goal": goal}).to_string();
        let (status, body) = server.call("POST", "/api/uavs", Some(&new)).await;
        assert_eq!(status, 201, "{id}: {body}");
    }
    // A goal outside the network (between the trunk and a branch) is refused, naming `goal`.
    let (status, body) =
        server.call("PUT", "/api/uavs/d/goal", Some(&json!({"goal": [20.0, 10.0]}).to_string())).await;
    assert_eq!((status, error_field(&body)), (422, "goal"), "{body}");
    let state =
        server.wait_for(90.0, |s| s["uavs"].as_array().unwrap().iter().all(|u| u["arrived"] == true)).await;
    for (id, goal) in goals.iter().copied().chain(added.iter().map(|&(id, _, goal)| (id, goal))) {
        let u = uav(&state, id);
        assert_eq!(u["arrived"], true, "`{id}` did not arrive: {u}");
        let p = [u["p"][0].as_f64().unwrap(), u["p"][1].as_f64().unwrap()];
        assert!(support::procs::distance(p, goal) < 0.5, "`{id}` at {p:?}, goal {goal:?}");
    }
    let metrics = server.get("/api/metrics").await;
    assert_eq!(metrics["qp"]["failures"], 0, "{metrics}");
    // The margins (the closest approach if braking now) stayed above D_c and D_s since the road
    // changed: no safety violation.
    let (d_c, d_s) = (state["d_c"].as_f64().unwrap(), state["d_s"].as_f64().unwrap());
    let collision = metrics["min_collision_margin_m"].as_f64().unwrap();
    assert!(collision >= d_c, "a pair came within D_c = {d_c} m: margin {collision} m");
    let road_margin = metrics["min_road_margin_m"].as_f64().unwrap();
    assert!(road_margin >= d_s, "a UAV came within D_s = {d_s} m of a wall: margin {road_margin} m");
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_broken_or_divided_network_is_refused_naming_the_field_and_changes_nothing() {
    let server = start(config(&small())).await;
    let chain = server.get("/api/road").await;
    let geometry = server.get("/api/road/geometry").await;
    // The trunk's first segment folded over itself.
    let mut broken = depot_layout();
    broken["roads"][0]["segments"][0][0] = json!([1.0, 2.0]);
    let (status, body) = put_road(&server, &broken).await;
    assert_eq!((status, body["error"]["code"].as_str()), (422, Some("invalid_road")), "{body}");
    assert_eq!(
        (error_field(&body), body["error"]["rule"].as_str()),
        ("roads[0].segments[0]", Some("not_convex"))
    );
    // The trunk's first segment no longer meets the depot junction's side: the west spoke is cut off.
    let mut cut = depot_layout();
    cut["roads"][0]["segments"][0][1][0] = json!(2.3);
    let (status, body) = put_road(&server, &cut).await;
    assert_eq!((status, body["error"]["rule"].as_str()), (422, Some("disconnected")), "{body}");
    assert!(error_field(&body).starts_with("roads[1].segments["), "{body}");
    // A junction moved off the roads' ends.
    let mut moved = depot_layout();
    moved["junctions"][1]["polygon"][0] = json!([27.0, -2.5]);
    let (status, body) = put_road(&server, &moved).await;
    assert_eq!(status, 422, "{body}");
    assert!(
        error_field(&body).starts_with("junctions[1]") || error_field(&body).starts_with("roads["),
        "{body}"
    );
    // Two roads of one name.
    let mut twice = depot_layout();
    twice["roads"][1]["name"] = json!("trunk");
    let (status, body) = put_road(&server, &twice).await;
    assert_eq!(
        (status, error_field(&body), body["error"]["rule"].as_str()),
        (422, "roads[1].name", Some("duplicate_name"))
    );
    // Too narrow for a UAV to pass with the fleet's parameters.
    let narrow = json!({"roads": [{"name": "thin", "segments": roads::RoadLayout::straight(0.0, 20.0, 0.6, 2).segments}]});
    let (status, body) = put_road(&server, &narrow).await;
    assert_eq!((status, body["error"]["rule"].as_str()), (422, Some("narrow_passage")), "{body}");
    // A network's regions are sets of cells that cover it: a chain's segment range is not one, and
    // one region of the trunk alone leaves the other cells out.
    let mut divided = depot_layout();
    divided["regions"] = json!([{"name": "all", "segments": [0, 5]}]);
    let (status, body) = put_road(&server, &divided).await;
    assert_eq!(status, 422, "{body}");
    assert!(error_field(&body).starts_with("regions[0]"), "{body}");
    divided["regions"] = json!([{"name": "all", "roads": [{"road": "trunk", "segments": [0, 5]}]}]);
    let (status, body) = put_road(&server, &divided).await;
    assert_eq!(
        (status, error_field(&body), body["error"]["rule"].as_str()),
        (422, "regions", Some("region_gap"))
    );
    assert!(body["error"]["message"].as_str().unwrap().contains("road `west-spoke`"), "{body}");
    // A network the UAVs (at x = 2) would be outside of: 409, naming `roads`.
    let far = json!({"roads": [{"name": "far", "segments": roads::RoadLayout::straight(50.0, 70.0, 4.0, 2).segments}]});
    let (status, body) = put_road(&server, &far).await;
    assert_eq!((status, error_field(&body)), (409, "roads"), "{body}");
    // Nothing changed.
    assert_eq!(server.get("/api/road").await, chain);
    assert_eq!(server.get("/api/road/geometry").await["version"], geometry["version"]);
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_network_scenario_loads_over_rest_and_a_chain_road_replaces_it() {
    let server = start(config(&small())).await;
    let depot = support::shipped("depot.json");
    let (status, body) = server.call("POST", "/api/scenario", Some(&depot.to_string())).await;
    assert_eq!((status, body["uavs"].as_u64()), (200, Some(16)), "{body}");
    let road = server.get("/api/road").await;
    assert_eq!(road["roads"].as_array().unwrap().len(), 6);
    assert_eq!(road["junctions"], depot["junctions"]);
    // Its UAVs fly: one bound for a branch has left its start within a few seconds.
    let start = [-6.0, -1.0];
    let state = server
        .wait_for(10.0, |s| {
            let u = uav(s, "out0");
            u["p"].as_array().is_some_and(|p| {
                support::procs::distance([p[0].as_f64().unwrap(), p[1].as_f64().unwrap()], start) > 1.0
            })
        })
        .await;
    assert!(uav(&state, "out0")["p"][0].as_f64().unwrap() > start[0] + 1.0, "{}", uav(&state, "out0"));
    // A network scenario with a chain's regions is refused, naming them.
    let mut divided = depot.clone();
    divided["regions"] = json!([{"name": "all", "segments": [0, 5]}]);
    let (status, body) = server.call("POST", "/api/scenario", Some(&divided.to_string())).await;
    assert_eq!((status, error_field(&body)), (422, "regions"), "{body}");
    // Back to one road, over the same route as before networks.
    let (status, body) = server.call("POST", "/api/scenario", Some(&small().to_string())).await;
    assert_eq!(status, 200, "{body}");
    let road = server.get("/api/road").await;
    assert_eq!(road, json!({"segments": small()["segments"]}));
    assert!(server.get("/api/road/geometry").await.get("cells").is_none());
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_network_put_over_rest_is_resumed_after_a_restart() {
    let dir = std::env::temp_dir().join(format!("airroads-network-resume-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let with_dir = |c: &mut airroads_server::serve::ServeConfig| {
        c.data_dir = Some(dir.clone());
        c.resume = true;
    };
    let server = support::start_with(&small(), with_dir).await;
    let layout = depot_layout();
    assert_eq!(put_road(&server, &layout).await.0, 200);
    let road = server.get("/api/road").await;
    let new = json!({"id": "p", "position": [0.0, 10.0], "goal": [30.0, 12.0]}).to_string();
    assert_eq!(server.call("POST", "/api/uavs", Some(&new)).await.0, 201);
    server.stop().await;

    let server = support::start_with(&small(), with_dir).await;
    assert_eq!(server.get("/api/road").await, road, "the network is resumed");
    assert_eq!(server.get("/api/road/geometry").await["cells"].as_array().map(Vec::len), Some(31));
    let state = server.get("/api/state").await;
    assert_eq!(uav(&state, "p")["goal"], json!([30.0, 12.0]), "{state}");
    // A chain road put now replaces the saved network.
    let chain = json!({"segments": roads::RoadLayout::straight(-2.0, 40.0, 30.0, 3).segments});
    let (status, body) = put_road(&server, &chain).await;
    assert_eq!(status, 200, "{body}");
    server.stop().await;
    let server = support::start_with(&small(), with_dir).await;
    assert_eq!(server.get("/api/road").await, chain);
    server.stop().await;
    std::fs::remove_dir_all(&dir).unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn serve_flies_a_network_scenario_and_refuses_to_divide_it_without_regions() {
    let depot = support::repo().join("scenarios/depot.json");
    let (_server, addr, _) =
        support::procs::serve(&["--scenario", depot.to_str().unwrap(), "--policy", "pd"]);
    let road = support::procs::get(addr, "/api/road").await;
    assert_eq!(road["junctions"].as_array().map(Vec::len), Some(2), "{road}");
    let state = support::procs::get(addr, "/api/state").await;
    assert_eq!(state["uavs"].as_array().map(Vec::len), Some(16));
    // A network without regions cannot be divided: `--region` exits 2, saying so.
    let divided = std::process::Command::new(env!("CARGO_BIN_EXE_airroads"))
        .args(["serve", "--addr", "127.0.0.1:0", "--ephemeral", "--zenoh-insecure"])
        .args(["--scenario", depot.to_str().unwrap(), "--region", "west"])
        .env_remove("AIRROADS_TOKEN")
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&divided.stderr);
    assert_eq!(divided.status.code(), Some(2), "{err}");
    assert!(err.contains("`west`: the network has no regions"), "{err}");
}
