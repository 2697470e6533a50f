//! `airroads bench regions`: one deployment of `--regions` region servers in this process (each its
//! own fleet loop and its own Zenoh session, joined over loopback TCP like separate machines), the
//! `--uavs` UAVs of the trunk road of `bench scale` split among them by equal segment ranges. After
//! a warm-up it measures for `--seconds`: per region the Zenoh bytes per second it publishes, the
//! age of the foreign states its fleet used (p50/p99/max), the handovers, and its tick p50/p99.

use flights::say;

use crate::BenchArgs;
use airroads_server::serve::{ServeConfig, Server};
use anyhow::Context as _;
use fleet::trunk::trunk_scenario;
use regions::{self, RegionShared, ZenohOptions};
use std::process::ExitCode;
use std::sync::atomic::Ordering::Relaxed;
use std::time::{Duration, Instant};

/// Runs the benchmark.
pub fn main(args: &BenchArgs) -> ExitCode {
    crate::block_on(bench(args))
}

/// One region's server and what it shares with Zenoh.
struct Running {
    server: Server,
    shared: RegionShared,
    _link: regions::RegionLink,
}

fn free_endpoint(protocol: &str) -> anyhow::Result<String> {
    let port = std::net::TcpListener::bind("127.0.0.1:0")?.local_addr()?.port();
    Ok(format!("{protocol}/127.0.0.1:{port}"))
}

