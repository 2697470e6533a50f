//! `airroads serve` as a process: it starts with no scenario (the embedded demo), refuses a public
//! address without a token, resumes road, fleet and goals after kill -9 (every acknowledged change,
//! even one acknowledged a moment before), refuses a data directory it cannot write, and answers 503
//! for changes a full disk cannot take without losing what it acknowledged.

mod support;

use serde_json::{Value, json};
use std::io::{BufRead, BufReader};
use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("airroads-serve-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// Starts `airroads serve` on 127.0.0.1:0 with `args`; returns the child and the printed address.
fn serve(data_dir: &Path, args: &[&str]) -> (Proc, SocketAddr) {
    let mut command = Command::new(env!("CARGO_BIN_EXE_airroads"));
    command.args(["serve", "--addr", "127.0.0.1:0", "--data-dir", data_dir.to_str().unwrap()]).args(args);
    start_child(command)
}

/// Starts the command (an `airroads serve`) and reads the address from its banner.
fn start_child(mut command: Command) -> (Proc, SocketAddr) {
    let mut child =
        command.env_remove("AIRROADS_TOKEN").stdout(Stdio::piped()).stderr(Stdio::inherit()).spawn().unwrap();
    let mut lines = BufReader::new(child.stdout.take().unwrap()).lines();
    let first = lines.next().expect("a banner line").unwrap();
    let addr = first.rsplit("http://").next().unwrap().trim().parse().unwrap_or_else(|_| panic!("{first}"));
    // Keep draining stdout so the server never blocks on a full pipe.
    std::thread::spawn(move || for _ in lines.by_ref() {});
    (Proc(Some(child)), addr)
}

/// A server process, killed when dropped (a failing test leaves nothing running).
struct Proc(Option<Child>);

impl Proc {
    fn id(&self) -> u32 {
        self.0.as_ref().map_or(0, Child::id)
    }

    /// kill -9 and wait.
    fn kill_now(&mut self) {
        if let Some(child) = &mut self.0 {
            child.kill().unwrap();
            child.wait().unwrap();
        }
        self.0 = None;
    }

    fn into_child(mut self) -> Child {
        self.0.take().unwrap()
    }
}

impl Drop for Proc {
    fn drop(&mut self) {
        if let Some(child) = &mut self.0 {
            let _ = child.kill();
            let _ = child.wait();
        }
    }
}

async fn call(addr: SocketAddr, method: &str, path: &str, body: Option<&Value>) -> (u16, Value) {
    let text = body.map(Value::to_string);
    let (status, reply) = support::raw(addr, method, path, text.as_deref(), &[]).await;
    (status, serde_json::from_str(&reply).unwrap_or(Value::Null))
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn starts_on_the_demo_and_resumes_after_kill_9() {
    let data = scratch("resume");
    let (mut child, addr) = serve(&data, &[]);
    let state = call(addr, "GET", "/api/state", None).await.1;
    assert!(state["uavs"].as_array().unwrap().len() >= 3, "the demo flies a few UAVs: {state}");
    assert_eq!(call(addr, "GET", "/healthz", None).await.0, 200);

    // Change road, fleet and goals, wait for the writer, then kill -9.
    let layout = call(addr, "GET", "/api/road", None).await.1;
    let mut wider = layout.clone();
    wider["segments"][0][1] = json!([-0.5, -1.5]);
    // Regions are part of the road, stored with it: entry segment alone, the rest after it.
    let n = layout["segments"].as_array().unwrap().len();
    assert!(n >= 2, "the demo road has several segments: {layout}");
    wider["regions"] =
        json!([{"name": "rest", "segments": [1, n - 1]}, {"name": "entry", "segments": [0, 0]}]);
    assert_eq!(call(addr, "PUT", "/api/road", Some(&wider)).await.0, 200);
    let new = json!({"id": "extra", "position": [13.0, 16.0], "goal": [10.0, 17.0], "policy": "pd"});
    assert_eq!(call(addr, "POST", "/api/uavs", Some(&new)).await.0, 201);
    assert_eq!(call(addr, "DELETE", "/api/uavs/uav1", None).await.0, 204);
    tokio::time::sleep(std::time::Duration::from_millis(1500)).await;
    child.kill_now();

    let (mut child, addr) = serve(&data, &[]);
    assert_eq!(call(addr, "GET", "/api/road", None).await.1, wider);
    let uavs = call(addr, "GET", "/api/uavs", None).await.1;
    let ids: Vec<&str> = uavs.as_array().unwrap().iter().map(|u| u["id"].as_str().unwrap()).collect();
    assert!(ids.contains(&"extra") && !ids.contains(&"uav1"), "{ids:?}");
    let extra = uavs.as_array().unwrap().iter().find(|u| u["id"] == "extra").unwrap();
    assert_eq!(extra["goal"], json!([10.0, 17.0]));
    assert_eq!(extra["policy"], "pd");
    child.kill_now();
    std::fs::remove_dir_all(&data).unwrap();
}

#[test]
fn refuses_a_public_address_without_a_token() {
    let data = scratch("public");
    let out = Command::new(env!("CARGO_BIN_EXE_airroads"))
        .args(["serve", "--addr", "0.0.0.0:0", "--data-dir", data.to_str().unwrap()])
        .env_remove("AIRROADS_TOKEN")
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("--addr 0.0.0.0:0") && stderr.contains("token"), "{stderr}");
}

#[test]
fn sigterm_saves_and_exits_cleanly() {
    let data = scratch("term");
    let (child, _addr) = serve(&data, &["--policy", "pd"]);
    std::thread::sleep(std::time::Duration::from_millis(500));
    let status = Command::new("kill").args(["-TERM", &child.id().to_string()]).status().unwrap();
    assert!(status.success());
    let out = child.into_child().wait_with_output().unwrap();
    assert_eq!(out.status.code(), Some(0));
    assert!(data.join("airroads.db").exists());
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn cfsim_crazyflies_take_off_and_sigterm_lands_them_before_exiting() {
    let data = scratch("cfsim");
    let lab3 = support::repo().join("scenarios/lab3.json");
    let args = ["--policy", "pd", "--scenario", lab3.to_str().unwrap(), "--cfsim", "3", "--cfsim-port", "0"];
    let (child, addr) = serve(&data, &args);
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(20);
    loop {
        let (_, state) = call(addr, "GET", "/api/state", None).await;
        let uavs = state["uavs"].as_array().cloned().unwrap_or_default();
        if uavs.len() == 3
            && uavs
                .iter()
                .all(|u| u["phase"] == "flying" && u["link"].as_str().unwrap().starts_with("udp://"))
        {
            break;
        }
        assert!(std::time::Instant::now() < deadline, "the simulated Crazyflies did not take off: {state}");
        tokio::time::sleep(std::time::Duration::from_millis(100)).await;
    }
    let started = std::time::Instant::now();
    let status = Command::new("kill").args(["-TERM", &child.id().to_string()]).status().unwrap();
    assert!(status.success());
    let out = child.into_child().wait_with_output().unwrap();
    assert_eq!(out.status.code(), Some(0));
    // Landing takes its 2 s before the server exits.
    assert!(started.elapsed() >= std::time::Duration::from_secs(2), "exited before landing");
    assert!(started.elapsed() < std::time::Duration::from_secs(12));
}

/// A straight road along x, `length` m long and 8 m wide, with two UAVs near its start.
fn long_road_scenario(dir: &Path) -> PathBuf {
    let scenario = json!({
        "name": "long",
        "segments": roads::RoadLayout::straight(0.0, 200.0, 8.0, 20).segments,
        "uavs": [
            {"id": "a", "start": [2.0, -3.0], "goal": [2.0, -3.0]},
            {"id": "b", "start": [2.0, 3.0], "goal": [2.0, 3.0]}
        ]
    });
    let path = dir.join("long.json");
    std::fs::write(&path, scenario.to_string()).unwrap();
    path
}

async fn ids(addr: SocketAddr) -> Vec<String> {
    let uavs = call(addr, "GET", "/api/uavs", None).await.1;
    uavs.as_array().unwrap().iter().map(|u| u["id"].as_str().unwrap().to_string()).collect()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn every_acknowledged_change_survives_kill_9_at_once() {
    let data = scratch("durable");
    let scenario = long_road_scenario(&data);
    for round in 0..3 {
        let args = ["--policy", "pd", "--scenario", scenario.to_str().unwrap()];
        let (mut child, addr) =
            if round == 0 { serve(&data, &args) } else { serve(&data, &["--policy", "pd"]) };
        // A burst of concurrent additions, then a goal; kill -9 the moment the last answer arrived.
        let mut calls = Vec::new();
        for i in 0..24 {
            let id = format!("r{round}u{i}");
            let x = 10.0 + f64::from(round) * 40.0 + f64::from(i);
            let body = json!({"id": id, "position": [x, 0.0]});
            calls.push(tokio::spawn(
                async move { (id, call(addr, "POST", "/api/uavs", Some(&body)).await.0) },
            ));
        }
        let mut acknowledged = Vec::new();
        for c in calls {
            let (id, status) = c.await.unwrap();
            if status == 201 {
                acknowledged.push(id);
            }
        }
        assert!(acknowledged.len() >= 20, "round {round}: {acknowledged:?}");
        let last = acknowledged.last().unwrap().clone();
        let goal = json!({"goal": [150.0, 1.5]});
        assert_eq!(call(addr, "PUT", &format!("/api/uavs/{last}/goal"), Some(&goal)).await.0, 200);
        child.kill_now();

        let (mut child, addr) = serve(&data, &["--policy", "pd"]);
        let resumed = ids(addr).await;
        for id in &acknowledged {
            assert!(
                resumed.contains(id),
                "round {round}: acknowledged `{id}` lost after kill -9: {resumed:?}"
            );
        }
        let uav = call(addr, "GET", &format!("/api/uavs/{last}"), None).await.1;
        assert_eq!(uav["goal"], json!([150.0, 1.5]), "round {round}: the last goal was lost");
        child.kill_now();
    }
    std::fs::remove_dir_all(&data).unwrap();
}

#[test]
fn a_data_directory_that_cannot_be_written_is_refused_at_start() {
    let data = scratch("unwritable");
    let file = data.join("a-file");
    std::fs::write(&file, "not a directory").unwrap();
    for dir in [file.to_str().unwrap(), "/proc/airroads-data", "/sys/airroads-data"] {
        let out = Command::new(env!("CARGO_BIN_EXE_airroads"))
            .args(["serve", "--addr", "127.0.0.1:0", "--data-dir", dir])
            .env_remove("AIRROADS_TOKEN")
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{dir}: {stderr}");
        assert!(stderr.contains(&format!("--data-dir {dir}")), "{stderr}");
    }
    std::fs::remove_dir_all(&data).unwrap();
}

/// A layout of `n` 1 m segments with long decimals, about 150 bytes of JSON each.
fn bulky_road(n: usize) -> Value {
    let x = |i: usize| i as f64 * 1.000_000_123_456_789;
    let segments: Vec<Value> = (0..n)
        .map(|i| {
            json!([
                [x(i + 1), -5.000_000_1],
                [x(i), -5.000_000_1],
                [x(i + 1), 5.000_000_1],
                [x(i), 5.000_000_1]
            ])
        })
        .collect();
    json!({ "segments": segments })
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_full_disk_refuses_changes_with_503_and_loses_nothing_acknowledged() {
    let data = scratch("full");
    let scenario = long_road_scenario(&data);
    // A file-size limit of 256 KiB stands for a full disk (writes fail with EFBIG, like ENOSPC);
    // the ignored SIGXFSZ keeps the server alive to answer.
    let mut command = Command::new("bash");
    command.args(["-c", "trap '' XFSZ; ulimit -f 256; exec \"$0\" \"$@\""]);
    command.arg(env!("CARGO_BIN_EXE_airroads"));
    command.args(["serve", "--addr", "127.0.0.1:0", "--data-dir", data.to_str().unwrap()]);
    command.args(["--policy", "pd", "--scenario", scenario.to_str().unwrap()]);
    let (mut child, addr) = start_child(command);
    let small = json!({"id": "before", "position": [20.0, 0.0]});
    assert_eq!(call(addr, "POST", "/api/uavs", Some(&small)).await.0, 201);
    let road = call(addr, "GET", "/api/road", None).await.1;

    // A road too large for what is left of the disk: 503, and nothing changed.
    let (status, body) = call(addr, "PUT", "/api/road", Some(&bulky_road(2000))).await;
    assert_eq!((status, body["error"]["code"].as_str()), (503, Some("not_durable")), "{body}");
    assert!(body["error"]["message"].as_str().unwrap().contains("disk"), "{body}");
    assert_eq!(call(addr, "GET", "/api/road", None).await.1, road, "the refused road is not flying");
    let metrics = call(addr, "GET", "/api/metrics", None).await.1;
    assert!(metrics["storage"]["failed_commits"].as_u64().unwrap() >= 1, "{}", metrics["storage"]);
    assert!(metrics["storage"]["error"].as_str().unwrap().contains("disk"), "{}", metrics["storage"]);
    // Health says so while changes are refused (it clears once a write succeeds again).
    let (code, health) = call(addr, "GET", "/healthz", None).await;
    assert_eq!(code, 200);
    assert!(health["status"] == "degraded" || health["status"] == "ok", "{health}");

    // Small changes go through again once the disk takes writes (or are refused with 503).
    let mut after = Vec::new();
    for i in 0..20 {
        let body = json!({"id": format!("after{i}"), "position": [30.0 + f64::from(i), 0.0]});
        match call(addr, "POST", "/api/uavs", Some(&body)).await {
            (201, _) => after.push(format!("after{i}")),
            (503, e) => assert_eq!(e["error"]["code"], "not_durable", "{e}"),
            (status, e) => panic!("POST /api/uavs: {status} {e}"),
        }
        tokio::time::sleep(std::time::Duration::from_millis(100)).await;
    }
    child.kill_now();
    assert!(!data.join("state.json.tmp").exists());

    // Restarted without the limit: everything acknowledged, nothing refused.
    let (mut child, addr) = serve(&data, &["--policy", "pd"]);
    assert_eq!(call(addr, "GET", "/api/road", None).await.1, road);
    let resumed = ids(addr).await;
    for id in after.iter().chain(std::iter::once(&"before".to_string())) {
        assert!(resumed.contains(id), "acknowledged `{id}` lost: {resumed:?}");
    }
    child.kill_now();
    std::fs::remove_dir_all(&data).unwrap();
}

#[test]
fn flags_that_would_weaken_the_server_are_refused_with_the_flag_named() {
    let data = scratch("flags");
    let dir = data.to_str().unwrap();
    let run = |args: &[&str], env: Option<&str>| {
        let mut command = Command::new(env!("CARGO_BIN_EXE_airroads"));
        command
            .args(["serve", "--addr", "127.0.0.1:0", "--data-dir", dir])
            .args(args)
            .env_remove("AIRROADS_TOKEN");
        if let Some(token) = env {
            command.env("AIRROADS_TOKEN", token);
        }
        // A server that starts after all is stopped after 10 s (and fails the test, without a code).
        let mut child = command.stdout(Stdio::null()).stderr(Stdio::piped()).spawn().unwrap();
        let deadline = std::time::Instant::now() + std::time::Duration::from_secs(10);
        let code = loop {
            if let Some(status) = child.try_wait().unwrap() {
                break status.code();
            }
            if std::time::Instant::now() > deadline {
                let _ = child.kill();
                let _ = child.wait();
                break None;
            }
            std::thread::sleep(std::time::Duration::from_millis(20));
        };
        let mut stderr = String::new();
        let _ = std::io::Read::read_to_string(&mut child.stderr.take().unwrap(), &mut stderr);
        (code, stderr)
    };
    // A token that cannot travel in a header unchanged would refuse every change later.
    for token in [" s3cret-with-space", "s3cret ", "sécret-token-1234", "tab\there"] {
        let (code, stderr) = run(&["--token", token], None);
        assert_eq!(code, Some(2), "--token {token:?}: {stderr}");
        assert!(stderr.contains("--token"), "{stderr}");
    }
    let (code, stderr) = run(&[], Some("bad token"));
    assert_eq!(code, Some(2), "{stderr}");
    assert!(stderr.contains("AIRROADS_TOKEN"), "{stderr}");
    // A token short enough to guess is refused with the minimum named.
    for token in ["s3cret", "change-me", "fifteen-chars-x"] {
        let (code, stderr) = run(&["--token", token], None);
        assert_eq!(code, Some(2), "--token {token:?}: {stderr}");
        assert!(stderr.contains("--token") && stderr.contains("at least 16"), "{stderr}");
        let (code, stderr) = run(&[], Some(token));
        assert_eq!(code, Some(2), "AIRROADS_TOKEN={token:?}: {stderr}");
        assert!(stderr.contains("AIRROADS_TOKEN") && stderr.contains("at least 16"), "{stderr}");
    }
    // Motion capture on a public address needs the senders named.
    let (code, stderr) = run(&["--mocap", "0.0.0.0:0"], None);
    assert_eq!(code, Some(2), "{stderr}");
    assert!(stderr.contains("--mocap-allow"), "{stderr}");
    // A fleet larger than the admitted maximum.
    let (code, stderr) = run(&["--max-uavs", "2"], None);
    assert_eq!(code, Some(2), "{stderr}");
    assert!(stderr.contains("--max-uavs 2"), "{stderr}");
    let (code, stderr) = run(&["--allow-origin", "evil.example"], None);
    assert_eq!(code, Some(2), "{stderr}");
    assert!(stderr.contains("--allow-origin"), "{stderr}");
    // Sixteen characters are enough: it starts.
    let (child, _addr) = serve(&data, &["--token", "sixteen-chars-ok"]);
    drop(child);
    std::fs::remove_dir_all(&data).unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn with_few_file_descriptors_idle_sockets_cannot_block_the_emergency_stop() {
    let data = scratch("fds");
    // 128 open files in all (soft and hard): the server fits its connection caps under them.
    let mut command = Command::new("bash");
    command.args(["-c", "ulimit -n 128; exec \"$0\" \"$@\""]).arg(env!("CARGO_BIN_EXE_airroads"));
    command.args(["serve", "--addr", "127.0.0.1:0", "--data-dir", data.to_str().unwrap(), "--policy", "pd"]);
    let (_child, addr) = start_child(command);
    let mut idle = Vec::new();
    for _ in 0..200 {
        idle.push(tokio::net::TcpStream::connect(addr).await.unwrap());
    }
    tokio::time::sleep(std::time::Duration::from_millis(300)).await;
    let stop =
        tokio::time::timeout(std::time::Duration::from_secs(5), call(addr, "POST", "/api/fleet/stop", None));
    let (status, body) = stop.await.expect("the emergency stop answered within 5 s");
    assert_eq!(status, 200, "{body}");
    let metrics = call(addr, "GET", "/api/metrics", None).await.1;
    assert!(metrics["connections"]["limit"].as_u64().unwrap() <= 16, "{}", metrics["connections"]);
    drop(idle);
    std::fs::remove_dir_all(&data).unwrap();
}
