//! `airroads serve`: checks the flags, starts the server and runs it until Ctrl-C or SIGTERM.

use flights::say;

use crate::cli::ServeArgs;
use crate::run_cmd::EXIT_INVALID;
use airroads_server::serve::{self, ServeConfig, Server};
use anyhow::Context as _;
use flights::load_scenario_with;
use std::process::ExitCode;

/// Runs the subcommand: exit 0 after a clean shutdown, 1 on a runtime failure, 2 for invalid flags.
pub fn main(args: ServeArgs) -> ExitCode {
    init_logging();
    let config = match config(&args) {
        Ok(c) => c,
        Err(message) => {
            eprintln!("error: {message}");
            return ExitCode::from(EXIT_INVALID);
        }
    };
    let runtime = match tokio::runtime::Builder::new_multi_thread().enable_all().build() {
        Ok(r) => r,
        Err(e) => {
            eprintln!("error: cannot start the async runtime: {e}");
            return ExitCode::FAILURE;
        }
    };
    match runtime.block_on(run(&args, config)) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}

/// The server's own log: `tracing` to stderr, `info` and above unless `RUST_LOG` says otherwise.
fn init_logging() {
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("info"));
    let colours = std::io::IsTerminal::is_terminal(&std::io::stderr());
    let _ = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_ansi(colours)
        .with_writer(std::io::stderr)
        .try_init();
}

