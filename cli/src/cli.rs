//! Command-line interface (a public contract: flags and exit codes are relied on by scripts).

use clap::{Args, Parser, Subcommand};
use std::path::PathBuf;

/// airroads: real-time ground control for UAV fleets flying inside air roads.
#[derive(Debug, Parser)]
#[command(name = "airroads", version, about)]
pub struct Cli {
    /// What to do.
    #[command(subcommand)]
    pub command: Command,
}

/// Subcommands.
#[derive(Debug, Subcommand)]
// Parsed once at start and moved into its subcommand: the size of the largest flags is no cost.
#[allow(clippy::large_enum_variant)]
pub enum Command {
    /// Run a scenario headless until every UAV arrived or t_max; exit 0 when safe and all arrived,
    /// 1 otherwise, 2 for invalid input.
    Run(RunArgs),
    /// Generate and run random valid scenarios; report every safety violation with its seed.
    Stress(StressArgs),
    /// Measure the filter and print a table.
    Bench(bench::BenchArgs),
    /// Run the ground-control server: the 20 Hz fleet loop, the REST API, the WebSocket stream.
    /// With no arguments it resumes the saved fleet or flies the embedded demo.
    Serve(ServeArgs),
    /// Ask a running server for `/healthz`; exit 0 when it answers 200 (for container health checks).
    Health(HealthArgs),
    /// Make the region network's certificate authority and one certificate per region and role
    /// (for `serve --region ... --zenoh-ca/--zenoh-cert/--zenoh-key`); exit 2 for invalid input.
    Certs(CertsArgs),
    /// Fly the paper's reference trajectories with a tracking policy and the PD baselines; print
    /// tracking RMSE and inference time.
    Track(TrackArgs),
}

/// `airroads track`.
#[derive(Debug, Args)]
pub struct TrackArgs {
    /// Which reference: ellipse, figure8, rectangle or all.
    #[arg(default_value = "all", value_parser = ["ellipse", "figure8", "rectangle", "all"])]
    pub trajectory: String,
    /// The learned policy to measure (`rl`, or a name given with --model).
    #[arg(long, default_value = "rl")]
    pub policy: String,
    /// Load an extra ONNX policy under a name (repeatable).
    #[arg(long = "model", value_name = "NAME=FILE")]
    pub models: Vec<String>,
    /// Print a JSON list of rows instead of the table.
    #[arg(long)]
    pub json: bool,
}

impl TrackArgs {
    /// The policies available to `track` (checked to contain `--policy`).
    pub fn policies(&self) -> Result<policies::PolicyRegistry, String> {
        load_policies(&self.policy, &self.models, 5.0)
    }
}

/// Options shared by `run` and `stress`.
#[derive(Debug, Clone, Args)]
pub struct FlightArgs {
    /// Which walls each UAV enforces.
    #[arg(long, default_value = "walls", value_parser = ["walls", "halfplanes", "paper"])]
    pub road_rule: String,
    /// How temporary targets are chosen.
    #[arg(long, default_value = "traffic", value_parser = ["traffic", "route", "lanes", "alg1"])]
    pub nav: String,
    /// Policy flown by every UAV: `rl` (the shipped RL model, default), `pd` (the PD baseline), or a
    /// name given with `--model NAME=FILE.onnx`.
    #[arg(long, default_value = "rl")]
    pub policy: String,
    /// Load an extra ONNX policy under a name (repeatable), e.g. `--model mine=policies/models/x.onnx`.
    #[arg(long = "model", value_name = "NAME=FILE")]
    pub models: Vec<String>,
    /// QP objective: `exact` (exact slack penalty, default) or `paper` (quadratic slack only).
    #[arg(long, default_value = "exact", value_parser = ["exact", "paper"])]
    pub objective: String,
    /// QP solver: `exact` (active set in R² with a KKT certificate, default) or `clarabel`.
    #[arg(long, default_value = "exact", value_parser = ["exact", "clarabel"])]
    pub solver: String,
    /// How pair rows are shared: `sequential` (default) or `split` (the paper's δ_k/(δ_k+δ_d) split).
    #[arg(long, default_value = "sequential", value_parser = ["sequential", "split"])]
    pub share: String,
    /// Slack weights: `urgency` (divided by the row's barrier value, default) or `fixed`
    /// (docs/safety.md §6).
    #[arg(long, default_value = "urgency", value_parser = ["urgency", "fixed"])]
    pub slack_weights: String,
}

