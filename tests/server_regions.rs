//! Two `airroads serve --region` processes on loopback, joined over Zenoh (one listens, the other
//! connects; multicast scouting is off whenever endpoints are given, so runs never see each other).
//! A road of two regions, UAVs of each flying head-on across the border into the other: each region
//! sees the other's UAVs (`/api/metrics` `region`) and every pair, own and foreign, stays D_c apart.
//! Three regions as three processes: UAVs fly through all three and are handed over at each
//! border; the regions' ownership logs (`/api/region/ownership`) never overlap for a UAV and leave
//! it unowned for at most `MAX_UNOWNED_S`; every UAV arrives, every pair D_c apart.
//! Crazyflies (cfsim, in a process of their own) handed over both ways: the old owner closes the
//! link without landing, the new one opens it; one owner at every moment, unowned at most
//! `MAX_UNOWNED_LINK_S`, none came down, every pair D_c apart by the simulators' own state.
//! Also: `--region` errors name the region and the known ones.

mod support;

use serde_json::{Value, json};
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};
use support::procs::{self, D_C, TICK_S, TOLERANCE_M, distance, free_endpoint, get, serve, uavs};
use support::regions::{assert_handed_over, fly_until_arrived, ownership, serve_regions};

/// The stated bound on a UAV's unowned time in a handover (`region::handover::MAX_UNOWNED_S`).
const MAX_UNOWNED_S: f64 = 0.25;
/// The same for a Crazyflie, whose old link closes first (`region::handover::MAX_UNOWNED_LINK_S`).
const MAX_UNOWNED_LINK_S: f64 = 1.0;

fn scratch(name: &str) -> PathBuf {
    procs::scratch("regions", name)
}

