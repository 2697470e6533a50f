//! The region network against a rogue Zenoh peer in a process of its own (Zenoh's stock Python
//! client, `tests/zenoh/rogue.py`), as a review found a peer could attack it: commands without the
//! token, forged ownership tokens and mirrors, unsolicited releases, walls of phantom states, a
//! rogue queryable answering for a region, 250 forged offers. Two region servers with TLS (mutual), access control and a
//! token; the rogue comes once with no certificate and once with a certificate of the other
//! region. Needs `AIRROADS_ZENOH_PYTHON` (a Python with `eclipse-zenoh`; `scripts/region-security-check`
//! makes one and runs this), else it says so and is skipped.
//!
//! Also, without the rogue: a region server refuses to start without certificates or
//! `--zenoh-insecure`, and `--zenoh-insecure` only on loopback.

mod support;

use serde_json::{Value, json};
use std::io::{BufRead, BufReader};
use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use support::procs::{self, free_endpoint, get, serve, tls_args};

const TOKEN: &str = "region-security-test-token-0123";

fn python() -> Option<String> {
    let python = std::env::var("AIRROADS_ZENOH_PYTHON").ok().filter(|p| !p.is_empty());
    if python.is_none() {
        eprintln!(
            "skipped: set AIRROADS_ZENOH_PYTHON to a Python with eclipse-zenoh (scripts/region-security-check does)"
        );
    }
    python
}

/// Two regions on a straight road (x 0–40): `west` 0–3 and `east` 4–7, two UAVs hovering in each.
fn scenario(dir: &Path) -> PathBuf {
    let doc = json!({
        "name": "rogue",
        "segments": roads::RoadLayout::straight(0.0, 40.0, 4.0, 8).segments,
        "regions": [{"name": "west", "segments": [0, 3]}, {"name": "east", "segments": [4, 7]}],
        "uavs": [
            {"id": "w1", "start": [8.0, 0.0], "goal": [8.0, 0.0]},
            {"id": "w2", "start": [12.0, 1.0], "goal": [12.0, 1.0]},
            {"id": "e1", "start": [28.0, 0.0], "goal": [28.0, 0.0]},
            {"id": "e2", "start": [32.0, 1.0], "goal": [32.0, 1.0]}
        ]
    });
    let path = dir.join("rogue.json");
    std::fs::write(&path, doc.to_string()).unwrap();
    path
}

fn uav_ids(state: &Value) -> Vec<String> {
    procs::uavs(state).into_iter().map(|u| u.0).collect()
}