/// `airroads serve`.
#[derive(Debug, Args)]
pub struct ServeArgs {
    /// Address to listen on. A non-loopback address needs a token.
    #[arg(long, default_value = "127.0.0.1:8080")]
    pub addr: std::net::SocketAddr,
    /// Bearer token required for changes (default: $AIRROADS_TOKEN; none: changes are open).
    #[arg(long)]
    pub token: Option<String>,
    /// Where the road, fleet and goals are saved and resumed from
    /// (default: $XDG_DATA_HOME/airroads or ~/.local/share/airroads).
    #[arg(long)]
    pub data_dir: Option<PathBuf>,
    /// Save nothing and resume nothing.
    #[arg(long, conflicts_with = "data_dir")]
    pub ephemeral: bool,
    /// Start from this scenario file instead of the saved state or the embedded demo.
    #[arg(long)]
    pub scenario: Option<PathBuf>,
    /// Log to Rerun (0.36.x viewer): `off`, `connect` (the local viewer), `connect=ADDR` (host:port or
    /// rerun+http://host:port/proxy), `save=FILE.rrd`, or `serve` (a gRPC server on 127.0.0.1:9876).
    #[arg(long, default_value = "off", value_name = "MODE")]
    pub rerun: rerun_sink::RerunMode,
    /// Above this many UAVs, log the fleet to Rerun as one batch per tick (`world/fleet`) and give
    /// only the UAVs selected with PUT /api/rerun/selection their own entities.
    #[arg(long, value_name = "N", default_value_t = rerun_sink::BATCH_ABOVE_UAVS)]
    pub rerun_batch_above: usize,
    /// Fly the first N UAVs of the scenario as simulated Crazyflies (cfsim, in this process) through
    /// the real CRTP path over UDP, on ports from --cfsim-port up. Starts from the scenario, like
    /// --scenario, not from the saved state.
    #[arg(long, value_name = "N", default_value_t = 0)]
    pub cfsim: usize,
    /// First UDP port of the --cfsim Crazyflies (0: any free ports).
    #[arg(long, default_value_t = 19850, value_name = "PORT")]
    pub cfsim_port: u16,
    /// Receive motion-capture poses (`{"id", "t", "p": [x, y, z]}` per UDP datagram) on this address
    /// and forward each to its Crazyflie as an external position.
    #[arg(long, value_name = "ADDR")]
    pub mocap: Option<std::net::SocketAddr>,
    /// Accept motion-capture datagrams from this address (repeatable). Without it only loopback
    /// senders are accepted, and a non-loopback --mocap address is refused.
    #[arg(long = "mocap-allow", value_name = "IP")]
    pub mocap_allow: Vec<std::net::IpAddr>,
    /// Crazyflie flight altitude (m).
    #[arg(long, default_value_t = 1.0, value_name = "M")]
    pub altitude: f64,
    /// The firmware controller each Crazyflie is set to on connect (`stabilizer.controller`, read
    /// back): `mellinger` follows the full-state setpoints' velocity and acceleration; `pid` (the
    /// firmware's default) only their position; `keep` leaves the Crazyflie's own.
    #[arg(long = "cf-controller", value_name = "NAME", default_value = "mellinger",
          value_parser = ["mellinger", "pid", "keep"])]
    pub cf_controller: String,
    /// Most UAVs the fleet may have; adding more (or a larger scenario) is refused with 422.
    #[arg(long, value_name = "N", default_value_t = airroads_server::serve::DEFAULT_MAX_UAVS)]
    pub max_uavs: usize,
    /// Also accept this `Host` header (repeatable): `name` or `name:port`, e.g. a reverse proxy's.
    #[arg(long = "allow-host", value_name = "HOST")]
    pub allow_hosts: Vec<String>,
    /// Also accept Crazyflie links `udp://IP:PORT` to this non-loopback simulator host (repeatable).
    #[arg(long = "allow-link-host", value_name = "IP")]
    pub allow_link_hosts: Vec<std::net::IpAddr>,
    /// Also let pages of this origin make changes and open /ws (repeatable), e.g.
    /// `https://ops.example.com`.
    #[arg(long = "allow-origin", value_name = "ORIGIN")]
    pub allow_origins: Vec<String>,
    /// Fly only this region of the scenario's road (its `regions`) and share states with the
    /// neighbouring regions' servers over Zenoh (docs/regions.md). Needs --scenario.
    /// A server started while the region's owner is alive joins as its standby.
    #[arg(long, value_name = "NAME", requires = "scenario", group = "regional")]
    pub region: Option<String>,
    /// Be the hot standby of this region: mirror its owner over Zenoh and take over within 1 s
    /// when the owner is gone (docs/regions.md). Needs --scenario (for the road).
    #[arg(long = "standby-for", value_name = "NAME", requires = "scenario", group = "regional")]
    pub standby_for: Option<String>,
    /// Zenoh endpoint to listen on, e.g. `tls/0.0.0.0:7447` (repeatable; with --region or
    /// --standby-for).
    #[arg(long = "zenoh-listen", value_name = "ENDPOINT", requires = "regional")]
    pub zenoh_listen: Vec<String>,
    /// Zenoh endpoint to connect to, e.g. `tls/10.0.0.2:7447` (repeatable; with --region or
    /// --standby-for).
    #[arg(long = "zenoh-connect", value_name = "ENDPOINT", requires = "regional")]
    pub zenoh_connect: Vec<String>,
    /// Zenoh configuration file (JSON5, Zenoh's own format), applied before --zenoh-listen and
    /// --zenoh-connect.
    #[arg(long = "zenoh-config", value_name = "FILE", requires = "regional")]
    pub zenoh_config: Option<PathBuf>,
    /// First chunks of the Zenoh keys: states go to `PREFIX/region/NAME/state`.
    #[arg(long = "zenoh-prefix", value_name = "PREFIX", default_value = "airroads")]
    pub zenoh_prefix: String,
    /// The region network's certificate authority (`ca.pem` of `airroads certs`); with
    /// --zenoh-cert and --zenoh-key the region network is TLS with mutual authentication.
    #[arg(long = "zenoh-ca", value_name = "FILE", requires_all = ["zenoh_cert", "zenoh_key"])]
    pub zenoh_ca: Option<PathBuf>,
    /// This server's certificate, whose common name is its region (`NAME.ROLE.pem`).
    #[arg(long = "zenoh-cert", value_name = "FILE", requires_all = ["zenoh_ca", "zenoh_key"])]
    pub zenoh_cert: Option<PathBuf>,
    /// This server's private key (`NAME.ROLE.key`).
    #[arg(long = "zenoh-key", value_name = "FILE", requires_all = ["zenoh_ca", "zenoh_cert"])]
    pub zenoh_key: Option<PathBuf>,
    /// Join the region network over plain TCP without authentication: only on loopback endpoints,
    /// and any process on this host can then command the region (logged as a warning).
    #[arg(long = "zenoh-insecure", requires = "regional", conflicts_with_all = ["zenoh_ca", "zenoh_cert", "zenoh_key"])]
    pub zenoh_insecure: bool,
    /// Flight options (`--policy` is the policy of UAVs added without one).
    #[command(flatten)]
    pub flight: FlightArgs,
}

