//! `airroads bench server`: the real server in-process on 127.0.0.1:0, measured in three phases of
//! one run: no clients; N WebSocket clients of which a tenth never read (stalled); the same plus
//! REST clients. Prints tick duration percentiles per phase and REST latency percentiles.

use flights::say;

use crate::BenchArgs;
use airroads_server::serve::{ServeConfig, Server};
use api::client;
use engine::stats::percentiles;
use flights::load_scenario;
use futures_util::StreamExt;
use std::net::SocketAddr;
use std::process::ExitCode;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering::Relaxed};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// Concurrent REST clients of the last phase.
const REST_WORKERS: usize = 8;

/// Runs the benchmark.
pub fn main(args: &BenchArgs) -> ExitCode {
    crate::block_on(bench(args))
}

/// What one phase measured.
struct Phase {
    name: String,
    ticks: Vec<f64>,
    frames: u64,
    /// Latencies of GET requests (ms).
    reads_ms: Vec<f64>,
    /// Latencies of PUT requests (ms): answered once the loop applied them between two ticks.
    changes_ms: Vec<f64>,
    rest_errors: u64,
}

async fn bench(args: &BenchArgs) -> anyhow::Result<()> {
    let initial = match (&args.scenario, args.crowd) {
        (Some(path), _) => load_scenario(path).map_err(anyhow::Error::msg)?,
        (None, Some(n)) => fleet::stress::crowd_scenario(usize::try_from(n)?).validate()?,
        (None, None) => airroads_server::serve::demo_scenario()?,
    };
    let policies = policies::PolicyRegistry::standard(initial.params.delta)?;
    let uavs = initial.uavs.len();
    let mut config =
        ServeConfig::new(fleet::FleetConfig::default(), policies, policies::SHIPPED_MODEL.into(), initial);
    config.resume = false;
    config.max_uavs = config.max_uavs.max(uavs);
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await?;
    let addr = listener.local_addr()?;
    let server = Server::start(config)?;
    let state = server.state().clone();
    let (stop, stopped) = tokio::sync::oneshot::channel::<()>();
    let http = tokio::spawn(airroads_server::serve::serve(listener, server, async move {
        let _ = stopped.await;
    }));
    let seconds = Duration::from_secs_f64(args.seconds.max(1.0));

    // Tick durations, collected by the bench from the metrics the loop publishes each tick.
    let durations = Arc::new(Mutex::new(Vec::<f64>::new()));
    let mut metrics = state.engine.metrics.clone();
    let sink = durations.clone();
    tokio::spawn(async move {
        let mut last = 0;
        while metrics.changed().await.is_ok() {
            let m = metrics.borrow_and_update().clone();
            if m.ticks != last {
                last = m.ticks;
                sink.lock().map(|mut v| v.push(m.last_tick_us)).ok();
            }
        }
    });
    let frames = Arc::new(AtomicU64::new(0));
    let take = |name: String, (reads_ms, changes_ms, rest_errors): (Vec<f64>, Vec<f64>, u64)| {
        let ticks = durations.lock().map(|mut v| std::mem::take(&mut *v)).unwrap_or_default();
        Phase { name, ticks, frames: frames.swap(0, Relaxed), reads_ms, changes_ms, rest_errors }
    };

    say!(
        "airroads bench server: {uavs} UAVs, {} s per phase, {} WebSocket clients",
        seconds.as_secs_f64(),
        args.clients
    );
    let mut phases = Vec::new();
    tokio::time::sleep(Duration::from_secs(1)).await;
    take(String::new(), Default::default());
    tokio::time::sleep(seconds).await;
    phases.push(take("no clients".into(), Default::default()));

    let stalled_count = args.clients / 10;
    let mut stalled = Vec::new();
    for k in 0..args.clients {
        let (socket, _) = tokio_tungstenite::connect_async(format!("ws://{addr}/ws")).await?;
        if k < stalled_count {
            stalled.push(socket);
        } else {
            let frames = frames.clone();
            tokio::spawn(async move {
                let mut socket = socket;
                while let Some(Ok(_)) = socket.next().await {
                    frames.fetch_add(1, Relaxed);
                }
            });
        }
    }
    take(String::new(), Default::default());
    tokio::time::sleep(seconds).await;
    let ws_name = format!("{} ws ({stalled_count} stalled)", args.clients);
    phases.push(take(ws_name.clone(), Default::default()));

    let running = Arc::new(AtomicBool::new(true));
    let ids: Vec<String> = state.engine.snapshots.borrow().uavs.iter().map(|u| u.id.to_string()).collect();
    let mut workers = Vec::new();
    for w in 0..REST_WORKERS {
        workers.push(tokio::spawn(rest_worker(addr, ids.clone(), w, running.clone())));
    }
    tokio::time::sleep(seconds).await;
    running.store(false, Relaxed);
    let mut rest = (Vec::new(), Vec::new(), 0);
    for worker in workers {
        let (reads, changes, errors) = worker.await?;
        rest.0.extend(reads);
        rest.1.extend(changes);
        rest.2 += errors;
    }
    phases.push(take(format!("{ws_name} + {REST_WORKERS} REST"), rest));
    let dropped = state.stream.clients_dropped.load(Relaxed);
    drop(stalled);
    let _ = stop.send(());
    http.await??;
    print_table(&mut phases, seconds.as_secs_f64());
    say!("stalled clients dropped by the server: {dropped} (a client is dropped once a send waits 2 s)");
    Ok(())
}