/// `airroads health`: exit 0 when `url` answers 200, 1 otherwise, 2 for an invalid URL.
pub fn health(url: &str) -> ExitCode {
    let Some((host, path)) = url.strip_prefix("http://").map(|r| r.split_once('/').unwrap_or((r, ""))) else {
        eprintln!("error: --url {url}: expected http://HOST:PORT/PATH");
        return ExitCode::from(EXIT_INVALID);
    };
    let check = async {
        let addr = tokio::net::lookup_host(host)
            .await?
            .next()
            .ok_or_else(|| anyhow::anyhow!("{host}: no address"))?;
        let path = format!("/{path}");
        let call = api::client::request(addr, "GET", &path, None, &[]);
        let (status, body) = tokio::time::timeout(std::time::Duration::from_secs(3), call).await??;
        anyhow::ensure!(status == 200, "{url}: HTTP {status}: {body}");
        anyhow::Ok(body)
    };
    let runtime = tokio::runtime::Builder::new_current_thread().enable_all().build();
    match runtime.map_err(anyhow::Error::from).and_then(|r| r.block_on(check)) {
        Ok(body) => {
            say!("{body}");
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}

/// The server configuration the flags select; the error names the flag or file.
fn config(args: &ServeArgs) -> Result<ServeConfig, String> {
    let from_env = args.token.is_none();
    let token = args.token.clone().or_else(|| std::env::var("AIRROADS_TOKEN").ok()).filter(|t| !t.is_empty());
    if let Some(t) = &token {
        let source = if from_env { "AIRROADS_TOKEN" } else { "--token" };
        api::auth::check_token(t).map_err(|reason| format!("{source}: {reason}"))?;
    }
    if token.is_none() && !args.addr.ip().is_loopback() {
        return Err(format!(
            "--addr {}: refusing to listen on a non-loopback address without a token (--token or AIRROADS_TOKEN)",
            args.addr
        ));
    }
    let link_rules = links::LinkRules { udp_hosts: args.allow_link_hosts.clone() };
    let mut initial = match &args.scenario {
        Some(path) => load_scenario_with(path, &link_rules)?,
        None => serve::demo_scenario().map_err(|e| format!("{e:#}"))?,
    };
    let region = match (&args.region, &args.standby_for) {
        (Some(name), _) => Some(keep_region(&mut initial, name, &args.zenoh_prefix)?),
        (None, Some(name)) => {
            let shared = keep_region(&mut initial, name, &args.zenoh_prefix)
                .map_err(|e| e.replace("--region", "--standby-for"))?;
            // The owner's UAVs come with the takeover.
            initial.uavs.clear();
            Some(shared)
        }
        (None, None) => None,
    };
    if region.is_some() {
        transport(args)?;
    }
    let policies = args.flight.policies(initial.params.delta)?;
    if args.cfsim > initial.uavs.len() {
        return Err(format!("--cfsim {}: the scenario has only {} UAVs", args.cfsim, initial.uavs.len()));
    }
    if !(args.altitude.is_finite() && (0.2..=10.0).contains(&args.altitude)) {
        return Err(format!("--altitude {}: must be between 0.2 and 10 m", args.altitude));
    }
    if let Some(at) = args.mocap
        && !at.ip().is_loopback()
        && args.mocap_allow.is_empty()
    {
        return Err(format!(
            "--mocap {at}: a non-loopback address needs --mocap-allow IP (the motion-capture senders)"
        ));
    }
    if args.max_uavs == 0 {
        return Err("--max-uavs: must be at least 1".into());
    }
    if initial.uavs.len() > args.max_uavs {
        return Err(format!("--max-uavs {}: the scenario has {} UAVs", args.max_uavs, initial.uavs.len()));
    }
    for origin in &args.allow_origins {
        let ok = ["http://", "https://"].iter().any(|s| origin.starts_with(s) && origin.len() > s.len())
            && !origin.ends_with('/');
        if !ok {
            return Err(format!(
                "--allow-origin {origin}: expected scheme://host[:port], e.g. https://ops.example.com"
            ));
        }
    }
    let data_dir = if args.ephemeral {
        None
    } else {
        Some(args.data_dir.clone().unwrap_or_else(engine::persist::default_dir))
    };
    // A data directory that cannot be written is refused now, not discovered at the first change.
    if let Some(dir) = &data_dir {
        serve::open_store(Some(dir)).map_err(|e| format!("--data-dir {}: {e}", dir.display()))?;
    }
    let open_files = api::listener::raise_open_files_limit();
    let mut config =
        ServeConfig::new(args.flight.fleet_config(), policies, args.flight.policy.clone(), initial);
    config.token = token;
    config.data_dir = data_dir;
    // Checked by clap's value parser: `keep` is the only name that is no controller.
    let controller = crazyflie::Controller::parse(&args.cf_controller);
    config.relay = crazyflie::RelayConfig { altitude: args.altitude, controller, ..Default::default() };
    // An explicit scenario (or --cfsim) starts over; the database is replaced when the server has
    // started, so a failed start loses nothing.
    config.resume = args.scenario.is_none() && args.cfsim == 0;
    config.max_uavs = args.max_uavs;
    config.allow_hosts = args.allow_hosts.clone();
    config.allow_origins = args.allow_origins.clone();
    config.limits = api::listener::Limits::fitted(open_files);
    config.max_stream_clients = api::ws::fitted_max_clients(open_files);
    config.link_rules = link_rules;
    config.region = region;
    Ok(config)
}

/// `--region NAME`: keeps the scenario's UAVs whose start lies in a segment of that region (the
/// others belong to other regions' servers) and returns the side the fleet loop shares with Zenoh.
fn keep_region(
    initial: &mut fleet::ValidScenario,
    name: &str,
    prefix: &str,
) -> Result<regions::RegionShared, String> {
    let road = &initial.road;
    regions::neighbours_of(road, name).map_err(|e| format!("--region {e}"))?;
    regions::check_prefix(prefix).map_err(|e| format!("--zenoh-prefix {e}"))?;
    initial.uavs.retain(|u| road.region_at(&u.start) == Some(name));
    Ok(regions::RegionShared::new(name))
}

async fn run(args: &ServeArgs, mut config: ServeConfig) -> anyhow::Result<()> {
    let (addr, rerun) = (args.addr, &args.rerun);
    let listener = tokio::net::TcpListener::bind(addr).await.with_context(|| format!("binding {addr}"))?;
    let local = listener.local_addr()?;
    let data_dir = config.data_dir.clone();
    // A region's ownership is settled before the loop starts: a server started while the region's
    // owner lives joins as its standby and flies nothing.
    let zenoh = match &config.region {
        Some(shared) => Some(claim_region(args, shared, &config.initial.road.layout()).await?),
        None => None,
    };
    if config.region.as_ref().is_some_and(|r| !r.failover.is_owner()) {
        config.initial.uavs.clear();
    }
    let sims = flights::cfsim_fleet::spawn(&mut config.initial, args.cfsim, args.cfsim_port)?;
    let server = Server::start(config)?;
    let mocap = match args.mocap {
        Some(at) => {
            let socket = tokio::net::UdpSocket::bind(at).await.with_context(|| format!("--mocap {at}"))?;
            let counters = server.state().mocap.clone();
            let senders = args.mocap_allow.clone();
            tokio::spawn(engine::mocap::ingest(socket, server.mocap().clone(), counters, senders));
            Some(at)
        }
        None => None,
    };
    say!("airroads serving on http://{local}");
    say!("  API        http://{local}/api (OpenAPI: /api/openapi.json), stream ws://{local}/ws");
    say!(
        "  fleet      {} UAVs from {}",
        server.state().engine.snapshots.borrow().uavs.len(),
        server.resumed_from()
    );
    match &data_dir {
        Some(dir) => say!("  data dir   {}", dir.display()),
        None => say!("  data dir   none (--ephemeral)"),
    }
    if !sims.is_empty() {
        let first = sims.first().map(|s| s.uri()).unwrap_or_default();
        say!("  cfsim      {} simulated Crazyflies over CRTP/UDP from {first}", sims.len());
    }
    if let Some(at) = mocap {
        say!("  mocap      udp://{at} ({{\"id\", \"t\", \"p\": [x, y, z]}} per datagram)");
    }
    say!(
        "  changes    {}",
        if server.state().token.is_some() { "need the bearer token" } else { "open (no token)" }
    );
    // Rerun is optional: a failure to start it is reported and the server runs without it.
    let sink = match rerun_sink::start(rerun, server.state().rerun_inputs(), args.rerun_batch_above) {
        Ok(sink) => {
            say!("  rerun      {rerun}");
            sink
        }
        Err(e) => {
            tracing::warn!("--rerun {rerun}: {e:#}; running without Rerun");
            None
        }
    };
    // Zenoh starts after the fleet loop: states are published from the first tick it sees.
    let zenoh = match (zenoh, &server.state().region) {
        (Some((session, claim)), Some(shared)) => {
            Some(start_region(args, session, claim, shared, server.state()).await?)
        }
        _ => None,
    };
    let served = serve::serve(listener, server, shutdown_signal()).await;
    drop(zenoh);
    if let Some(sink) = sink
        && let Ok(None) = tokio::task::spawn_blocking(move || sink.finish()).await
    {
        tracing::warn!("rerun: the log was not flushed within {:?}", rerun_sink::FINISH_TIMEOUT);
    }
    for sim in sims {
        sim.shutdown().await;
    }
    served
}

/// How this server joins the region network: QUIC with its certificate, or `--zenoh-insecure`.
fn transport(args: &ServeArgs) -> Result<regions::secure::Transport, String> {
    use regions::secure::{TlsFiles, Transport};
    let transport = match (&args.zenoh_ca, &args.zenoh_cert, &args.zenoh_key) {
        (Some(ca), Some(cert), Some(key)) => {
            Transport::Tls(TlsFiles { ca: ca.clone(), cert: cert.clone(), key: key.clone() })
        }
        _ if args.zenoh_insecure => Transport::InsecureLoopback,
        _ => {
            return Err("--region/--standby-for: the region network needs --zenoh-ca, --zenoh-cert and \
                        --zenoh-key (make them with `airroads certs`), or --zenoh-insecure on loopback"
                .into());
        }
    };
    let endpoints = args.zenoh_listen.iter().chain(&args.zenoh_connect);
    regions::secure::check_endpoints(&transport, endpoints)?;
    Ok(transport)
}

fn zenoh_options(args: &ServeArgs, road: &roads::AirspaceLayout) -> anyhow::Result<regions::ZenohOptions> {
    let transport = transport(args).map_err(anyhow::Error::msg)?;
    Ok(regions::ZenohOptions {
        listen: args.zenoh_listen.clone(),
        connect: args.zenoh_connect.clone(),
        config_file: args.zenoh_config.clone(),
        prefix: args.zenoh_prefix.clone(),
        transport,
        regions: road.region_names().into_iter().map(String::from).collect(),
    })
}

/// Opens the region's Zenoh session (`--region`, `--standby-for`) and settles who owns the region.
async fn claim_region(
    args: &ServeArgs,
    shared: &regions::RegionShared,
    road: &roads::AirspaceLayout,
) -> anyhow::Result<(zenoh::Session, regions::tokens::Claim)> {
    let options = zenoh_options(args, road)?;
    if options.transport == regions::secure::Transport::InsecureLoopback {
        tracing::warn!(
            "--zenoh-insecure: the region network is plain TCP without authentication; any process on \
             this host can publish states, hand over UAVs and command this region"
        );
    }
    let session = regions::open(&options).await?;
    let keys = regions::tokens::RegionKeys::new(&options, &shared.name);
    let standby = args.standby_for.is_some();
    let claim = regions::tokens::claim(&session, &keys, &shared.failover, standby).await?;
    Ok((session, claim))
}

/// Subscribes to the regions next to this one and starts publishing (`--region`, `--standby-for`).
async fn start_region(
    args: &ServeArgs,
    session: zenoh::Session,
    claim: regions::tokens::Claim,
    shared: &regions::RegionShared,
    app: &api::state::AppState,
) -> anyhow::Result<(regions::RegionLink, zenoh::query::Queryable<()>)> {
    let road = app.engine.road.borrow().layout.clone();
    let options = zenoh_options(args, &road)?;
    // Served already, so valid: built again for its regions only.
    let road = road.build(0.0).context("the served road")?;
    let neighbours = regions::neighbours_of(&road, &shared.name).map_err(anyhow::Error::msg)?;
    let link = regions::start(session.clone(), &options, shared, &neighbours, claim).await?;
    let federation = regions::federation::Federation::new(session.clone(), &options.prefix, &shared.name);
    let queryable = api::federate::answer_queries(&federation, &session, app.clone()).await?;
    let _ = shared.federation.set(federation);
    tokio::spawn(api::road_follow::follow(app.clone()));
    let key = regions::state_key(&options.prefix, &shared.name);
    let role = if shared.failover.is_owner() { "owner" } else { "standby" };
    say!(
        "  region     {} as {role} ({} UAVs), states on {key}",
        shared.name,
        app.engine.snapshots.borrow().uavs.len()
    );
    say!("  neighbours {}", if neighbours.is_empty() { "none".to_string() } else { neighbours.join(", ") });
    if args.region.is_some() && !shared.failover.is_owner() {
        say!("  standby    region {}'s owner is alive: this server joins as its standby", shared.name);
    }
    Ok((link, queryable))
}

/// Completes on Ctrl-C or SIGTERM.
async fn shutdown_signal() {
    let ctrl_c = async {
        if tokio::signal::ctrl_c().await.is_err() {
            std::future::pending::<()>().await;
        }
    };
    #[cfg(unix)]
    let term = async {
        match tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate()) {
            Ok(mut s) => {
                s.recv().await;
            }
            Err(_) => std::future::pending::<()>().await,
        }
    };
    #[cfg(not(unix))]
    let term = std::future::pending::<()>();
    tokio::select! {
        () = ctrl_c => {}
        () = term => {}
    }
    say!("airroads: shutting down");
}