/// `airroads certs`.
#[derive(Debug, Args)]
pub struct CertsArgs {
    /// Directory of the certificates (created; an existing authority in it is reused and existing
    /// certificates are kept).
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,
    /// A region to certify (repeatable; the certificate's common name).
    #[arg(long = "region", value_name = "NAME")]
    pub regions: Vec<String>,
    /// Take the regions from this scenario's or road's `regions` (besides any --region).
    #[arg(long, value_name = "FILE.json")]
    pub road: Option<PathBuf>,
    /// The certificates per region, by role: `NAME.ROLE.pem` and `NAME.ROLE.key`.
    #[arg(long, value_delimiter = ',', default_value = "primary,standby")]
    pub roles: Vec<String>,
    /// A host name or IP address the certificates also name (repeatable).
    #[arg(long = "host", value_name = "NAME")]
    pub hosts: Vec<String>,
    /// How long each server certificate is valid (days, at most 3650).
    #[arg(long, default_value_t = 825)]
    pub days: u64,
}

/// `airroads health`.
#[derive(Debug, Args)]
pub struct HealthArgs {
    /// The health URL (plain http).
    #[arg(long, default_value = "http://127.0.0.1:8080/healthz")]
    pub url: String,
}

/// `airroads run`.
#[derive(Debug, Args)]
pub struct RunArgs {
    /// Scenario file (JSON).
    pub scenario: PathBuf,
    /// Write the metrics JSON here.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Write the trajectory (CSV, one row per UAV and tick) here.
    #[arg(long)]
    pub trajectory: Option<PathBuf>,
    /// Draw the road, every UAV's path and where each stalled or waited into this SVG file.
    #[arg(long)]
    pub plot: Option<PathBuf>,
    /// `sim`: the in-process simulator, as fast as it computes. `cfsim`: every UAV a simulated
    /// Crazyflie flown through the real CRTP path over UDP, in real time (take-off first, landing
    /// after); the metrics count from the moment all fly. `firmware`: every UAV a real Crazyflie
    /// firmware process (`--cf2`) on cfsim's physics of a Crazyflie 2.1, the margins measured on
    /// the physics' ground truth.
    #[arg(long, default_value = "sim", value_parser = ["sim", "cfsim", "firmware"])]
    pub link: String,
    /// The Crazyflie firmware's SITL build (`cf2`) that `--link firmware` runs, one process per UAV.
    #[arg(long, value_name = "PATH")]
    pub cf2: Option<PathBuf>,
    /// Flight options.
    #[command(flatten)]
    pub flight: FlightArgs,
}