/// Loops over GET /api/state, GET /api/uavs, GET /api/uavs/{id} then PUT its goal (unchanged) and
/// GET /api/metrics, one connection per request. Returns read and change latencies (ms) and errors.
async fn rest_worker(
    addr: SocketAddr,
    ids: Vec<String>,
    worker: usize,
    running: Arc<AtomicBool>,
) -> (Vec<f64>, Vec<f64>, u64) {
    let (mut reads, mut changes, mut errors) = (Vec::new(), Vec::new(), 0);
    let mut k = worker;
    while running.load(Relaxed) {
        let path = match k % 4 {
            0 => "/api/state".to_string(),
            1 => "/api/uavs".to_string(),
            2 if !ids.is_empty() => format!("/api/uavs/{}", ids[k % ids.len()]),
            _ => "/api/metrics".to_string(),
        };
        k += 1;
        let started = Instant::now();
        let body = match client::request(addr, "GET", &path, None, &[]).await {
            Ok((200, body)) => {
                reads.push(started.elapsed().as_secs_f64() * 1e3);
                body
            }
            _ => {
                errors += 1;
                continue;
            }
        };
        // One UAV: put its goal back as it is (a real change request, applied between ticks).
        let goal = serde_json::from_str::<serde_json::Value>(&body).ok().map(|u| u["goal"].clone());
        let Some(goal) = goal.filter(|g| path.starts_with("/api/uavs/") && g.is_array()) else { continue };
        let body = serde_json::json!({ "goal": goal }).to_string();
        let started = Instant::now();
        match client::request(addr, "PUT", &format!("{path}/goal"), Some(&body), &[]).await {
            Ok((200, _)) => changes.push(started.elapsed().as_secs_f64() * 1e3),
            _ => errors += 1,
        }
    }
    (reads, changes, errors)
}

fn print_table(phases: &mut [Phase], seconds: f64) {
    say!(
        "{:<34} {:>6} {:>11} {:>11} {:>11} {:>9} {:>6} {:>10} {:>10} {:>6} {:>10} {:>10} {:>6}",
        "phase",
        "ticks",
        "tick p50µs",
        "tick p99µs",
        "tick maxµs",
        "frames/s",
        "GET n",
        "GET p50ms",
        "GET p99ms",
        "PUT n",
        "PUT p50ms",
        "PUT p99ms",
        "errors"
    );
    for p in phases {
        let t = percentiles(&mut p.ticks);
        let (n, r) = (p.reads_ms.len(), percentiles(&mut p.reads_ms));
        let (m, c) = (p.changes_ms.len(), percentiles(&mut p.changes_ms));
        // `percentiles` names its fields for µs; these samples are ms.
        let ms = |count: usize, x: f64| if count == 0 { "-".to_string() } else { format!("{x:.2}") };
        say!(
            "{:<34} {:>6} {:>11.1} {:>11.1} {:>11.1} {:>9.0} {:>6} {:>10} {:>10} {:>6} {:>10} {:>10} {:>6}",
            p.name,
            p.ticks.len(),
            t.p50_us,
            t.p99_us,
            t.max_us,
            p.frames as f64 / seconds,
            n,
            ms(n, r.p50_us),
            ms(n, r.p99_us),
            m,
            ms(m, c.p50_us),
            ms(m, c.p99_us),
            p.rest_errors
        );
    }
}
