//! Helpers of the server's end-to-end tests: start the real server on 127.0.0.1:0 and talk to it
//! with a minimal HTTP/1.1 client over a TCP socket (no client library to trust instead).

#![allow(dead_code)]

pub mod crazyflies;
pub mod firmware;
pub mod procs;
pub mod regions;

use airroads_server::serve::{ServeConfig, Server};
use serde_json::Value;
use std::net::SocketAddr;
use std::path::PathBuf;
use tokio::sync::oneshot;

/// The keys of METRICS.json, sorted: a public contract (docs/runs.md).
pub const METRICS_KEYS: [&str; 15] = [
    "all_arrived",
    "arrival_time_s",
    "max_stall_s",
    "max_wait_s",
    "min_collision_margin_m",
    "min_road_margin_m",
    "min_separation_m",
    "min_wall_distance_m",
    "qp",
    "safe",
    "scenario",
    "sim_time_s",
    "stall_s",
    "steps_outside_road",
    "ticks",
];

/// The repository root.
pub fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// A validated scenario from JSON.
pub fn scenario(json: &Value) -> fleet::ValidScenario {
    fleet::Scenario::from_json(&json.to_string()).unwrap().validate().unwrap()
}

/// A shipped scenario file as JSON.
pub fn shipped(name: &str) -> Value {
    let text = std::fs::read_to_string(repo().join("scenarios").join(name)).unwrap();
    serde_json::from_str(&text).unwrap()
}

/// A straight road 20 m long, 4 m wide (two segments), with two UAVs flying 3 m along it.
pub fn small() -> Value {
    serde_json::json!({
        "name": "small",
        "segments": roads::RoadLayout::straight(0.0, 20.0, 4.0, 2).segments,
        "uavs": [
            {"id": "a", "start": [2.0, -1.0], "goal": [5.0, -1.0]},
            {"id": "b", "start": [2.0, 1.0], "goal": [5.0, 1.0]}
        ]
    })
}

/// A running server and how to reach it.
pub struct Running {
    /// Its address.
    pub addr: SocketAddr,
    /// Its shared handler state (to look inside, or to stage a failure).
    pub state: api::state::AppState,
    stop: Option<oneshot::Sender<()>>,
    task: Option<tokio::task::JoinHandle<anyhow::Result<()>>>,
}

/// The configuration of a test server flying `initial` with the PD policy by default.
pub fn config(initial: &Value) -> ServeConfig {
    let policies = policies::PolicyRegistry::standard(5.0).unwrap();
    ServeConfig::new(fleet::FleetConfig::default(), policies, "pd".into(), scenario(initial))
}

/// Starts the real server on 127.0.0.1:0.
pub async fn start(config: ServeConfig) -> Running {
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
    let addr = listener.local_addr().unwrap();
    let server = Server::start(config).unwrap();
    let state = server.state().clone();
    let (stop, stopped) = oneshot::channel::<()>();
    let task = tokio::spawn(airroads_server::serve::serve(listener, server, async move {
        let _ = stopped.await;
    }));
    Running { addr, state, stop: Some(stop), task: Some(task) }
}

impl Running {
    /// Shuts the server down and waits until it stopped.
    pub async fn stop(mut self) {
        let _ = self.stop.take().unwrap().send(());
        self.task.take().unwrap().await.unwrap().unwrap();
    }

    /// Sends a request; returns the status and the body parsed as JSON (Null when empty).
    pub async fn call(&self, method: &str, path: &str, body: Option<&str>) -> (u16, Value) {
        self.call_with(method, path, body, &[]).await
    }

    /// Sends a request with extra headers.
    pub async fn call_with(
        &self,
        method: &str,
        path: &str,
        body: Option<&str>,
        headers: &[(&str, &str)],
    ) -> (u16, Value) {
        let (status, text) = raw(self.addr, method, path, body, headers).await;
        let value = if text.trim().is_empty() {
            Value::Null
        } else {
            serde_json::from_str(&text).unwrap_or_else(|e| panic!("{method} {path}: not JSON ({e}): {text}"))
        };
        (status, value)
    }

