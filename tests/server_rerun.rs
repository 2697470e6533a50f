//! Rerun: a real server records its fleet with `--rerun save=FILE.rrd`; the file is read back with
//! Rerun's own decoder and checked entity by entity against what the server published.

mod support;

use airroads_server::serve::Server;
use api::state::AppState;
use rerun::components::{LineStrip2D, Position2D};
use rerun::external::re_log_encoding::DecoderApp;
use rerun::log::{Chunk, LogMsg};
use rerun::{Clear, ComponentIdentifier, EntityPath, LineStrips2D, Points2D, Scalars, TimelineName};
use rerun_sink::RerunMode;
use std::collections::HashMap;
use std::time::Duration;

/// The chunks of one recording, by entity.
struct Recording {
    application_ids: Vec<String>,
    chunks: HashMap<EntityPath, Vec<Chunk>>,
}

fn read_rrd(path: &std::path::Path) -> Recording {
    let file = std::fs::File::open(path).unwrap();
    let mut recording = Recording { application_ids: Vec::new(), chunks: HashMap::new() };
    for msg in DecoderApp::decode_lazy(std::io::BufReader::new(file)) {
        match msg.expect("a valid .rrd") {
            LogMsg::SetStoreInfo(info) => {
                recording.application_ids.push(info.info.application_id().to_string())
            }
            LogMsg::ArrowMsg(_, arrow) => {
                let chunk = Chunk::from_arrow_msg(&arrow).unwrap();
                recording.chunks.entry(chunk.entity_path().clone()).or_default().push(chunk);
            }
            LogMsg::BlueprintActivationCommand(_) => {}
        }
    }
    recording
}

impl Recording {
    fn chunks(&self, path: &str) -> &[Chunk] {
        self.chunks.get(&EntityPath::from(path)).map_or(&[], Vec::as_slice)
    }

    /// (tick, value) of every row of `path` holding `component`, in tick order; `read` gives the
    /// values of a chunk's non-null rows of that component.
    fn rows<T>(
        &self,
        path: &str,
        component: ComponentIdentifier,
        read: impl Fn(&Chunk) -> Vec<T>,
    ) -> Vec<(i64, T)> {
        let mut rows = Vec::new();
        for chunk in self.chunks(path) {
            assert!(chunk.timelines().contains_key(&TimelineName::from("time")), "{path}: no time timeline");
            let ticks: Vec<i64> = chunk
                .iter_component_indices(TimelineName::from("tick"), component)
                .map(|(t, _)| t.as_i64())
                .collect();
            let values = read(chunk);
            assert_eq!(ticks.len(), values.len(), "{path}: rows without a tick");
            rows.extend(ticks.into_iter().zip(values));
        }
        rows.sort_by_key(|(t, _)| *t);
        rows
    }

    /// The scalar series at `path`.
    fn scalars(&self, path: &str) -> Vec<(i64, f64)> {
        let component = Scalars::descriptor_scalars().component;
        self.rows(path, component, |c| c.iter_slices::<f64>(component).map(|s| s[0]).collect())
    }

    /// The positions logged at `path` (one point per row).
    fn points(&self, path: &str) -> Vec<(i64, [f32; 2])> {
        let component = Points2D::descriptor_positions().component;
        self.rows(path, component, |c| {
            c.iter_component::<Position2D>(component).map(|b| [b[0].x(), b[0].y()]).collect()
        })
    }

    /// The positions logged at `path`, one batch per row.
    fn point_batches(&self, path: &str) -> Vec<(i64, Vec<[f32; 2]>)> {
        let component = Points2D::descriptor_positions().component;
        self.rows(path, component, |c| {
            c.iter_component::<Position2D>(component)
                .map(|b| b.iter().map(|p| [p.x(), p.y()]).collect())
                .collect()
        })
    }

    /// The label batches logged at `path`, one per row that has labels.
    fn label_batches(&self, path: &str) -> Vec<(i64, Vec<String>)> {
        let component = Points2D::descriptor_labels().component;
        self.rows(path, component, |c| {
            c.iter_slices::<String>(component).map(|s| s.iter().map(|l| l.to_string()).collect()).collect()
        })
    }

    /// The labels logged at `path` (one per row).
    fn labels(&self, path: &str) -> Vec<(i64, String)> {
        let component = Points2D::descriptor_labels().component;
        self.rows(path, component, |c| c.iter_slices::<String>(component).map(|s| s[0].to_string()).collect())
    }

