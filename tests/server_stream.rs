//! End-to-end tests of the WebSocket stream and of a scenario flown by the real server: ticks
//! advance, UAVs reach their goals, slow clients do not slow anyone else, and a scenario loaded over
//! REST flies as `airroads run` flies it.

mod support;

use futures_util::StreamExt;
use serde_json::{Value, json};
use std::time::{Duration, Instant};
use support::{config, small, start};
use tokio_tungstenite::tungstenite::Message;

type Socket = tokio_tungstenite::WebSocketStream<tokio_tungstenite::MaybeTlsStream<tokio::net::TcpStream>>;

async fn connect(addr: std::net::SocketAddr, query: &str) -> Socket {
    let (socket, _) = tokio_tungstenite::connect_async(format!("ws://{addr}/ws{query}")).await.unwrap();
    socket
}

async fn next_frame(socket: &mut Socket) -> Value {
    loop {
        let message = tokio::time::timeout(Duration::from_secs(5), socket.next())
            .await
            .expect("a frame within 5 s")
            .expect("the stream stays open")
            .expect("a valid frame");
        if let Message::Text(text) = message {
            return serde_json::from_str(&text).unwrap();
        }
    }
}

fn all_arrived(state: &Value) -> bool {
    let uavs = state["uavs"].as_array().unwrap();
    !uavs.is_empty() && uavs.iter().all(|u| u["arrived"] == json!(true))
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_websocket_client_sees_ticks_advance_and_uavs_arrive() {
    let server = start(config(&small())).await;
    let mut socket = connect(server.addr, "").await;
    let mut last_tick: Option<u64> = None;
    let deadline = Instant::now() + Duration::from_secs(30);
    let mut frames = 0;
    loop {
        let frame = next_frame(&mut socket).await;
        let tick = frame["tick"].as_u64().unwrap();
        assert!(last_tick.is_none_or(|last| tick > last), "ticks advance: {tick} after {last_tick:?}");
        last_tick = Some(tick);
        frames += 1;
        if all_arrived(&frame) {
            break;
        }
        assert!(Instant::now() < deadline, "not all arrived after 30 s: {frame}");
    }
    assert!(frames > 10, "{frames} frames");
    // The state document and the stream carry the same shape.
    let state = server.get("/api/state").await;
    assert!(all_arrived(&state));
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn rate_limits_frames_and_stalled_clients_slow_no_one() {
    let server = start(config(&small())).await;
    let (status, _) = support::raw(server.addr, "GET", "/ws?rate=-1", None, &[]).await;
    assert!((400..500).contains(&status), "{status}");
    let refused = tokio_tungstenite::connect_async(format!("ws://{}/ws?rate=abc", server.addr)).await;
    assert!(refused.is_err());

    // Ten clients that never read, one at full rate, one at 4 Hz.
    let mut stalled = Vec::new();
    for _ in 0..10 {
        stalled.push(connect(server.addr, "").await);
    }
    let mut full = connect(server.addr, "").await;
    let mut slow = connect(server.addr, "?rate=4").await;
    let first = next_frame(&mut full).await["tick"].as_u64().unwrap();
    let started = Instant::now();
    let mut slow_frames = 0;
    let mut last = first;
    while started.elapsed() < Duration::from_secs(3) {
        tokio::select! {
            f = next_frame(&mut full) => {
                let tick = f["tick"].as_u64().unwrap();
                assert!(tick > last);
                last = tick;
            }
            _ = next_frame(&mut slow) => slow_frames += 1,
        }
    }
    let ticks = last - first;
    // 20 Hz for 3 s: 60 ticks, less scheduling noise on a loaded 2-core machine.
    assert!((45..=62).contains(&ticks), "{ticks} ticks in 3 s");
    assert!((8..=16).contains(&slow_frames), "{slow_frames} frames at 4 Hz in 3 s");
    let metrics = server.get("/api/metrics").await;
    assert_eq!(metrics["stream"]["clients"], 12, "{metrics}");
    drop(stalled);
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_scenario_loaded_over_rest_flies_as_airroads_run_flies_it() {
    let lab3 = support::shipped("lab3.json");
    let headless = fleet::run_scenario(
        &support::scenario(&lab3),
        fleet::RunOptions {
            config: fleet::FleetConfig::default(),
            policy: "pd".into(),
            trajectory: None,
            paths: false,
        },
        policies::PolicyRegistry::standard(5.0).unwrap(),
    )
    .unwrap()
    .metrics;
    assert!(headless.safe && headless.all_arrived);

    let server = start(config(&small())).await;
    let mut socket = connect(server.addr, "").await;
    let (status, body) = server.call("POST", "/api/scenario", Some(&lab3.to_string())).await;
    assert_eq!(status, 200, "{body}");
    let loaded = body["loaded_after_tick"].as_u64().unwrap();
    let deadline = Instant::now() + Duration::from_secs(90);
    let arrived_tick = loop {
        let frame = next_frame(&mut socket).await;
        let tick = frame["tick"].as_u64().unwrap();
        if tick > loaded && frame["uavs"].as_array().unwrap().len() == 3 && all_arrived(&frame) {
            break tick;
        }
        assert!(Instant::now() < deadline, "lab3 not arrived after 90 s: {frame}");
    };
    // The same fleet code on the same scenario: the same arrival tick, up to solver round-off.
    let flown = arrived_tick - loaded;
    assert!(flown.abs_diff(headless.ticks) <= 2, "server {flown} ticks, headless {}", headless.ticks);
    let metrics = server.get("/api/metrics").await;
    let params = &lab3["params"];
    let d_c = params["D_c"].as_f64().unwrap_or(0.3);
    let d_s = params["D_s"].as_f64().unwrap_or(0.1);
    assert!(metrics["min_collision_margin_m"].as_f64().unwrap() >= d_c, "{metrics}");
    assert!(metrics["min_road_margin_m"].as_f64().unwrap() >= d_s, "{metrics}");
    assert_eq!(metrics["qp"]["failures"], 0);
    server.stop().await;
}
