//! Regions of a road network: `scenarios/depot-regions.json` (the depot with its spoke and pads, a
//! trunk to a fork, three branches) flown by three `airroads serve --region` processes on loopback
//! over Zenoh with TLS: `west` (the depot, its spoke, the pads, the trunk's first half), `east` (the
//! trunk's second half and the fork) and `branches`. The borders cut the trunk and separate the
//! fork from its branches. Ten UAVs fly from the spoke to the branches and six from the branches to
//! the pads: each is handed over at both borders in order, the ownership logs never overlap for a
//! UAV and leave it unowned for at most `MAX_UNOWNED_S`, every pair stays D_c apart, all arrive.
//! Then the refusals of a network's regions over REST (422 naming the field and the rule, nothing
//! changed), and a deployment-wide network with a moved border taken by all three.

mod support;

use serde_json::{Value, json};
use std::net::SocketAddr;
use std::time::Duration;
use support::procs::{get, uavs};
use support::regions::{assert_handed_over, fly_until_arrived, ownership, serve_regions};

/// The stated bound on a UAV's unowned time in a handover (docs/regions.md, Handover).
const MAX_UNOWNED_S: f64 = 0.25;
/// UAVs in the scenario.
const FLEET: usize = 16;

/// A change that breaks a network's regions, the field and the rule the 422 names.
type Refusal = (fn(&mut Value), &'static str, &'static str);

/// `METHOD path` with a JSON body; status and body as JSON.
async fn send(addr: SocketAddr, method: &str, path: &str, body: &Value) -> (u16, Value) {
    let text = body.to_string();
    let headers: &[(&str, &str)] = &[("content-type", "application/json")];
    let (status, body) = support::raw(addr, method, path, Some(&text), headers).await;
    (status, serde_json::from_str(&body).unwrap_or(Value::Null))
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_divided_network_hands_uavs_over_at_every_border_and_refuses_bad_regions() {
    let path = support::repo().join("scenarios/depot-regions.json");
    let scenario = path.to_str().unwrap();
    let (_servers, regions) = serve_regions(scenario, &["west", "east", "branches"]);
    let (west, east, branches) = (regions[0].1, regions[1].1, regions[2].1);
    // Each region flies the UAVs that start in its cells: the spoke's ten, none, the branches' six.
    let mut counts = Vec::new();
    for &(_, addr) in &regions {
        counts.push(uavs(&get(addr, "/api/state?scope=region").await).len());
    }
    assert_eq!(counts, [10, 0, 6]);
    let arrived = fly_until_arrived(&regions, FLEET, Duration::from_secs(110)).await;
    assert_eq!(arrived.len(), FLEET, "all arrive within 110 s: {arrived:?}");
    let by_uav = ownership(&regions).await;
    assert_eq!(by_uav.len(), FLEET, "{by_uav:?}");
    let path = |id: &str| {
        if id.starts_with("out") {
            vec!["west", "east", "branches"]
        } else {
            vec!["branches", "east", "west"]
        }
    };
    let longest_gap = assert_handed_over(&by_uav, path, MAX_UNOWNED_S);
    eprintln!("{} handovers on the network, longest unowned gap {longest_gap:.3} s", 2 * FLEET);
    for &(_, addr) in &regions {
        let metrics = get(addr, "/api/metrics").await;
        assert_eq!(metrics["region"]["refused"], 0, "{}", metrics["region"]);
        assert_eq!(metrics["region"]["handover"]["refused"], 0, "{}", metrics["region"]);
    }

    // Refusals over REST: each names the field and the rule, and changes nothing.
    let road = get(west, "/api/road").await;
    let version = get(west, "/api/road/geometry").await["version"].clone();
    let cases: [Refusal; 8] = [
        (|r| r["regions"][1]["roads"][0]["road"] = json!("nowhere"), "regions[1].roads[0]", "unknown_name"),
        (|r| r["regions"][1]["junctions"][0] = json!("nowhere"), "regions[1].junctions[0]", "unknown_name"),
        (
            |r| r["regions"][1]["roads"][0]["segments"] = json!([5, 3]),
            "regions[1].roads[0]",
            "reversed_region",
        ),
        (
            |r| r["regions"][1]["roads"][0]["segments"] = json!([3, 6]),
            "regions[1].roads[0]",
            "region_out_of_range",
        ),
        (
            |r| r["regions"][1]["roads"][0]["segments"] = json!([2, 5]),
            "regions[1].roads[0]",
            "region_overlap",
        ),
        (|r| r["regions"][1]["roads"][0]["segments"] = json!([4, 5]), "regions", "region_gap"),
        (|r| r["regions"][2]["junctions"] = json!(["fork"]), "regions[2].junctions[0]", "region_overlap"),
        (|r| r["regions"][2]["name"] = json!("west"), "regions[2].name", "duplicate_region_name"),
    ];
    for (k, (change, field, rule)) in cases.iter().enumerate() {
        let mut bad = road.clone();
        change(&mut bad);
        // This region alone, then the whole deployment (every region refuses it at the prepare).
        for path in ["/api/road?scope=region", "/api/road"] {
            let (status, body) = send(west, "PUT", path, &bad).await;
            let error = &body["error"];
            assert_eq!(
                (status, &error["field"], &error["rule"]),
                (422, &json!(field), &json!(rule)),
                "{k} {path}: {body}"
            );
        }
    }
    // A network without the deployment's regions is refused naming `regions`.
    let mut plain = road.clone();
    plain.as_object_mut().unwrap().remove("regions");
    let (status, body) = send(east, "PUT", "/api/road", &plain).await;
    assert_eq!((status, &body["error"]["field"]), (422, &json!("regions")), "{body}");
    for &(_, addr) in &regions {
        assert_eq!(get(addr, "/api/road").await, road, "unchanged");
    }
    assert_eq!(get(west, "/api/road/geometry").await["version"], version);
    // The trunk's border moved one segment east, the same neighbours: every region takes it.
    let mut moved = road.clone();
    moved["regions"][0]["roads"][2]["segments"] = json!([0, 3]);
    moved["regions"][1]["roads"][0]["segments"] = json!([4, 5]);
    let (status, body) = send(branches, "PUT", "/api/road", &moved).await;
    assert_eq!(status, 200, "{body}");
    for &(_, addr) in &regions {
        assert_eq!(get(addr, "/api/road").await["regions"], moved["regions"]);
    }
}
