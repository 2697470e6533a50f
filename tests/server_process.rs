//! `airroads serve` as a process: it starts with no scenario (the embedded demo), refuses a public
//! address without a token, and resumes road, fleet and goals after kill -9.

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
fn serve(data_dir: &Path, args: &[&str]) -> (Child, SocketAddr) {
    let mut child = Command::new(env!("CARGO_BIN_EXE_airroads"))
        .args(["serve", "--addr", "127.0.0.1:0", "--data-dir", data_dir.to_str().unwrap()])
        .args(args)
        .env_remove("AIRROADS_TOKEN")
        .stdout(Stdio::piped())
        .stderr(Stdio::inherit())
        .spawn()
        .unwrap();
    let mut lines = BufReader::new(child.stdout.take().unwrap()).lines();
    let first = lines.next().expect("a banner line").unwrap();
    let addr = first.rsplit("http://").next().unwrap().trim().parse().unwrap_or_else(|_| panic!("{first}"));
    // Keep draining stdout so the server never blocks on a full pipe.
    std::thread::spawn(move || for _ in lines.by_ref() {});
    (child, addr)
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
    assert_eq!(call(addr, "PUT", "/api/road", Some(&wider)).await.0, 200);
    let new = json!({"id": "extra", "position": [13.0, 16.0], "goal": [10.0, 17.0], "policy": "pd"});
    assert_eq!(call(addr, "POST", "/api/uavs", Some(&new)).await.0, 201);
    assert_eq!(call(addr, "DELETE", "/api/uavs/uav1", None).await.0, 204);
    tokio::time::sleep(std::time::Duration::from_millis(1500)).await;
    child.kill().unwrap();
    child.wait().unwrap();

    let (mut child, addr) = serve(&data, &[]);
    assert_eq!(call(addr, "GET", "/api/road", None).await.1, wider);
    let uavs = call(addr, "GET", "/api/uavs", None).await.1;
    let ids: Vec<&str> = uavs.as_array().unwrap().iter().map(|u| u["id"].as_str().unwrap()).collect();
    assert!(ids.contains(&"extra") && !ids.contains(&"uav1"), "{ids:?}");
    let extra = uavs.as_array().unwrap().iter().find(|u| u["id"] == "extra").unwrap();
    assert_eq!(extra["goal"], json!([10.0, 17.0]));
    assert_eq!(extra["policy"], "pd");
    child.kill().unwrap();
    child.wait().unwrap();
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
    let out = child.wait_with_output().unwrap();
    assert_eq!(out.status.code(), Some(0));
    assert!(data.join("state.json").exists());
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
    let out = child.wait_with_output().unwrap();
    assert_eq!(out.status.code(), Some(0));
    // Landing takes its 2 s before the server exits.
    assert!(started.elapsed() >= std::time::Duration::from_secs(2), "exited before landing");
    assert!(started.elapsed() < std::time::Duration::from_secs(12));
}
