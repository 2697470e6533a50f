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
use std::collections::BTreeMap;
use std::net::SocketAddr;
use std::time::{Duration, Instant};
use support::procs::{D_C, TICK_S, TOLERANCE_M, distance, free_endpoint, get, serve, uavs};

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

/// Every UAV's ownership intervals over all regions, by UAV: `(from, to, region)`, by `from`.
async fn ownership(regions: &[(&str, SocketAddr)]) -> BTreeMap<String, Vec<(f64, f64, String)>> {
    let mut by_uav: BTreeMap<String, Vec<(f64, f64, String)>> = BTreeMap::new();
    for (name, addr) in regions {
        let doc = get(*addr, "/api/region/ownership").await;
        for i in doc["intervals"].as_array().unwrap() {
            let to = i["to"].as_f64().unwrap_or(f64::INFINITY);
            let entry = (i["from"].as_f64().unwrap(), to, name.to_string());
            by_uav.entry(i["id"].as_str().unwrap().to_string()).or_default().push(entry);
        }
    }
    for intervals in by_uav.values_mut() {
        intervals.sort_by(|a, b| a.0.total_cmp(&b.0));
    }
    by_uav
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_divided_network_hands_uavs_over_at_every_border_and_refuses_bad_regions() {
    let path = support::repo().join("scenarios/depot-regions.json");
    let scenario = path.to_str().unwrap();
    let ports: Vec<String> = (0..3).map(|_| free_endpoint()).collect();
    let (_w, west, _) = serve(&["--scenario", scenario, "--region", "west", "--zenoh-listen", &ports[0]]);
    let (_e, east, _) = serve(&[
        "--scenario",
        scenario,
        "--region",
        "east",
        "--zenoh-listen",
        &ports[1],
        "--zenoh-connect",
        &ports[0],
    ]);
    let (_b, branches, _) = serve(&[
        "--scenario",
        scenario,
        "--region",
        "branches",
        "--zenoh-listen",
        &ports[2],
        "--zenoh-connect",
        &ports[0],
        "--zenoh-connect",
        &ports[1],
    ]);
    let regions = [("west", west), ("east", east), ("branches", branches)];
    // Each region flies the UAVs that start in its cells: the spoke's ten, none, the branches' six.
    let mut counts = Vec::new();
    for (_, addr) in regions {
        counts.push(uavs(&get(addr, "/api/state?scope=region").await).len());
    }
    assert_eq!(counts, [10, 0, 6]);
    let started = Instant::now();
    let mut arrived = Vec::new();
    while started.elapsed() < Duration::from_secs(110) {
        let asked = Instant::now();
        let (sw, se, sb) = tokio::join!(
            get(west, "/api/state?scope=region"),
            get(east, "/api/state?scope=region"),
            get(branches, "/api/state?scope=region")
        );
        let skew = asked.elapsed().as_secs_f64() + 2.0 * TICK_S;
        let all: Vec<_> = [&sw, &se, &sb].iter().flat_map(|s| uavs(s)).collect();
        for (i, x) in all.iter().enumerate() {
            for y in &all[i + 1..] {
                let d = distance(x.1, y.1);
                let slack = TOLERANCE_M + distance(x.2, y.2) * skew;
                // The same UAV in two snapshots (taken around its handover) is not a pair.
                assert!(x.0 == y.0 || d >= D_C - slack, "{} and {} {d} m apart", x.0, y.0);
            }
        }
        arrived = all.iter().filter(|u| u.3).map(|u| u.0.clone()).collect();
        arrived.sort();
        arrived.dedup();
        if arrived.len() == FLEET {
            break;
        }
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    assert_eq!(arrived.len(), FLEET, "all arrive within 110 s: {arrived:?}");
    let by_uav = ownership(&regions).await;
    assert_eq!(by_uav.len(), FLEET, "{by_uav:?}");
    let mut longest_gap = 0.0f64;
    for (id, intervals) in &by_uav {
        let path: Vec<&str> = intervals.iter().map(|i| i.2.as_str()).collect();
        let expected =
            if id.starts_with("out") { ["west", "east", "branches"] } else { ["branches", "east", "west"] };
        assert_eq!(path, expected, "{id}: {intervals:?}");
        for pair in intervals.windows(2) {
            let gap = pair[1].0 - pair[0].1;
            assert!(gap >= 0.0, "{id}: owned by {} and {} at once ({intervals:?})", pair[0].2, pair[1].2);
            assert!(gap <= MAX_UNOWNED_S, "{id}: unowned {gap} s between {} and {}", pair[0].2, pair[1].2);
            longest_gap = longest_gap.max(gap);
        }
        assert!(intervals.last().unwrap().1.is_infinite(), "{id}: owned at the end");
    }
    eprintln!("{} handovers on the network, longest unowned gap {longest_gap:.3} s", 2 * FLEET);
    for (_, addr) in regions {
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
    for (_, addr) in regions {
        assert_eq!(get(addr, "/api/road").await, road, "unchanged");
    }
    assert_eq!(get(west, "/api/road/geometry").await["version"], version);
    // The trunk's border moved one segment east, the same neighbours: every region takes it.
    let mut moved = road.clone();
    moved["regions"][0]["roads"][2]["segments"] = json!([0, 3]);
    moved["regions"][1]["roads"][0]["segments"] = json!([4, 5]);
    let (status, body) = send(branches, "PUT", "/api/road", &moved).await;
    assert_eq!(status, 200, "{body}");
    for (_, addr) in regions {
        assert_eq!(get(addr, "/api/road").await["regions"], moved["regions"]);
    }
}