    /// The line strips logged at `path`, one batch per row.
    fn strips(&self, path: &str) -> Vec<(i64, Vec<Vec<[f32; 2]>>)> {
        let component = LineStrips2D::descriptor_strips().component;
        self.rows(path, component, |c| {
            c.iter_component::<LineStrip2D>(component)
                .map(|batch| batch.iter().map(|s| s.0.iter().map(|v| v.0).collect()).collect())
                .collect()
        })
    }
}

fn temp_rrd() -> std::path::PathBuf {
    let nanos = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).unwrap().as_nanos();
    std::env::temp_dir().join(format!("airroads-rerun-{}-{nanos}.rrd", std::process::id()))
}

fn walls_as_strips(road: &engine::fleet_loop::RoadView) -> Vec<Vec<[f32; 2]>> {
    road.walls.iter().map(|w| w.iter().map(|p| [p[0] as f32, p[1] as f32]).collect()).collect()
}

/// A real server on 127.0.0.1:0 with a Rerun sink in `mode`.
struct Running {
    addr: std::net::SocketAddr,
    state: AppState,
    sink: rerun_sink::RerunSink,
    stop: tokio::sync::oneshot::Sender<()>,
    serving: tokio::task::JoinHandle<anyhow::Result<()>>,
}

async fn start(mode: &str) -> Running {
    start_batching_above(mode, rerun_sink::BATCH_ABOVE_UAVS).await
}

/// As [`start`], logging fleets of more than `batch_above` UAVs as one batch.
async fn start_batching_above(mode: &str, batch_above: usize) -> Running {
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
    let addr = listener.local_addr().unwrap();
    let server = Server::start(support::config(&support::small())).unwrap();
    let state = server.state().clone();
    let mode: RerunMode = mode.parse().unwrap();
    let sink = rerun_sink::start(&mode, state.rerun_inputs(), batch_above).unwrap().expect("a sink");
    let (stop, stopped) = tokio::sync::oneshot::channel::<()>();
    let serving = tokio::spawn(airroads_server::serve::serve(listener, server, async move {
        let _ = stopped.await;
    }));
    Running { addr, state, sink, stop, serving }
}

