//! `GET /ws?format=bin`: a real server's binary stream decoded by the layout docs/streams.md documents (not by
//! the server's encoder) and compared with the JSON stream of the same ticks; the roster follows
//! changes; a viewport sends only the UAVs inside it; bad parameters are refused.

mod support;

use futures_util::StreamExt;
use serde_json::{Value, json};
use std::collections::HashMap;
use std::time::Duration;
use support::{config, small, start};
use tokio_tungstenite::tungstenite::Message;

type Socket = tokio_tungstenite::WebSocketStream<tokio_tungstenite::MaybeTlsStream<tokio::net::TcpStream>>;

/// docs/streams.md's status table: the status byte is the index in this list.
const STATUSES: [&str; 13] = [
    "flying",
    "arrived",
    "braking",
    "failed",
    "stale",
    "lost",
    "connecting",
    "taking_off",
    "landing",
    "landed",
    "stopped",
    "stopping",
    "waiting",
];

/// One UAV's record of a tick frame.
#[derive(Debug, Clone, PartialEq)]
struct Record {
    index: u32,
    p: [f32; 2],
    v: [f32; 2],
    u: [f32; 2],
    target: [f32; 2],
    status: &'static str,
    arrived: bool,
    lost: bool,
}

/// A tick frame.
#[derive(Debug)]
struct Tick {
    flags: u16,
    roster_version: u32,
    tick: u64,
    time: f64,
    fleet: u32,
    road_version: u32,
    margins: [f32; 2],
    d_c: f32,
    records: Vec<Record>,
}

/// A message of the binary stream.
#[derive(Debug)]
enum Frame {
    Roster(u32, Value),
    Tick(Tick),
    Reservations(u32, Value),
}

fn u32_at(b: &[u8], at: usize) -> u32 {
    u32::from_le_bytes(b[at..at + 4].try_into().unwrap())
}

fn f32_at(b: &[u8], at: usize) -> f32 {
    f32::from_le_bytes(b[at..at + 4].try_into().unwrap())
}

fn pair(b: &[u8], at: usize) -> [f32; 2] {
    [f32_at(b, at), f32_at(b, at + 4)]
}

fn decode(b: &[u8]) -> Frame {
    assert_eq!(b[0], 1, "format version");
    match b[1] {
        2 => Frame::Roster(u32_at(b, 4), serde_json::from_slice(&b[8..]).expect("the roster is JSON")),
        3 => Frame::Reservations(u32_at(b, 4), serde_json::from_slice(&b[8..]).expect("JSON reservations")),
        1 => {
            let count = u32_at(b, 28) as usize;
            assert_eq!(b.len(), 52 + 40 * count, "header and {count} records");
            let records = b[52..]
                .chunks_exact(40)
                .map(|r| Record {
                    index: u32_at(r, 0),
                    p: pair(r, 4),
                    v: pair(r, 12),
                    u: pair(r, 20),
                    target: pair(r, 28),
                    status: STATUSES[usize::from(r[36])],
                    arrived: r[37] & 1 != 0,
                    lost: r[37] & 2 != 0,
                })
                .collect();
            Frame::Tick(Tick {
                flags: u16::from_le_bytes([b[2], b[3]]),
                roster_version: u32_at(b, 4),
                tick: u64::from_le_bytes(b[8..16].try_into().unwrap()),
                time: f64::from_le_bytes(b[16..24].try_into().unwrap()),
                fleet: u32_at(b, 24),
                road_version: u32_at(b, 32),
                margins: pair(b, 36),
                d_c: f32_at(b, 44),
                records,
            })
        }
        kind => panic!("unknown frame kind {kind}"),
    }
}

async fn connect(addr: std::net::SocketAddr, query: &str) -> Socket {
    tokio_tungstenite::connect_async(format!("ws://{addr}/ws{query}")).await.unwrap().0
}

