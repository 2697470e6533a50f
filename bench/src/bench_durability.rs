//! `airroads bench durability`: how many changes per second the server acknowledges when each is
//! on disk before its answer, with 1 to N concurrent clients, against a database in a temporary
//! directory (fsync) and in memory (`--ephemeral`, the same code without the disk); plus the store
//! alone: one fsynced transaction per change against one per batch of 64 (group commit).

use flights::say;

use crate::BenchArgs;
use airroads_server::serve::{ServeConfig, Server};
use api::client;
use engine::persist;
use engine::store::{Store, Write};
use flights::load_scenario;
use std::net::SocketAddr;
use std::process::ExitCode;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering::Relaxed};
use std::time::{Duration, Instant};

/// Runs the subcommand.
pub fn main(args: &BenchArgs) -> ExitCode {
    crate::block_on(bench(args))
}

struct Row {
    storage: &'static str,
    clients: usize,
    acknowledged: usize,
    per_second: f64,
    commits: u64,
    p50_ms: f64,
    p99_ms: f64,
}

async fn bench(args: &BenchArgs) -> anyhow::Result<()> {
    let seconds = Duration::from_secs_f64(args.seconds.max(1.0));
    let dir = std::env::temp_dir().join(format!("airroads-bench-durability-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    say!(
        "airroads bench durability: PUT /api/uavs/{{id}}/goal, {} s per row, data in {}",
        seconds.as_secs_f64(),
        dir.display()
    );
    store_alone(&dir.join("store"))?;
    let mut rows = Vec::new();
    for (storage, data_dir) in [("fsync", Some(dir.join("server"))), ("memory", None)] {
        for clients in [1, 8, 64] {
            rows.push(serve_and_change(args, storage, data_dir.clone(), clients, seconds).await?);
        }
    }
    say!(
        "{:<8} {:>8} {:>13} {:>12} {:>9} {:>14} {:>10} {:>10}",
        "storage",
        "clients",
        "acknowledged",
        "changes/s",
        "commits",
        "changes/commit",
        "p50 ms",
        "p99 ms"
    );
    for r in &rows {
        let per_commit = r.acknowledged as f64 / (r.commits.max(1)) as f64;
        say!(
            "{:<8} {:>8} {:>13} {:>12.0} {:>9} {:>14.1} {:>10.2} {:>10.2}",
            r.storage,
            r.clients,
            r.acknowledged,
            r.per_second,
            r.commits,
            per_commit,
            r.p50_ms,
            r.p99_ms
        );
    }
    let _ = std::fs::remove_dir_all(&dir);
    Ok(())
}

/// The store alone: fsynced commits of one change each, then of 64 changes each.
fn store_alone(dir: &std::path::Path) -> anyhow::Result<()> {
    let mut store = Store::open(dir)?;
    let uav = |i: usize| persist::SavedUav {
        id: format!("u{}", i % 1000),
        policy: "pd".into(),
        position: [1.0, 2.0],
        goal: Some([i as f64, 0.0]),
        link: None,
    };
    for batch in [1usize, 64] {
        let started = Instant::now();
        let mut changes = 0;
        while started.elapsed() < Duration::from_secs(2) {
            let writes: Vec<Write> = (0..batch).map(|k| Write::Uav(uav(changes + k))).collect();
            store.commit(&writes)?;
            changes += batch;
        }
        let s = started.elapsed().as_secs_f64();
        say!(
            "store alone, {batch:>2} change(s) per commit: {:>8.0} changes/s, {:>7.0} commits/s",
            changes as f64 / s,
            (changes / batch) as f64 / s
        );
    }
    Ok(())
}

async fn serve_and_change(
    args: &BenchArgs,
    storage: &'static str,
    data_dir: Option<std::path::PathBuf>,
    clients: usize,
    seconds: Duration,
) -> anyhow::Result<Row> {
    let initial = match &args.scenario {
        Some(path) => load_scenario(path).map_err(anyhow::Error::msg)?,
        None => airroads_server::serve::demo_scenario()?,
    };
    let policies = policies::PolicyRegistry::standard(initial.params.delta)?;
    let mut config = ServeConfig::new(fleet::FleetConfig::default(), policies, "pd".into(), initial);
    config.resume = false;
    if let Some(dir) = &data_dir {
        let _ = std::fs::remove_dir_all(dir);
    }
    config.data_dir = data_dir;
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await?;
    let addr = listener.local_addr()?;
    let server = Server::start(config)?;
    let state = server.state().clone();
    let ids: Vec<String> = state.engine.snapshots.borrow().uavs.iter().map(|u| u.id.to_string()).collect();
    let goals: Vec<Option<[f64; 2]>> = state.engine.snapshots.borrow().uavs.iter().map(|u| u.goal).collect();
    let (stop, stopped) = tokio::sync::oneshot::channel::<()>();
    let http = tokio::spawn(airroads_server::serve::serve(listener, server, async move {
        let _ = stopped.await;
    }));
    tokio::time::sleep(Duration::from_millis(500)).await;
    let commits_before = state.engine.storage.commits.load(Relaxed);
    let running = Arc::new(AtomicBool::new(true));
    let mut workers = Vec::new();
    for w in 0..clients {
        let k = w % ids.len();
        let (id, goal) = (ids[k].clone(), goals[k].unwrap_or([0.0, 0.0]));
        workers.push(tokio::spawn(change_loop(addr, id, goal, running.clone())));
    }
    let started = Instant::now();
    tokio::time::sleep(seconds).await;
    running.store(false, Relaxed);
    let mut latencies = Vec::new();
    for w in workers {
        latencies.extend(w.await?);
    }
    let elapsed = started.elapsed().as_secs_f64();
    let commits = state.engine.storage.commits.load(Relaxed) - commits_before;
    let _ = stop.send(());
    http.await??;
    let stats = engine::stats::percentiles(&mut latencies);
    Ok(Row {
        storage,
        clients,
        acknowledged: latencies.len(),
        per_second: latencies.len() as f64 / elapsed,
        commits,
        p50_ms: stats.p50_us,
        p99_ms: stats.p99_us,
    })
}

/// Puts UAV `id`'s goal back as it is, again and again; returns the latencies (ms) of the 200s.
async fn change_loop(addr: SocketAddr, id: String, goal: [f64; 2], running: Arc<AtomicBool>) -> Vec<f64> {
    let (path, body) = (format!("/api/uavs/{id}/goal"), serde_json::json!({ "goal": goal }).to_string());
    let mut latencies = Vec::new();
    while running.load(Relaxed) {
        let started = Instant::now();
        if let Ok((200, _)) = client::request(addr, "PUT", &path, Some(&body), &[]).await {
            latencies.push(started.elapsed().as_secs_f64() * 1e3);
        }
    }
    latencies
}