/// A straight road from x = 0 to 40 (8 segments of 5 m, 4 m wide): `west` segments 0–3, `east` 4–7.
/// Two UAVs start in each region and fly into the other, head-on through the border at x = 20.
fn two_region_scenario(dir: &Path) -> PathBuf {
    let scenario = json!({
        "name": "border",
        "segments": roads::RoadLayout::straight(0.0, 40.0, 4.0, 8).segments,
        "regions": [{"name": "west", "segments": [0, 3]}, {"name": "east", "segments": [4, 7]}],
        "uavs": [
            {"id": "w1", "start": [14.0, 0.1], "goal": [32.0, 0.1]},
            {"id": "w2", "start": [12.0, -1.0], "goal": [30.0, -1.0]},
            {"id": "e1", "start": [26.0, -0.1], "goal": [8.0, -0.1]},
            {"id": "e2", "start": [28.0, 1.0], "goal": [10.0, 1.0]}
        ]
    });
    let path = dir.join("border.json");
    std::fs::write(&path, scenario.to_string()).unwrap();
    path
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn two_regions_see_each_other_and_keep_d_c_across_the_border() {
    let dir = scratch("border");
    let scenario = two_region_scenario(&dir);
    let scenario = scenario.to_str().unwrap();
    let endpoint = free_endpoint();
    let (_west, west, _) = serve(&["--scenario", scenario, "--region", "west", "--zenoh-listen", &endpoint]);
    let (_east, east, _) = serve(&["--scenario", scenario, "--region", "east", "--zenoh-connect", &endpoint]);
    // Each region flies only the UAVs that start in it.
    let ids = |state: &Value| uavs(state).into_iter().map(|u| u.0).collect::<Vec<_>>();
    assert_eq!(ids(&get(west, "/api/state?scope=region").await), ["w1", "w2"]);
    assert_eq!(ids(&get(east, "/api/state?scope=region").await), ["e1", "e2"]);
    let started = Instant::now();
    let (mut seen_west, mut seen_east) = (false, false);
    let mut closest = f64::INFINITY;
    let mut crossed = false;
    while started.elapsed() < Duration::from_secs(20) {
        let asked = Instant::now();
        let (w, e) = tokio::join!(get(west, "/api/state?scope=region"), get(east, "/api/state?scope=region"));
        let skew = asked.elapsed().as_secs_f64() + 2.0 * TICK_S;
        let (w, e) = (uavs(&w), uavs(&e));
        for (list, name) in [(&w, "west"), (&e, "east")] {
            for (i, a) in list.iter().enumerate() {
                for b in &list[i + 1..] {
                    let d = distance(a.1, b.1);
                    assert!(d >= D_C - TOLERANCE_M, "{name}: {} and {} {d} m apart", a.0, b.0);
                }
            }
        }
        // Across the regions the two snapshots were taken up to `skew` apart: allow the distance
        // the pair's relative speed covers in that time.
        for a in &w {
            // A UAV handed over between the two requests is in both snapshots: not a pair.
            for b in e.iter().filter(|b| b.0 != a.0) {
                let d = distance(a.1, b.1);
                let closing = distance(a.2, b.2);
                closest = closest.min(d);
                assert!(
                    d >= D_C - TOLERANCE_M - closing * skew,
                    "{} (west) and {} (east) {d} m apart (skew {skew} s, relative speed {closing} m/s)",
                    a.0,
                    b.0
                );
            }
        }
        crossed |= w.iter().any(|u| u.1[0] > 20.0) || e.iter().any(|u| u.1[0] < 20.0);
        let (mw, me) = tokio::join!(get(west, "/api/metrics"), get(east, "/api/metrics"));
        seen_west |= mw["region"]["foreign_uavs"] == 2 && mw["region"]["heard"]["east"]["uavs"] == 2;
        seen_east |= me["region"]["foreign_uavs"] == 2 && me["region"]["heard"]["west"]["uavs"] == 2;
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    assert!(seen_west && seen_east, "each region must see the other's two UAVs");
    assert!(crossed, "some UAV must have crossed the border");
    assert!(closest < 3.0, "the UAVs must have met (closest {closest} m)");
    for metrics in [get(west, "/api/metrics").await, get(east, "/api/metrics").await] {
        assert_eq!(metrics["region"]["refused"], 0, "{}", metrics["region"]);
    }
}

/// UAVs flying each way in the three-region test (30 in all).
const EACH_WAY: usize = 15;

/// A straight road x ∈ [0, 60] (12 segments of 5 m, 4 m wide) in three regions `a` 0–3, `b` 4–7,
/// `c` 8–11, with [`EACH_WAY`] UAVs flying from each end to the other through all three: a grid of
/// starts at one end, a grid of goals at the other (3 m by 0.7 m).
fn three_region_scenario(dir: &Path) -> PathBuf {
    let mut uavs = Vec::new();
    for k in 0..EACH_WAY {
        let (x, y) = (3.0 + 3.0 * (k / 3) as f64, -1.4 + 0.7 * (k % 3) as f64);
        uavs.push(json!({"id": format!("east{k}"), "start": [x, y], "goal": [x + 43.5, y]}));
        uavs.push(json!({"id": format!("west{k}"), "start": [60.0 - x, -y], "goal": [16.5 - x, -y]}));
    }
    let scenario = json!({
        "name": "three",
        "params": {"t_max": 120.0},
        "segments": roads::RoadLayout::straight(0.0, 60.0, 4.0, 12).segments,
        "regions": [
            {"name": "a", "segments": [0, 3]}, {"name": "b", "segments": [4, 7]}, {"name": "c", "segments": [8, 11]}
        ],
        "uavs": uavs,
    });
    let path = dir.join("three.json");
    std::fs::write(&path, scenario.to_string()).unwrap();
    path
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn three_regions_hand_uavs_over_with_one_owner_at_every_moment() {
    let dir = scratch("three");
    let scenario = three_region_scenario(&dir);
    let scenario = scenario.to_str().unwrap();
    let (_servers, regions) = serve_regions(scenario, &["a", "b", "c"]);
    let arrived = fly_until_arrived(&regions, 2 * EACH_WAY, Duration::from_secs(110)).await;
    assert_eq!(arrived.len(), 2 * EACH_WAY, "all arrive: {arrived:?}");
    let by_uav = ownership(&regions).await;
    assert_eq!(by_uav.len(), 2 * EACH_WAY, "{by_uav:?}");
    let path = |id: &str| if id.starts_with("east") { vec!["a", "b", "c"] } else { vec!["c", "b", "a"] };
    let longest_gap = assert_handed_over(&by_uav, path, MAX_UNOWNED_S);
    eprintln!("{} handovers, longest unowned gap {longest_gap:.3} s", 4 * EACH_WAY);
    for &(_, addr) in &regions {
        let metrics = get(addr, "/api/metrics").await;
        assert_eq!(metrics["region"]["refused"], 0, "{}", metrics["region"]);
    }
}

/// Not a test on its own: the process of simulated Crazyflies that
/// `crazyflies_are_handed_over_with_their_links` starts (`support::crazyflies`).
#[test]
#[ignore = "a helper process of crazyflies_are_handed_over_with_their_links"]
fn cfsim_host() {
    support::crazyflies::host();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn crazyflies_are_handed_over_with_their_links() {
    // Two fly east through the border at x = 20, one flies west between them.
    let starts = [[12.0, -1.0], [12.0, 1.0], [28.0, 0.0]];
    let goals = [[28.0, -1.0], [28.0, 1.0], [12.0, 0.0]];
    let crazyflies = support::crazyflies::start(&starts);
    let (uris, truth) = (&crazyflies.uris, &crazyflies.truth);
    let uavs_json: Vec<Value> = (0..3)
        .map(|k| json!({"id": format!("cf{k}"), "start": starts[k], "goal": goals[k], "link": uris[k]}))
        .collect();
    let dir = scratch("crazyflies");
    let scenario = json!({
        "name": "crazyflies",
        "params": {"t_max": 120.0},
        "segments": roads::RoadLayout::straight(0.0, 40.0, 4.0, 8).segments,
        "regions": [{"name": "west", "segments": [0, 3]}, {"name": "east", "segments": [4, 7]}],
        "uavs": uavs_json,
    });
    let path = dir.join("crazyflies.json");
    std::fs::write(&path, scenario.to_string()).unwrap();
    let scenario = path.to_str().unwrap();
    let endpoint = free_endpoint();
    let (_west, west, _) = serve(&["--scenario", scenario, "--region", "west", "--zenoh-listen", &endpoint]);
    let (_east, east, _) = serve(&["--scenario", scenario, "--region", "east", "--zenoh-connect", &endpoint]);
    let started = Instant::now();
    while truth.lock().unwrap().airborne < 3 {
        assert!(started.elapsed() < Duration::from_secs(30), "not all took off");
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    truth.lock().unwrap().watching = true;
    let mut arrived = 0;
    while started.elapsed() < Duration::from_secs(100) {
        let asked = Instant::now();
        let (sw, se) =
            tokio::join!(get(west, "/api/state?scope=region"), get(east, "/api/state?scope=region"));
        let skew = asked.elapsed().as_secs_f64() + 2.0 * TICK_S;
        let all: Vec<Value> = [&sw, &se].iter().flat_map(|s| s["uavs"].as_array().unwrap().clone()).collect();
        for u in &all {
            assert!(u["phase"] != "landed" && u["phase"] != "landing", "{}: {u}", u["id"]);
        }
        let listed: Vec<_> = uavs(&sw).into_iter().chain(uavs(&se)).collect();
        for (i, x) in listed.iter().enumerate() {
            for y in listed[i + 1..].iter().filter(|y| y.0 != x.0) {
                let d = distance(x.1, y.1);
                let slack = TOLERANCE_M + distance(x.2, y.2) * skew;
                assert!(d >= D_C - slack, "{} and {} {d} m apart", x.0, y.0);
            }
        }
        arrived = listed.iter().filter(|u| u.3).count();
        if arrived == 3 {
            break;
        }
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    assert_eq!(arrived, 3, "every Crazyflie arrives");
    let by_uav = ownership(&[("west", west), ("east", east)]).await;
    let mut longest_gap = 0.0f64;
    for (id, intervals) in &by_uav {
        let path: Vec<&str> = intervals.iter().map(|i| i.2.as_str()).collect();
        let expected = if id == "cf2" { ["east", "west"] } else { ["west", "east"] };
        assert_eq!(path, expected, "{id}: {intervals:?}");
        let gap = intervals[1].0 - intervals[0].1;
        assert!(gap >= 0.0, "{id}: two owners at once: {intervals:?}");
        assert!(gap <= MAX_UNOWNED_LINK_S, "{id}: unowned {gap} s: {intervals:?}");
        longest_gap = longest_gap.max(gap);
    }
    assert_eq!(by_uav.len(), 3, "{by_uav:?}");
    let t = truth.lock().unwrap();
    eprintln!(
        "longest unowned gap {longest_gap:.3} s; closest pair in flight {:.3} m",
        t.closest_while_flying
    );
    assert!(!t.fell, "a Crazyflie came down during a handover");
    assert!(t.closest_while_flying >= D_C - TOLERANCE_M, "closest pair {} m", t.closest_while_flying);
}

#[test]
fn an_unknown_region_is_refused_naming_the_known_ones() {
    let dir = scratch("unknown");
    let scenario = two_region_scenario(&dir);
    let out = Command::new(env!("CARGO_BIN_EXE_airroads"))
        .args(["serve", "--addr", "127.0.0.1:0", "--ephemeral", "--region", "north", "--scenario"])
        .arg(&scenario)
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("--region `north`") && err.contains("known: west, east"), "{err}");
    // Zenoh flags need --region, and --region needs --scenario.
    for args in [&["--zenoh-listen", "tcp/127.0.0.1:0"][..], &["--region", "west"][..]] {
        let out = Command::new(env!("CARGO_BIN_EXE_airroads"))
            .args(["serve", "--addr", "127.0.0.1:0", "--ephemeral"])
            .args(args)
            .output()
            .unwrap();
        assert_eq!(out.status.code(), Some(2), "{args:?}");
    }
}