/// Runs the rogue against `west` (`endpoints`), asking `east` about a west UAV while the rogue's
/// queryable claims west's API; returns what the rogue saw.
async fn attack(python: &str, endpoints: &str, cert: &[String], east: SocketAddr) -> Value {
    let script = support::repo().join("tests/zenoh/rogue.py");
    let mut child = Command::new(python)
        .arg(script)
        .args([endpoints, "airroads", "west"])
        .args(cert)
        .stdout(Stdio::piped())
        .stderr(Stdio::inherit())
        .spawn()
        .unwrap();
    let stdout = child.stdout.take().unwrap();
    // Killed if this test fails before it ends.
    let mut rogue = procs::Proc(child);
    let mut lines = BufReader::new(stdout).lines();
    let mut report = None;
    while let Some(Ok(line)) = lines.next() {
        if line == "QUERYABLE" {
            // The rogue's queryable claims west's API: east's forwarded read must still get west's
            // own answer (the access control drops the rogue's declaration and replies).
            for _ in 0..3 {
                let (status, body) = support::raw(east, "GET", "/api/uavs/w1", None, &[]).await;
                assert_eq!(status, 200, "{body}");
                let uav: Value = serde_json::from_str(&body).unwrap();
                assert_eq!(uav["id"], "w1", "the rogue answered for west: {body}");
            }
        } else if line.starts_with('{') {
            report = Some(serde_json::from_str(&line).unwrap());
        }
    }
    let status = rogue.0.wait().unwrap();
    assert!(status.success(), "the rogue failed: {status}");
    report.expect("the rogue's report")
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_rogue_peer_without_a_certificate_or_with_another_regions_cannot_command_forge_or_flood() {
    let Some(python) = python() else { return };
    let dir = procs::scratch("region-security", "rogue");
    let scenario = scenario(&dir);
    let scenario = scenario.to_str().unwrap();
    let (west_endpoint, east_endpoint) = (free_endpoint(), free_endpoint());
    let with_token = ["--token", TOKEN];
    let (mut west_process, west, _) = serve(
        &[
            &["--scenario", scenario, "--region", "west", "--zenoh-listen", &west_endpoint][..],
            &["--max-uavs", "20"],
            &with_token,
        ]
        .concat(),
    );
    let east_args = ["--scenario", scenario, "--region", "east", "--zenoh-listen", &east_endpoint];
    let (_east, east, _) =
        serve(&[&east_args[..], &["--zenoh-connect", &west_endpoint], &with_token].concat());
    // West's hot standby: the rogue's forged owner token, standby token and mirror aim at it.
    let standby_args = ["--scenario", scenario, "--standby-for", "west", "--zenoh-connect", &west_endpoint];
    let (_standby, standby, _) =
        serve(&[&standby_args[..], &["--zenoh-connect", &east_endpoint], &with_token].concat());
    let both = format!("{west_endpoint},{east_endpoint}");
    // East sees west's UAVs, and the standby mirrors them, before anything starts.
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(10);
    while get(east, "/api/metrics").await["region"]["heard"]["west"]["uavs"] != 2
        || get(standby, "/api/metrics").await["region"]["failover"]["mirror_uavs"] != 2
    {
        assert!(
            std::time::Instant::now() < deadline,
            "east never heard west, or the standby never mirrored it"
        );
        tokio::time::sleep(std::time::Duration::from_millis(100)).await;
    }

    // No certificate: mutual TLS refuses the session, nothing reaches either region.
    let ca = tls_args("west", "primary")[1].clone();
    let seen = attack(&python, &both, &["--ca".into(), ca.clone()], east).await;
    assert_eq!(seen["connected"], false, "{seen}");
    assert_eq!((seen["stop_as_sender"].clone(), seen["audit_read"].clone()), (Value::Null, Value::Null));

    // A certificate of region east (signed by the deployment's authority), attacking west.
    let east_cert = tls_args("east", "standby");
    let cert = vec![
        "--ca".to_string(),
        ca,
        "--cert".into(),
        east_cert[3].clone(),
        "--key".into(),
        east_cert[5].clone(),
        "--as".into(),
        "east".into(),
    ];
    let before = get(west, "/api/metrics").await["region"].clone();
    let missed_before = get(west, "/api/metrics").await["missed_ticks"].as_u64().unwrap();
    let seen = attack(&python, &both, &cert, east).await;
    assert_eq!(seen["connected"], true, "{seen}");
    // West checks the operator's token itself: a forwarded change without it is 401; the audit log
    // cannot even be asked for (no request of the wire reads it: 422); asking as west itself is not
    // allowed to east's certificate (no answer at all).
    assert_eq!(seen["stop_as_sender"], 401, "{seen}");
    assert_eq!(seen["audit_read"], 422, "{seen}");
    assert_eq!(seen["stop_as_target"], Value::Null, "{seen}");
    assert_eq!(seen["stop_on_the_bare_key"], Value::Null, "nothing answers on the old API key: {seen}");
    let state = get(west, "/api/state?scope=region").await;
    assert_eq!(uav_ids(&state), ["w1", "w2"], "nothing adopted, nothing removed");
    assert!(
        state["uavs"].as_array().unwrap().iter().all(|u| u["status"] != "stopped"),
        "west's fleet was stopped: {state}"
    );
    let after = get(west, "/api/metrics").await["region"].clone();
    // The forged owner token of a higher epoch never reached west: it still owns, never gave way.
    assert_eq!(after["failover"]["role"], "owner", "{after}");
    assert_eq!(after["failover"]["given_way"], before["failover"]["given_way"], "{after}");
    // Releases east's certificate may send are refused as unrequested; phantoms far from east are
    // refused by name, and west's view of east stays east's two UAVs.
    let refused = &after["peer_refused"];
    assert!(refused["unrequested_release"].as_u64().unwrap() >= 3, "{after}");
    assert!(
        refused["far_from_region"].as_u64().unwrap() + refused["too_fast"].as_u64().unwrap() >= 1,
        "{after}"
    );
    assert_eq!(after["heard"]["east"]["uavs"], 2, "{after}");
    // Of the 250 forged offers, more than a gap's share from one sender are dropped unanswered.
    assert!(refused["too_many_offers"].as_u64().unwrap() >= 1, "{after}");
    eprintln!("west refused from peers: {refused}");
    // The 12 MiB message of 300,000 UAVs was refused before decoding: no tick stretched (copied
    // into the fleet it missed 28 ticks; a few may be missed here to a busy 2-core machine).
    let missed = get(west, "/api/metrics").await["missed_ticks"].as_u64().unwrap() - missed_before;
    assert!(missed < 8, "{missed} ticks missed during the attack");
    // The standby kept the real owner's mirror and its role; the invented UAV is nowhere.
    let failover = get(standby, "/api/metrics").await["region"]["failover"].clone();
    assert_eq!(
        (failover["role"].clone(), failover["mirror_uavs"].clone()),
        (json!("standby"), json!(2)),
        "{failover}"
    );
    // The 250 offers forged as east reserved room at west (at most 20 UAVs there) for a few seconds
    // at most: a real handover from east afterwards is taken.
    let bearer = format!("Bearer {TOKEN}");
    let goal = json!({"goal": [10.0, -1.0]}).to_string();
    let (status, body) =
        support::raw(east, "PUT", "/api/uavs/e1/goal", Some(&goal), &[("authorization", &bearer)]).await;
    assert!((200..300).contains(&status), "{status} {body}");
    let handed = std::time::Instant::now();
    while !uav_ids(&get(west, "/api/state?scope=region").await).contains(&"e1".to_string()) {
        assert!(
            handed.elapsed() < std::time::Duration::from_secs(30),
            "west never took e1 from east after the forged offers: {}",
            get(west, "/api/metrics").await["region"]
        );
        tokio::time::sleep(std::time::Duration::from_millis(100)).await;
    }
    eprintln!("e1 handed over to west {:.1} s after its goal", handed.elapsed().as_secs_f64());
    // The forwarded request that was refused is in west's own audit log, with the region it came
    // through; the operator's token still works from east.
    let (status, _) =
        support::raw(east, "POST", "/api/uavs/w1/land", None, &[("authorization", &bearer)]).await;
    assert!((200..300).contains(&status), "{status}");
    let audit = support::raw(west, "GET", "/api/audit?limit=20", None, &[("authorization", &bearer)]).await;
    let entries: Value = serde_json::from_str(&audit.1).unwrap();
    let forwarded = entries["entries"].as_array().unwrap().iter().any(|e| {
        e["route"] == "/api/uavs/w1/land" && e["remote"].as_str().unwrap_or("").ends_with("via region east")
    });
    assert!(forwarded, "the land forwarded from east is audited at west: {entries}");
    // The forged standby token did not keep the real standby from taking over: kill -9 of west.
    west_process.kill();
    let killed = std::time::Instant::now();
    while get(standby, "/api/metrics").await["region"]["failover"]["role"] != "owner" {
        assert!(killed.elapsed() < std::time::Duration::from_secs(2), "the standby never took over");
        tokio::time::sleep(std::time::Duration::from_millis(20)).await;
    }
    eprintln!("takeover seen {:.3} s after the kill", killed.elapsed().as_secs_f64());
    tokio::time::sleep(std::time::Duration::from_millis(200)).await;
    let mut flown = uav_ids(&get(standby, "/api/state?scope=region").await);
    flown.sort();
    assert_eq!(flown, ["e1", "w1", "w2"], "the standby flies west's UAVs and nothing invented");
}

#[test]
fn a_region_server_needs_certificates_or_an_explicit_insecure_flag_on_loopback() {
    let dir = procs::scratch("region-security", "flags");
    let scenario = scenario(&dir);
    let run = |extra: &[&str]| {
        let out = Command::new(env!("CARGO_BIN_EXE_airroads"))
            .args(["serve", "--addr", "127.0.0.1:0", "--ephemeral", "--region", "west", "--scenario"])
            .arg(&scenario)
            .args(extra)
            .output()
            .unwrap();
        (out.status.code(), String::from_utf8_lossy(&out.stderr).into_owned())
    };
    let (code, err) = run(&["--zenoh-listen", "tcp/127.0.0.1:0"]);
    assert_eq!(code, Some(2), "{err}");
    assert!(err.contains("--zenoh-ca") && err.contains("--zenoh-insecure"), "{err}");
    let (code, err) = run(&["--zenoh-insecure", "--zenoh-listen", "tcp/0.0.0.0:7447"]);
    assert_eq!(code, Some(2), "{err}");
    assert!(err.contains("tcp/0.0.0.0:7447") && err.contains("loopback"), "{err}");
    let tls = tls_args("west", "primary");
    let tls: Vec<&str> = tls.iter().map(String::as_str).collect();
    let (code, err) = run(&[&tls[..], &["--zenoh-listen", "tcp/127.0.0.1:0"]].concat());
    assert_eq!(code, Some(2), "{err}");
    assert!(err.contains("tls/HOST:PORT"), "{err}");
}

/// Keeps one keep-alive connection pipelining `GET /api/uavs/no-such-uav` to `addr` until `until`
/// (answers are read and dropped); returns how many requests it sent.
async fn flood(addr: SocketAddr, until: std::time::Instant) -> usize {
    use tokio::io::{AsyncReadExt as _, AsyncWriteExt as _};
    let request = format!("GET /api/uavs/no-such-uav HTTP/1.1\r\nHost: {addr}\r\n\r\n").repeat(20);
    let mut sent = 0;
    while std::time::Instant::now() < until {
        let Ok(mut stream) = tokio::net::TcpStream::connect(addr).await else { continue };
        let mut buffer = vec![0u8; 64 << 10];
        while std::time::Instant::now() < until {
            if stream.write_all(request.as_bytes()).await.is_err() {
                break;
            }
            sent += 20;
            // Read what comes within a moment, then pipeline more.
            let read = tokio::time::timeout(std::time::Duration::from_millis(200), stream.read(&mut buffer));
            if let Ok(Ok(0) | Err(_)) = read.await {
                break;
            }
        }
    }
    sent
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_flood_of_forwarded_reads_about_a_silent_region_leaves_the_emergency_stop_answered() {
    let dir = procs::scratch("region-security", "flood");
    let scenario = scenario(&dir);
    let scenario = scenario.to_str().unwrap();
    let endpoint = free_endpoint();
    let with_token = ["--token", TOKEN];
    let (_west, west, _) = serve(
        &[&["--scenario", scenario, "--region", "west", "--zenoh-listen", &endpoint][..], &with_token]
            .concat(),
    );
    let (mut east, _, _) = serve(
        &[&["--scenario", scenario, "--region", "east", "--zenoh-connect", &endpoint][..], &with_token]
            .concat(),
    );
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(10);
    while get(west, "/api/metrics").await["region"]["heard"]["east"]["uavs"] != 2 {
        assert!(std::time::Instant::now() < deadline, "west never heard east");
        tokio::time::sleep(std::time::Duration::from_millis(100)).await;
    }
    // East dies: every read about a UAV west does not fly must ask it, and it never answers.
    east.kill();
    let until = std::time::Instant::now() + std::time::Duration::from_secs(12);
    let flooders: Vec<_> = (0..300).map(|_| tokio::spawn(flood(west, until))).collect();
    tokio::time::sleep(std::time::Duration::from_secs(2)).await;
    let bearer = format!("Bearer {TOKEN}");
    let headers = [("authorization", bearer.as_str())];
    let mut answered = 0;
    for _ in 0..10 {
        let started = std::time::Instant::now();
        let call = support::raw(west, "POST", "/api/fleet/stop", None, &headers);
        // Applied here; east did not answer, so 502 `regions_failed` naming it (200 if it had).
        if let Ok((status, body)) = tokio::time::timeout(std::time::Duration::from_secs(4), call).await {
            assert!(status == 200 || status == 502, "{status} {body}");
            answered += 1;
        }
        eprintln!("stop answered in {:.2} s", started.elapsed().as_secs_f64());
        tokio::time::sleep(std::time::Duration::from_millis(300)).await;
    }
    let mut sent = 0;
    for f in flooders {
        sent += f.await.unwrap();
    }
    eprintln!("{sent} flood requests sent");
    assert_eq!(answered, 10, "the emergency stop must be answered during the flood");
    let state = get(west, "/api/state?scope=region").await;
    assert!(state["uavs"].as_array().unwrap().iter().all(|u| u["status"] == "stopped"), "{state}");
}