impl Running {
    /// Stops the server; the sink then ends by itself (the loop's channels close) and flushes.
    async fn stop(self) -> rerun_sink::SinkStats {
        self.stop.send(()).unwrap();
        self.serving.await.unwrap().unwrap();
        let sink = self.sink;
        tokio::task::spawn_blocking(move || sink.finish()).await.unwrap().expect("sink finished in time")
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn save_mode_records_road_uavs_and_series_readable_by_rerun() {
    let rrd = temp_rrd();
    let server = start(&format!("save={}", rrd.display())).await;
    let first_road = walls_as_strips(&server.state.engine.road.borrow());

    // Fly, then change the road (walls logged again) and remove `b` (its entities cleared), fly on.
    tokio::time::sleep(Duration::from_millis(600)).await;
    let longer = serde_json::json!({"segments": roads::RoadLayout::straight(0.0, 30.0, 4.0, 3).segments});
    let (status, body) = support::raw(server.addr, "PUT", "/api/road", Some(&longer.to_string()), &[]).await;
    assert_eq!(status, 200, "{body}");
    let (status, body) = support::raw(server.addr, "DELETE", "/api/uavs/b", None, &[]).await;
    assert_eq!(status, 204, "{body}");
    let second_road = walls_as_strips(&server.state.engine.road.borrow());
    assert_ne!(first_road, second_road);
    tokio::time::sleep(Duration::from_millis(600)).await;
    let state = server.state.clone();
    let stats = server.stop().await;
    let last = state.engine.snapshots.borrow().clone();
    assert_eq!(stats.errors, 0);
    assert!(stats.logged >= 10, "{stats:?}");

    let rec = read_rrd(&rrd);
    std::fs::remove_file(&rrd).unwrap();
    assert_eq!(rec.application_ids.first().map(String::as_str), Some(rerun_sink::APPLICATION_ID));

    // The road: the first layout, then the longer one, exactly as the server drew them.
    let walls = rec.strips("world/road/walls");
    assert_eq!(walls.len(), 2, "walls logged once per road version");
    assert_eq!((&walls[0].1, &walls[1].1), (&first_road, &second_road));
    let centre = rec.strips("world/road/centerline");
    assert_eq!(centre.len(), 2);
    assert!(centre.iter().all(|(_, strips)| strips.len() == 1 && strips[0].len() >= 2));

    // Each UAV: labelled positions on increasing ticks, starting where the scenario put it.
    for (id, y) in [("a", -1.0f32), ("b", 1.0)] {
        let root = format!("world/uavs/{id}");
        let points = rec.points(&root);
        assert!(points.len() >= 5, "{id}: {} positions", points.len());
        assert!(points.windows(2).all(|w| w[0].0 < w[1].0), "{id}: ticks not increasing");
        let (x0, y0) = (points[0].1[0], points[0].1[1]);
        assert!((x0 - 2.0).abs() < 0.3 && (y0 - y).abs() < 0.3, "{id} starts at ({x0}, {y0})");
        let labels = rec.labels(&root);
        assert!(labels.len() == points.len() && labels.iter().all(|(_, l)| l == id), "{id}: {labels:?}");
        for leaf in ["velocity", "target", "trail"] {
            assert!(!rec.chunks(&format!("{root}/{leaf}")).is_empty(), "{root}/{leaf} missing");
        }
        let goals = rec.points(&format!("{root}/goal"));
        assert!(
            !goals.is_empty()
                && goals.iter().all(|(_, g)| (g[0] - 5.0).abs() < 1e-4 && (g[1] - y).abs() < 1e-4)
        );
        let slack = rec.scalars(&format!("slack/{id}"));
        assert!(slack.len() >= 5 && slack.iter().all(|(_, s)| s.is_finite() && *s >= 0.0), "slack/{id}");
        let barrier = rec.scalars(&format!("barrier/{id}"));
        assert!(barrier.len() >= 5 && barrier.iter().all(|(_, b)| b.is_finite()), "barrier/{id}");
    }
    // `a` flew towards its goal; its last logged position is where the server left it.
    let a = rec.points("world/uavs/a");
    let final_a = last.uavs.iter().find(|u| &*u.id == "a").unwrap().p;
    assert!(a.last().unwrap().1[0] > a[0].1[0] + 0.2, "a did not move: {a:?}");
    assert!((f64::from(a.last().unwrap().1[0]) - final_a[0]).abs() < 0.2, "{a:?} vs {final_a:?}");

    // `b` was removed: its subtree was cleared once, recursively, and not logged afterwards.
    let clear = Clear::descriptor_is_recursive().component;
    let cleared =
        rec.rows("world/uavs/b", clear, |c| c.iter_slices::<bool>(clear).map(|s| s.value(0)).collect());
    assert_eq!(cleared.len(), 1, "{cleared:?}");
    assert!(cleared[0].1, "not recursive");
    assert!(rec.points("world/uavs/b").iter().all(|(t, _)| *t < cleared[0].0));

    // Fleet series: margins stay positive, tick timing p99 ≥ p50.
    for series in ["margins/road", "margins/collision", "tick_us/p50", "tick_us/p99"] {
        let values = rec.scalars(series);
        assert!(values.len() >= 5, "{series}: {} values", values.len());
        assert!(values.iter().all(|(_, v)| v.is_finite() && *v > 0.0), "{series}: {values:?}");
    }
    let p50: HashMap<i64, f64> = rec.scalars("tick_us/p50").into_iter().collect();
    assert!(rec.scalars("tick_us/p99").iter().all(|(t, p99)| p50.get(t).is_none_or(|p50| p99 >= p50)));
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn connect_without_a_viewer_keeps_the_server_running() {
    // A port nothing listens on: the sink logs nothing and skips; the loop and the API carry on.
    let closed = std::net::TcpListener::bind("127.0.0.1:0").unwrap().local_addr().unwrap();
    let server = start(&format!("connect={closed}")).await;
    let tick = server.state.engine.snapshots.borrow().tick;
    tokio::time::sleep(Duration::from_millis(1500)).await;
    let (status, _) = support::raw(server.addr, "GET", "/healthz", None, &[]).await;
    assert_eq!(status, 200);
    let ticked = server.state.engine.snapshots.borrow().tick - tick;
    assert!(ticked >= 20, "{ticked} ticks in 1.5 s");
    let stopping = std::time::Instant::now();
    let stats = server.stop().await;
    assert!(stopping.elapsed() < Duration::from_secs(3), "shutdown took {:?}", stopping.elapsed());
    assert_eq!((stats.logged, stats.errors), (0, 0));
    assert!(stats.skipped >= 20, "{stats:?}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn single_file_reservations_are_logged_with_who_is_in_and_who_waits() {
    let rrd = temp_rrd();
    let server = start(&format!("save={}", rrd.display())).await;
    // The narrow-section scenario: a 0.9 m wide section between x = −2.5 and 2.5, 8 UAVs each side.
    let scenario =
        std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/../scenarios/narrow16.json")).unwrap();
    let (status, body) = support::raw(server.addr, "POST", "/api/scenario", Some(&scenario), &[]).await;
    assert_eq!(status, 200, "{body}");
    tokio::time::sleep(Duration::from_millis(2500)).await;
    let state = server.state.clone();
    let stats = server.stop().await;
    assert_eq!(stats.errors, 0);
    let last = state.engine.snapshots.borrow().clone();
    assert_eq!(last.reservations.len(), 1, "one single-file section");

    let rec = read_rrd(&rrd);
    std::fs::remove_file(&rrd).unwrap();
    let strips = rec.strips("world/road/reservations");
    assert!(strips.len() >= 5, "logged every tick: {} rows", strips.len());
    for (_, batch) in &strips {
        assert_eq!(batch.len(), 1, "one strip per section");
        // Along the centre line through the section (with the funnels where the lanes are tight).
        assert!(batch[0].iter().all(|p| p[0].abs() < 6.0 && p[1].abs() < 1e-3), "{:?}", batch[0]);
        assert!(batch[0].iter().any(|p| p[0] < -2.4) && batch[0].iter().any(|p| p[0] > 2.4));
    }
    let component = LineStrips2D::descriptor_labels().component;
    let labels = rec.rows("world/road/reservations", component, |c| {
        c.iter_slices::<String>(component).map(|s| s[0].to_string()).collect()
    });
    assert!(labels.iter().all(|(_, l)| l.starts_with("single file: ")), "{labels:?}");
    // One side goes in while the other waits.
    assert!(labels.iter().any(|(_, l)| l.contains(" in, ") && !l.ends_with(" 0 waiting")), "{labels:?}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_fleet_above_the_threshold_is_one_batch_and_only_selected_uavs_have_their_own_entities() {
    let rrd = temp_rrd();
    // The small fleet has two UAVs, `a` and `b`: above a threshold of 1 it is logged as a batch.
    let server = start_batching_above(&format!("save={}", rrd.display()), 1).await;
    let addr = server.addr;
    let call = |method: &'static str, path: &'static str, body: Option<String>| async move {
        let (status, text) = support::raw(addr, method, path, body.as_deref(), &[]).await;
        (status, serde_json::from_str::<serde_json::Value>(&text).unwrap_or_default())
    };
    let put = |body: &str| call("PUT", "/api/rerun/selection", Some(body.to_string()));
    let (status, body) = put(r#"{"ids": ["b", "b"]}"#).await;
    assert_eq!((status, body["ids"].clone()), (200, serde_json::json!(["b"])), "{body}");
    // Bad selections are refused with the field named, and change nothing.
    let (status, body) = put(r#"{"ids": ["a", "nobody"]}"#).await;
    assert_eq!((status, body["error"]["field"].as_str()), (422, Some("ids")), "{body}");
    let many: Vec<String> = (0..=rerun_sink::MAX_SELECTED).map(|_| "a".to_string()).collect();
    let (status, body) = put(&serde_json::json!({ "ids": many }).to_string()).await;
    assert_eq!((status, body["error"]["field"].as_str()), (422, Some("ids")), "{body}");
    // The fields as an array (serde's derive would read `[[]]` as `{"ids": []}`): refused.
    let (status, body) = put("[[]]").await;
    assert_eq!((status, body["error"]["code"].as_str()), (422, Some("invalid_body")), "{body}");
    let (status, body) = call("GET", "/api/rerun/selection", None).await;
    assert_eq!((status, body["ids"].clone()), (200, serde_json::json!(["b"])), "{body}");
    tokio::time::sleep(Duration::from_millis(800)).await;
    let (_, metrics) = call("GET", "/api/metrics", None).await;
    let rerun = &metrics["rerun"];
    assert_eq!((rerun["active"].as_bool(), rerun["batched"].as_bool()), (Some(true), Some(true)), "{rerun}");
    assert!(rerun["logged"].as_u64() > Some(5) && rerun["errors"].as_u64() == Some(0), "{rerun}");
    let state = server.state.clone();
    let stats = server.stop().await;
    assert_eq!(stats.errors, 0);
    let last = state.engine.snapshots.borrow().clone();

    let rec = read_rrd(&rrd);
    std::fs::remove_file(&rrd).unwrap();
    // Every tick one batch of both positions, in snapshot order; the ids as labels, logged once.
    let fleet = rec.point_batches("world/fleet");
    assert!(fleet.len() >= 5 && fleet.iter().all(|(_, b)| b.len() == 2), "{fleet:?}");
    let (last_tick, last_batch) = fleet.last().unwrap();
    assert_eq!(*last_tick, i64::try_from(last.tick).unwrap());
    for (logged, u) in last_batch.iter().zip(&last.uavs) {
        assert!((f64::from(logged[0]) - u.p[0]).abs() < 1e-4 && (f64::from(logged[1]) - u.p[1]).abs() < 1e-4);
    }
    let labels = rec.label_batches("world/fleet");
    assert_eq!(labels.len(), 1, "labels only when the roster changes: {labels:?}");
    assert_eq!(labels[0].1, vec!["a".to_string(), "b".to_string()]);
    assert!(rec.chunks("world/fleet/velocity").iter().map(|c| c.num_rows()).sum::<usize>() >= 5);
    // Only the selected UAV has its own entities and series.
    assert!(rec.points("world/uavs/b").len() >= 5 && rec.scalars("slack/b").len() >= 5);
    assert!(rec.chunks("world/uavs/a").is_empty() && rec.chunks("slack/a").is_empty());
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_network_is_logged_with_its_cells_and_walls_and_no_centre_line() {
    let rrd = temp_rrd();
    let server = start(&format!("save={}", rrd.display())).await;
    tokio::time::sleep(Duration::from_millis(300)).await;
    let depot = support::shipped("depot.json");
    let network = serde_json::json!({"roads": depot["roads"], "junctions": depot["junctions"]});
    let (status, body) = support::raw(server.addr, "PUT", "/api/road", Some(&network.to_string()), &[]).await;
    assert_eq!(status, 200, "{body}");
    let view = server.state.engine.road.borrow().clone();
    tokio::time::sleep(Duration::from_millis(600)).await;
    let stats = server.stop().await;
    assert_eq!(stats.errors, 0);

    let rec = read_rrd(&rrd);
    std::fs::remove_file(&rrd).unwrap();
    let walls = rec.strips("world/road/walls");
    assert_eq!(walls.last().map(|w| &w.1), Some(&walls_as_strips(&view)), "the network's walls");
    // Each cell as its closed outline, exactly as the server drew it.
    let cells = rec.strips("world/road/cells");
    let outlines: Vec<Vec<[f32; 2]>> = view
        .cells
        .iter()
        .map(|c| c.polygon.iter().chain(c.polygon.first()).map(|p| [p[0] as f32, p[1] as f32]).collect())
        .collect();
    assert_eq!(outlines.len(), 31);
    assert_eq!(cells.last().map(|c| &c.1), Some(&outlines));
    let component = LineStrips2D::descriptor_labels().component;
    let labels = rec.rows("world/road/cells", component, |c| {
        c.iter_slices::<String>(component)
            .map(|s| s.iter().map(|l| l.to_string()).collect::<Vec<_>>())
            .collect::<Vec<_>>()
    });
    let last = &labels.last().expect("labelled cells").1;
    assert!(last.contains(&"trunk[0]".to_string()) && last.contains(&"fork".to_string()), "{last:?}");
    // The chain road's centre line is cleared: the network has none.
    let clear = Clear::descriptor_is_recursive().component;
    let cleared = rec
        .rows("world/road/centerline", clear, |c| c.iter_slices::<bool>(clear).map(|s| s.value(0)).collect());
    assert_eq!(cleared.len(), 1, "the centre line is cleared once: {cleared:?}");
}