async fn bench(args: &BenchArgs) -> anyhow::Result<()> {
    let n = args.uavs_or(&[10_000])[0];
    let count = usize::try_from(args.regions)?;
    let mut scenario = trunk_scenario(n, 1).context("the trunk road")?;
    let segments = scenario.segments.len();
    anyhow::ensure!(segments >= count, "{segments} segments cannot make {count} regions");
    scenario.regions = Some(fleet::ScenarioRegions::Road(
        (0..count)
            .map(|k| roads::Region {
                name: format!("r{k}"),
                segments: [k * segments / count, (k + 1) * segments / count - 1],
            })
            .collect(),
    ));
    let scenario = scenario.validate().context("the trunk road's regions")?;
    let endpoints: Vec<String> = (0..count)
        .map(|_| free_endpoint(if args.zenoh_insecure { "tcp" } else { "tls" }))
        .collect::<anyhow::Result<_>>()?;
    let seconds = args.seconds.max(1.0);
    say!(
        "airroads bench regions: {n} UAVs on the trunk road ({segments} segments) over {count} regions, \
         one process, Zenoh over loopback {}, policy {}, {seconds} s measured after 3 s",
        if args.zenoh_insecure { "plain TCP (--zenoh-insecure)" } else { "TLS (mutual, access control)" },
        args.policy
    );
    // The deployment's certificates, as `airroads certs` makes them.
    let names: Vec<String> = (0..count).map(|k| format!("r{k}")).collect();
    let certs = std::env::temp_dir().join(format!("airroads-bench-regions-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&certs);
    let request = regions::certs::Request {
        regions: names.clone(),
        roles: vec!["primary".into()],
        hosts: vec![],
        days: 1,
    };
    regions::certs::issue(&certs, &request)?;
    let mut running = Vec::new();
    for k in 0..count {
        let name = format!("r{k}");
        let mut initial = scenario.clone();
        let road = initial.road.clone();
        initial.uavs.retain(|u| road.region_at(&u.start) == Some(name.as_str()));
        let shared = RegionShared::new(&name);
        let options = ZenohOptions {
            listen: vec![endpoints[k].clone()],
            connect: endpoints[..k].to_vec(),
            config_file: None,
            prefix: "bench".into(),
            transport: if args.zenoh_insecure {
                regions::secure::Transport::InsecureLoopback
            } else {
                let (cert, key) = regions::certs::server_files(&certs, &name, "primary");
                regions::secure::Transport::Tls(regions::secure::TlsFiles {
                    ca: certs.join(regions::certs::CA_CERT),
                    cert,
                    key,
                })
            },
            regions: names.clone(),
        };
        let session = regions::open(&options).await?;
        let keys = regions::tokens::RegionKeys::new(&options, &name);
        let claim = regions::tokens::claim(&session, &keys, &shared.failover, false).await?;
        let uavs = initial.uavs.len();
        let policies = policies::PolicyRegistry::standard(scenario.params.delta)?;
        policies.check(&args.policy).map_err(|e| anyhow::anyhow!("--policy {}: {e}", args.policy))?;
        let mut config =
            ServeConfig::new(fleet::FleetConfig::default(), policies, args.policy.clone(), initial);
        config.resume = false;
        config.max_uavs = n;
        config.region = Some(shared.clone());
        let server = Server::start(config)?;
        let neighbours = regions::neighbours_of(&scenario.road, &name).map_err(anyhow::Error::msg)?;
        let link = regions::start(session, &options, &shared, &neighbours, claim).await?;
        say!("  {name}: {uavs} UAVs, neighbours {}", neighbours.join(", "));
        running.push(Running { server, shared, _link: link });
    }
    tokio::time::sleep(Duration::from_secs(3)).await;
    let bytes_at_start: Vec<u64> = running.iter().map(|r| r.shared.published_bytes.load(Relaxed)).collect();
    let missed_at_start: Vec<u64> =
        running.iter().map(|r| r.server.state().engine.metrics.borrow().missed_ticks).collect();
    let started = Instant::now();
    tokio::time::sleep(Duration::from_secs_f64(seconds)).await;
    let elapsed = started.elapsed().as_secs_f64();
    say!(
        "{:>6} {:>6} {:>10} {:>9} {:>9} {:>9} {:>8} {:>8} {:>8} {:>8} {:>7} {:>8}",
        "region",
        "uavs",
        "MB/s out",
        "foreign",
        "age p50",
        "age p99",
        "age max",
        "handed",
        "tick p50",
        "tick p99",
        "missed",
        "refused"
    );
    let mut total = 0.0;
    for (k, r) in running.iter().enumerate() {
        let now = Instant::now();
        let report = r.shared.report(now);
        let metrics = r.server.state().engine.metrics.borrow().clone();
        let uavs = r.server.state().engine.snapshots.borrow().uavs.len();
        let rate = (r.shared.published_bytes.load(Relaxed) - bytes_at_start[k]) as f64 / elapsed / 1e6;
        total += rate;
        let ages = &report.foreign_age_ms;
        let ms = |v: Option<u64>| v.map_or("-".into(), |x| format!("{x} ms"));
        say!(
            "{:>6} {:>6} {:>10.2} {:>9} {:>9} {:>9} {:>8} {:>8} {:>8.1} {:>8.1} {:>7} {:>8}",
            r.shared.name,
            uavs,
            rate,
            report.table.foreign_uavs,
            ms(ages.p50.map(|x| x as u64)),
            ms(ages.p99.map(|x| x as u64)),
            ms(ages.max),
            report.handover.adopted,
            metrics.tick.p50_us / 1e3,
            metrics.tick.p99_us / 1e3,
            metrics.missed_ticks - missed_at_start[k],
            report.table.refused,
        );
        if report.table.refused > 0 {
            let refused = serde_json::to_string(report.peer_refused.report()).unwrap_or_default();
            say!("  {} refused its neighbours' messages: {refused}", r.shared.name);
        }
    }
    say!("all regions: {total:.2} MB/s of state messages published ({elapsed:.1} s measured)");
    say!("age: of every foreign state each tick gave the fleet, on the receiver's clock (since the start)");
    say!("refused: neighbours' state messages this region refused (undecodable or failing its checks)");
    for r in running {
        r.server.shutdown().await;
    }
    let _ = std::fs::remove_dir_all(&certs);
    Ok(())
}