/// `airroads stress`.
#[derive(Debug, Args)]
pub struct StressArgs {
    /// Number of random scenarios.
    #[arg(long, default_value_t = 100)]
    pub scenarios: u64,
    /// Seed of the first scenario (case i uses seed + i).
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Which random scenarios: `mixed` (bends, widths, hairpins, crowds), `bends` (one-way along
    /// tight bends), `bottleneck` (two-way through a narrow section), `headon` (two groups swapping
    /// ends through a part 0.5–5 m wide), `hairpin` (two-way through a U-turn), `crowd` (two
    /// dense blocks flying through each other), or a road network: `tee`, `wye`, `crossing`,
    /// `merge`, `roundabout`, `grid` (a street grid) or `ring` (a ring with spokes).
    #[arg(long, default_value = "mixed", value_parser = [
        "mixed", "bends", "bottleneck", "headon", "hairpin", "crowd",
        "tee", "wye", "crossing", "merge", "roundabout", "grid", "ring",
    ])]
    pub family: String,
    /// Save the scenario file of every violating case (stress-SEED.json) and of every case in which
    /// not every UAV arrived (stress-SEED-unfinished.json) into this directory.
    #[arg(long)]
    pub save_failing: Option<PathBuf>,
    /// Save the scenario file of every safe case in which not every UAV arrived into this directory
    /// (`--save-failing` saves those too, as stress-SEED-unfinished.json, unless this is given).
    #[arg(long)]
    pub save_unfinished: Option<PathBuf>,
    /// Worker threads (default: all cores; with `--link firmware`, flights at once, default 1).
    #[arg(long)]
    pub jobs: Option<usize>,
    /// `sim`: the in-process double integrator; `firmware`: random faulty flights of 2–3 real
    /// Crazyflie firmware processes on cfsim's physics on the lab road (needs `--cf2`), judged on
    /// ground truth (`--family` does not apply; `--save-failing` saves the scenarios of violating
    /// and unfinished cases, to fly again with `run --link firmware`).
    #[arg(long, default_value = "sim", value_parser = ["sim", "firmware"])]
    pub link: String,
    /// The Crazyflie firmware's SITL build (`cf2`) that `--link firmware` runs.
    #[arg(long, value_name = "PATH")]
    pub cf2: Option<PathBuf>,
    /// Flight options.
    #[command(flatten)]
    pub flight: FlightArgs,
}

impl FlightArgs {
    /// The policies these flags make available (`pd`, `rl` and every `--model`), checked to contain
    /// `--policy`; the error names the flag and the reason.
    pub fn policies(&self, delta: f64) -> Result<policies::PolicyRegistry, String> {
        load_policies(&self.policy, &self.models, delta)
    }

    /// The fleet configuration these flags select (params come from the scenario).
    pub fn fleet_config(&self) -> fleet::FleetConfig {
        // The value parsers above only admit valid names.
        let mut config = fleet::FleetConfig {
            road_rule: self.road_rule.parse().unwrap_or_default(),
            nav: self.nav.parse().unwrap_or_default(),
            share: self.share.parse().unwrap_or_default(),
            ..fleet::FleetConfig::default()
        };
        config.filter.objective = self.objective.parse().unwrap_or_default();
        config.filter.solver = self.solver.parse().unwrap_or_default();
        if self.slack_weights == "fixed" {
            config.filter.urgency_floor = 0.0;
        }
        config
    }
}

/// `pd`, `rl` and every `--model NAME=FILE.onnx`, checked to contain `policy`; errors name the flag.
fn load_policies(policy: &str, models: &[String], delta: f64) -> Result<policies::PolicyRegistry, String> {
    let mut registry =
        policies::PolicyRegistry::standard(delta).map_err(|e| format!("shipped model: {e}"))?;
    for spec in models {
        let Some((name, path)) = spec.split_once('=') else {
            return Err(format!("--model {spec}: expected NAME=FILE.onnx"));
        };
        registry.load(name, std::path::Path::new(path)).map_err(|e| format!("--model {name}: {e}"))?;
    }
    registry.check(policy).map_err(|e| format!("--policy: {e}"))?;
    Ok(registry)
}
