//! `airroads bench server`: the real server in-process on 127.0.0.1:0, measured in three phases of
//! one run: no clients; N WebSocket clients of which a tenth never read (stalled); the same plus
//! REST clients. Prints tick duration percentiles per phase and REST latency percentiles.

use crate::cli::BenchArgs;
use crate::run_cmd::load_scenario;
use airroads::serve::stats::percentiles;
use airroads::serve::{ServeConfig, Server, client};
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
    let Some(runtime) = crate::bench::runtime() else { return ExitCode::FAILURE };
    match runtime.block_on(bench(args)) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}

/// What one phase measured.
struct Phase {
    name: String,
    ticks: Vec<f64>,
    frames: u64,
    rest_ms: Vec<f64>,
    rest_errors: u64,
}

async fn bench(args: &BenchArgs) -> anyhow::Result<()> {
    let initial = match &args.scenario {
        Some(path) => load_scenario(path).map_err(anyhow::Error::msg)?,
        None => airroads::serve::demo_scenario()?,
    };
    let policies = policies::PolicyRegistry::standard(initial.params.delta)?;
    let uavs = initial.uavs.len();
    let config = ServeConfig {
        fleet: fleet::FleetConfig::default(),
        policies,
        default_policy: policies::SHIPPED_MODEL.into(),
        token: None,
        data_dir: None,
        initial,
        relay: Default::default(),
        resume: false,
    };
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await?;
    let addr = listener.local_addr()?;
    let server = Server::start(config)?;
    let state = server.state().clone();
    let (stop, stopped) = tokio::sync::oneshot::channel::<()>();
    let http = tokio::spawn(airroads::serve::serve(listener, server, async move {
        let _ = stopped.await;
    }));
    let seconds = Duration::from_secs_f64(args.seconds.max(1.0));

    // Tick durations, collected by the bench from the metrics the loop publishes each tick.
    let durations = Arc::new(Mutex::new(Vec::<f64>::new()));
    let mut metrics = state.metrics.clone();
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
    let take = |name: String, rest_ms: Vec<f64>, rest_errors: u64| {
        let ticks = durations.lock().map(|mut v| std::mem::take(&mut *v)).unwrap_or_default();
        Phase { name, ticks, frames: frames.swap(0, Relaxed), rest_ms, rest_errors }
    };

    say!(
        "airroads bench server: {uavs} UAVs, {} s per phase, {} WebSocket clients",
        seconds.as_secs_f64(),
        args.clients
    );
    let mut phases = Vec::new();
    tokio::time::sleep(Duration::from_secs(1)).await;
    take(String::new(), Vec::new(), 0);
    tokio::time::sleep(seconds).await;
    phases.push(take("no clients".into(), Vec::new(), 0));

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
    take(String::new(), Vec::new(), 0);
    tokio::time::sleep(seconds).await;
    let ws_name = format!("{} ws ({stalled_count} stalled)", args.clients);
    phases.push(take(ws_name.clone(), Vec::new(), 0));

    let running = Arc::new(AtomicBool::new(true));
    let ids: Vec<String> = state.snapshots.borrow().uavs.iter().map(|u| u.id.clone()).collect();
    let mut workers = Vec::new();
    for w in 0..REST_WORKERS {
        workers.push(tokio::spawn(rest_worker(addr, ids.clone(), w, running.clone())));
    }
    tokio::time::sleep(seconds).await;
    running.store(false, Relaxed);
    let (mut rest_ms, mut rest_errors) = (Vec::new(), 0);
    for worker in workers {
        let (times, errors) = worker.await?;
        rest_ms.extend(times);
        rest_errors += errors;
    }
    phases.push(take(format!("{ws_name} + {REST_WORKERS} REST"), rest_ms, rest_errors));
    let dropped = state.stream.clients_dropped.load(Relaxed);
    drop(stalled);
    let _ = stop.send(());
    http.await??;
    print_table(&mut phases, seconds.as_secs_f64());
    say!("stalled clients dropped by the server: {dropped} (a client is dropped once a send waits 2 s)");
    Ok(())
}

/// Loops over GET /api/state, GET /api/uavs, PUT goal (unchanged goal) and GET /api/metrics.
async fn rest_worker(
    addr: SocketAddr,
    ids: Vec<String>,
    worker: usize,
    running: Arc<AtomicBool>,
) -> (Vec<f64>, u64) {
    let (mut times, mut errors) = (Vec::new(), 0);
    let mut k = worker;
    while running.load(Relaxed) {
        let started = Instant::now();
        let result = match k % 4 {
            0 => client::request(addr, "GET", "/api/state", None, &[]).await,
            1 => client::request(addr, "GET", "/api/uavs", None, &[]).await,
            2 if !ids.is_empty() => {
                let id = &ids[k % ids.len()];
                let path = format!("/api/uavs/{id}");
                match client::request(addr, "GET", &path, None, &[]).await {
                    Ok((200, body)) => {
                        let goal =
                            serde_json::from_str::<serde_json::Value>(&body).ok().map(|u| u["goal"].clone());
                        match goal.filter(|g| g.is_array()) {
                            Some(goal) => {
                                let body = serde_json::json!({ "goal": goal }).to_string();
                                client::request(addr, "PUT", &format!("{path}/goal"), Some(&body), &[]).await
                            }
                            None => Ok((200, String::new())),
                        }
                    }
                    other => other,
                }
            }
            _ => client::request(addr, "GET", "/api/metrics", None, &[]).await,
        };
        match result {
            Ok((status, _)) if status < 300 => times.push(started.elapsed().as_secs_f64() * 1e3),
            _ => errors += 1,
        }
        k += 1;
    }
    (times, errors)
}

fn print_table(phases: &mut [Phase], seconds: f64) {
    say!(
        "{:<34} {:>6} {:>11} {:>11} {:>11} {:>9} {:>7} {:>11} {:>11} {:>6}",
        "phase",
        "ticks",
        "tick p50µs",
        "tick p99µs",
        "tick maxµs",
        "frames/s",
        "REST n",
        "REST p50ms",
        "REST p99ms",
        "errors"
    );
    for p in phases {
        let t = percentiles(&mut p.ticks);
        let (n, r) = (p.rest_ms.len(), percentiles(&mut p.rest_ms));
        let rest = |x: f64| if n == 0 { "-".to_string() } else { format!("{x:.2}") };
        say!(
            "{:<34} {:>6} {:>11.1} {:>11.1} {:>11.1} {:>9.0} {:>7} {:>11} {:>11} {:>6}",
            p.name,
            p.ticks.len(),
            t.p50_us,
            t.p99_us,
            t.max_us,
            p.frames as f64 / seconds,
            n,
            rest(r.p50_us),
            rest(r.p99_us),
            p.rest_errors
        );
    }
}