    /// `GET path` as JSON, asserting 200.
    pub async fn get(&self, path: &str) -> Value {
        let (status, body) = self.call("GET", path, None).await;
        assert_eq!(status, 200, "GET {path}: {body}");
        body
    }

    /// Polls `GET /api/state` until `done(state)` or `timeout_s` seconds passed; returns the last state.
    pub async fn wait_for(&self, timeout_s: f64, done: impl Fn(&Value) -> bool) -> Value {
        let deadline = std::time::Instant::now() + std::time::Duration::from_secs_f64(timeout_s);
        loop {
            let state = self.get("/api/state").await;
            if done(&state) || std::time::Instant::now() > deadline {
                return state;
            }
            tokio::time::sleep(std::time::Duration::from_millis(50)).await;
        }
    }
}

/// One HTTP/1.1 exchange with `Connection: close`: the status code and the body text.
pub async fn raw(
    addr: SocketAddr,
    method: &str,
    path: &str,
    body: Option<&str>,
    headers: &[(&str, &str)],
) -> (u16, String) {
    api::client::request(addr, method, path, body, headers).await.unwrap()
}

/// A response read off the wire: status, headers (names lower-cased) and body.
#[derive(Debug)]
pub struct Wire {
    /// Status code (0 when the server closed without answering).
    pub status: u16,
    /// Header lines as (lower-cased name, value).
    pub headers: Vec<(String, String)>,
    /// The body text.
    pub body: String,
}

impl Wire {
    /// The first value of header `name` (lower case).
    pub fn header(&self, name: &str) -> Option<&str> {
        self.headers.iter().find(|(k, _)| k == name).map(|(_, v)| v.as_str())
    }

    /// The body as JSON (Null when empty or not JSON).
    pub fn json(&self) -> Value {
        serde_json::from_str(&self.body).unwrap_or(Value::Null)
    }
}

/// Sends `request` (a whole HTTP/1.1 request, `Connection: close` expected) byte for byte and reads
/// the answer until the server closes (at most 10 s).
pub async fn exchange(addr: SocketAddr, request: &[u8]) -> Wire {
    use tokio::io::{AsyncReadExt, AsyncWriteExt};
    let mut stream = tokio::net::TcpStream::connect(addr).await.unwrap();
    stream.write_all(request).await.unwrap();
    let mut response = Vec::new();
    let read =
        tokio::time::timeout(std::time::Duration::from_secs(10), stream.read_to_end(&mut response)).await;
    assert!(read.is_ok(), "no complete answer within 10 s: {}", String::from_utf8_lossy(&response));
    let text = String::from_utf8_lossy(&response).into_owned();
    let Some((head, body)) = text.split_once("\r\n\r\n") else {
        return Wire { status: 0, headers: Vec::new(), body: text };
    };
    let mut lines = head.lines();
    let status = lines.next().and_then(|l| l.split(' ').nth(1)).and_then(|s| s.parse().ok()).unwrap_or(0);
    let headers = lines
        .filter_map(|l| l.split_once(':'))
        .map(|(k, v)| (k.trim().to_ascii_lowercase(), v.trim().to_string()))
        .collect();
    Wire { status, headers, body: body.to_string() }
}

/// A request text with the given method, path, extra header lines and body (`Connection: close`).
pub fn request_text(method: &str, path: &str, headers: &[&str], body: &str) -> String {
    let mut text =
        format!("{method} {path} HTTP/1.1\r\nConnection: close\r\nContent-Length: {}\r\n", body.len());
    for h in headers {
        text.push_str(h);
        text.push_str("\r\n");
    }
    text.push_str("\r\n");
    text.push_str(body);
    text
}

/// Starts the real server with `config` changed by `change`.
pub async fn start_with(initial: &Value, change: impl FnOnce(&mut ServeConfig)) -> Running {
    let mut c = config(initial);
    change(&mut c);
    start(c).await
}
