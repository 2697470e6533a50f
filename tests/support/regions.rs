//! Region servers on loopback (`airroads serve --region` over Zenoh with TLS) and what the region
//! tests check of them: D_c across every pair while they fly, and each UAV's owners in turn.

use super::procs::{D_C, Proc, TICK_S, TOLERANCE_M, distance, free_endpoint, get, serve, uavs};
use futures_util::future::join_all;
use std::collections::BTreeMap;
use std::net::SocketAddr;
use std::time::{Duration, Instant};

/// One server per region of `scenario`, in the order of `names`: each listens on an endpoint of
/// its own and connects to those started before it. The processes (kept alive while held) and the
/// regions with their addresses.
pub fn serve_regions(scenario: &str, names: &[&'static str]) -> (Vec<Proc>, Vec<(&'static str, SocketAddr)>) {
    let ports: Vec<String> = names.iter().map(|_| free_endpoint()).collect();
    let (mut procs, mut regions) = (Vec::new(), Vec::new());
    for (k, name) in names.iter().enumerate() {
        let mut args = vec!["--scenario", scenario, "--region", name, "--zenoh-listen", &ports[k]];
        for port in &ports[..k] {
            args.extend(["--zenoh-connect", port.as_str()]);
        }
        let (proc, addr, _) = serve(&args);
        procs.push(proc);
        regions.push((*name, addr));
    }
    (procs, regions)
}

/// Reads every region's UAVs every 50 ms until `fleet` of them arrived or `limit` passed, and
/// asserts D_c between every two UAVs seen (less what the snapshots' skew lets them move); the ids
/// of the UAVs arrived, sorted.
pub async fn fly_until_arrived(regions: &[(&str, SocketAddr)], fleet: usize, limit: Duration) -> Vec<String> {
    let started = Instant::now();
    let mut arrived = Vec::new();
    while started.elapsed() < limit {
        let asked = Instant::now();
        let states = join_all(regions.iter().map(|(_, addr)| get(*addr, "/api/state?scope=region"))).await;
        let skew = asked.elapsed().as_secs_f64() + 2.0 * TICK_S;
        let all: Vec<_> = states.iter().flat_map(uavs).collect();
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
        if arrived.len() == fleet {
            break;
        }
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    arrived
}

/// Every UAV's ownership intervals over all regions, by UAV: `(from, to, region)`, by `from`.
pub async fn ownership(regions: &[(&str, SocketAddr)]) -> BTreeMap<String, Vec<(f64, f64, String)>> {
    let mut by_uav: BTreeMap<String, Vec<(f64, f64, String)>> = BTreeMap::new();
    for (name, addr) in regions {
        let doc = get(*addr, "/api/region/ownership").await;
        assert_eq!(doc["region"], *name);
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

/// Asserts that each UAV of `by_uav` was owned by the regions `path(id)` in that order, never by
/// two at once, unowned at most `max_unowned_s` in between, and owned at the end; the longest
/// unowned gap (s). A UAV may cross a border back and forth (stepping aside or backing off at a
/// junction on the border) as long as each handover is to the next or the previous region of its
/// path: every border is still crossed, in order, and it ends in the last region.
pub fn assert_handed_over(
    by_uav: &BTreeMap<String, Vec<(f64, f64, String)>>,
    path: impl Fn(&str) -> Vec<&'static str>,
    max_unowned_s: f64,
) -> f64 {
    let mut longest_gap = 0.0f64;
    for (id, intervals) in by_uav {
        let owners: Vec<&str> = intervals.iter().map(|i| i.2.as_str()).collect();
        let way = path(id);
        let places: Vec<Option<usize>> = owners.iter().map(|o| way.iter().position(|w| w == o)).collect();
        let walks = places.first() == Some(&Some(0))
            && places.last() == Some(&Some(way.len() - 1))
            && places.windows(2).all(|p| matches!((p[0], p[1]), (Some(a), Some(b)) if a.abs_diff(b) == 1));
        assert!(walks, "{id}: owners {owners:?} are not a walk along {way:?}: {intervals:?}");
        for pair in intervals.windows(2) {
            let gap = pair[1].0 - pair[0].1;
            assert!(gap >= 0.0, "{id}: owned by {} and {} at once ({intervals:?})", pair[0].2, pair[1].2);
            assert!(gap <= max_unowned_s, "{id}: unowned {gap} s between {} and {}", pair[0].2, pair[1].2);
            longest_gap = longest_gap.max(gap);
        }
        assert!(intervals.last().unwrap().1.is_infinite(), "{id}: owned at the end");
    }
    longest_gap
}