async fn next(socket: &mut Socket) -> Message {
    tokio::time::timeout(Duration::from_secs(5), socket.next())
        .await
        .expect("a frame within 5 s")
        .expect("the stream stays open")
        .expect("a valid frame")
}

/// The next roster or tick frame (reservations frames are checked apart).
async fn next_binary(socket: &mut Socket) -> Frame {
    loop {
        match next(socket).await {
            Message::Binary(b) => match decode(&b) {
                Frame::Reservations(..) => continue,
                frame => return frame,
            },
            other => panic!("a binary message, got {other:?}"),
        }
    }
}

async fn next_json(socket: &mut Socket) -> Value {
    loop {
        if let Message::Text(text) = next(socket).await {
            return serde_json::from_str(&text).unwrap();
        }
    }
}

fn close(a: f32, b: &Value) -> bool {
    (f64::from(a) - b.as_f64().unwrap()).abs() < 1e-4
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_binary_stream_carries_what_the_json_stream_carries() {
    let server = start(config(&small())).await;
    let mut json_client = connect(server.addr, "").await;
    let mut bin = connect(server.addr, "?format=bin").await;
    // A new client gets the roster first, in full.
    let Frame::Roster(version, roster) = next_binary(&mut bin).await else { panic!("roster first") };
    assert_eq!(roster["uavs"].as_array().unwrap().len(), 2, "{roster}");
    assert_eq!((&roster["uavs"][0]["id"], &roster["uavs"][1]["id"]), (&json!("a"), &json!("b")));
    assert_eq!(roster["uavs"][0]["goal"], json!([5.0, -1.0]));
    assert_eq!((&roster["uavs"][0]["policy"], &roster["uavs"][0]["link"]), (&json!("pd"), &json!("sim")));

    // The same ticks from both streams agree field by field.
    let mut by_tick: HashMap<u64, Value> = HashMap::new();
    let mut compared = 0;
    while compared < 10 {
        tokio::select! {
            state = next_json(&mut json_client) => { by_tick.insert(state["tick"].as_u64().unwrap(), state); }
            frame = next_binary(&mut bin) => {
                let Frame::Tick(t) = frame else { panic!("no roster change expected") };
                assert_eq!((t.roster_version, t.fleet, t.records.len()), (version, 2, 2));
                let Some(state) = by_tick.get(&t.tick) else { continue };
                assert!((t.time - state["time"].as_f64().unwrap()).abs() < 1e-9);
                assert_eq!((t.flags & 1 != 0, u64::from(t.road_version)), (state["paused"] == json!(true), state["road_version"].as_u64().unwrap()));
                assert!(close(t.margins[1], &state["min_road_margin_m"]) && close(t.d_c, &state["d_c"]));
                for (r, u) in t.records.iter().zip(state["uavs"].as_array().unwrap()) {
                    assert_eq!(r.index, if u["id"] == "a" { 0 } else { 1 });
                    for (field, value) in [("p", r.p), ("v", r.v), ("u", r.u), ("target", r.target)] {
                        assert!(close(value[0], &u[field][0]) && close(value[1], &u[field][1]), "{field}: {r:?} {u}");
                    }
                    assert_eq!((r.status, r.arrived, r.lost), (u["status"].as_str().unwrap(), u["arrived"] == json!(true), u["lost"] == json!(true)));
                }
                compared += 1;
            }
        }
    }

    // A new goal changes the roster: a roster frame of the next version comes before the tick frame
    // that uses it.
    let (status, reply) = server.call("PUT", "/api/uavs/a/goal", Some(r#"{"goal": [8.0, -1.0]}"#)).await;
    assert_eq!(status, 200, "{reply}");
    loop {
        match next_binary(&mut bin).await {
            Frame::Tick(t) if t.roster_version == version => continue,
            Frame::Tick(t) => panic!("tick of roster {} before its roster", t.roster_version),
            Frame::Roster(v, roster) => {
                assert!(v > version, "{v} after {version}");
                assert_eq!(roster["uavs"][0]["goal"], json!([8.0, -1.0]));
                let Frame::Tick(t) = next_binary(&mut bin).await else { panic!("a tick after the roster") };
                assert_eq!(t.roster_version, v);
                break;
            }
            Frame::Reservations(..) => unreachable!("next_binary skips them"),
        }
    }
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_viewport_gets_only_the_uavs_inside_it() {
    let server = start(config(&small())).await;
    // `a` flies along y = −1 and `b` along y = +1: the lower half of the road holds `a` only.
    let mut lower = connect(server.addr, "?format=bin&bbox=-100,-100,100,0&rate=10").await;
    let Frame::Roster(_, roster) = next_binary(&mut lower).await else { panic!("roster first") };
    assert_eq!(roster["uavs"].as_array().unwrap().len(), 2, "the roster is the whole fleet's");
    for _ in 0..5 {
        let Frame::Tick(t) = next_binary(&mut lower).await else { panic!("ticks") };
        assert_eq!(t.flags & 2, 2, "marked as filtered");
        assert_eq!(t.fleet, 2);
        assert_eq!(t.records.len(), 1, "{t:?}");
        assert!(t.records[0].index == 0 && t.records[0].p[1] < 0.0, "{t:?}");
    }
    let mut empty = connect(server.addr, "?format=bin&bbox=50,50,60,60").await;
    next_binary(&mut empty).await;
    let Frame::Tick(t) = next_binary(&mut empty).await else { panic!("ticks") };
    assert!(t.records.is_empty() && t.fleet == 2);
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn bad_stream_parameters_are_refused_with_the_field_named() {
    let server = start(config(&small())).await;
    for (query, field) in [
        ("format=xml", "format"),
        ("format=bin&bbox=1,2,3", "bbox"),
        ("format=bin&bbox=1,2,0,3", "bbox"),
        ("format=bin&bbox=0,0,NaN,1", "bbox"),
        ("format=bin&bbox=0,0,inf,1", "bbox"),
        ("bbox=0,0,1,1", "bbox"),
    ] {
        // A real WebSocket handshake, refused with the API's JSON error.
        let refused = tokio_tungstenite::connect_async(format!("ws://{}/ws?{query}", server.addr)).await;
        let Err(tokio_tungstenite::tungstenite::Error::Http(response)) = refused else {
            panic!("{query}: not refused with an HTTP answer")
        };
        let body: Value =
            serde_json::from_slice(response.body().as_deref().unwrap_or_default()).unwrap_or_default();
        assert_eq!(
            (response.status().as_u16(), body["error"]["field"].as_str()),
            (422, Some(field)),
            "{query}: {body}"
        );
    }
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn single_file_sections_come_as_a_reservations_frame_when_they_change() {
    let server = start(config(&small())).await;
    let scenario =
        std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/../scenarios/narrow16.json")).unwrap();
    let (status, reply) = server.call("POST", "/api/scenario", Some(&scenario)).await;
    assert_eq!(status, 200, "{reply}");
    let mut bin = connect(server.addr, "?format=bin").await;
    let (mut versions, mut ticks) = (Vec::new(), 0);
    while ticks < 60 {
        let Message::Binary(b) = next(&mut bin).await else { continue };
        match decode(&b) {
            Frame::Reservations(version, body) => {
                let state = server.get("/api/state").await;
                let sections = body["reservations"].as_array().unwrap();
                assert_eq!(sections.len(), state["reservations"].as_array().unwrap().len(), "{body}");
                assert!(
                    sections.iter().all(|z| z["path"].as_array().is_some_and(|p| p.len() >= 2)),
                    "{body}"
                );
                versions.push(version);
            }
            Frame::Tick(_) => ticks += 1,
            Frame::Roster(..) => {}
        }
    }
    // First to the new client, then only when a section's state changed (not every tick).
    assert!(!versions.is_empty() && versions.len() < 60, "{versions:?}");
    assert!(versions.windows(2).all(|w| w[0] < w[1]), "{versions:?}");
    server.stop().await;
}
