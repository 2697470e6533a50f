//! `cfsim`: serve N simulated Crazyflies over UDP on consecutive ports (19850 and up by
//! default), so a CRTP client (`udp://127.0.0.1:19850`, ...) can fly them; or, with
//! `--firmware`, be the physics of N real firmware processes (the SITL `cf2`) and relay their
//! clients.

use std::io::Write;
use std::net::{IpAddr, SocketAddr};
use std::process::ExitCode;
use std::time::Duration;

use cfsim::sitl::firmware::{FirmwareProcesses, StartOptions};
use cfsim::sitl::{SitlConfig, SitlHandle};
use cfsim::{Faults, SimConfig, SimCrazyflie, SimHandle};

const USAGE: &str = "\
usage: cfsim [options]
  -n, --count N          number of Crazyflies (default 1)
      --host IP          address to bind (default 127.0.0.1)
      --base-port PORT   port of the first Crazyflie (default 19850)
      --positions LIST   initial positions 'x,y;x,y;...' in metres (z = 0);
                         default: a row along x, --spacing apart
      --spacing M        spacing of the default row (default 0.5)
      --max-accel A      acceleration bound in m/s^2 (default 4)
      --loss P           packet loss probability in each direction (default 0)
      --latency-ms MS    added latency in each direction (default 0)
      --seed S           PRNG seed for packet loss (default: fixed)
      --require-arming   wait for an arming request before the motors may run
                         (default: arm automatically, like a Crazyflie 2.1)
  -h, --help             this help

usage: cfsim --firmware [options]
  The physics of the real Crazyflie firmware: run one `cf2 PORT` (the firmware's SITL
  build) per drone, PORT = firmware port; clients connect to udp://HOST:(base port + N).
  -n, --count N                 number of drones (default 1)
      --host IP                 address to bind (default 127.0.0.1)
      --firmware-base-port PORT firmware port of drone 0 (default 19950)
      --base-port PORT          client port of drone 0 (default 19850)
      --positions LIST          start positions 'x,y;x,y;...' in metres (z = 0);
                                default: a row along x, --spacing apart
      --spacing M               spacing of the default row (default 0.5)
      --pose-hz H               external pose sent to the firmware (default 200; 0: none,
                                when the client sends the pose itself)
      --truth-dir DIR           ground truth CSV at 100 Hz per drone: DIR/truthN.csv
      --noise                   IMU noise (about a BMI088's)
      --seed S                  PRNG seed of noise and loss (default: fixed)
      --answer-null             answer null packets (0xFF) like a radio acknowledgement
                                (default: forwarded only, like the real firmware)
      --loss P                  drop this fraction of client<->firmware datagrams
      --wind FX,FY,FZ           constant wind force in newtons (world frame, z up)
      --pose-gap START,LENGTH   no pose from START s after the start, for LENGTH s
      --cf2 PATH                also start the firmware: one `PATH PORT` per drone, restarted
                                while it stalls at start (its console: RUNDIR/fwN.out)
      --run-dir DIR             the firmware's working folder (default: a temporary one)";

/// Command-line errors.
#[derive(Debug, thiserror::Error)]
enum CliError {
    #[error("missing value for {0}")]
    Missing(String),
    #[error("bad value {value:?} for {flag}")]
    Bad { flag: String, value: String },
    #[error("unknown argument {0:?}")]
    Unknown(String),
    #[error("{count} Crazyflies but {given} positions")]
    Positions { count: usize, given: usize },
    #[error("cannot bind {addr}: {source}")]
    Bind { addr: SocketAddr, source: std::io::Error },
    #[error("{0} is not an option of --firmware")]
    NotInFirmwareMode(String),
    #[error("{0}")]
    Sitl(#[from] cfsim::sitl::SitlError),
}

struct Args {
    count: usize,
    host: IpAddr,
    base_port: u16,
    positions: Option<Vec<[f64; 3]>>,
    spacing: f64,
    config: SimConfig,
}

fn parse_value<T: std::str::FromStr>(flag: &str, value: Option<String>) -> Result<T, CliError> {
    let value = value.ok_or_else(|| CliError::Missing(flag.to_owned()))?;
    value.parse().map_err(|_| CliError::Bad { flag: flag.to_owned(), value })
}

fn parse_positions(flag: &str, text: &str) -> Result<Vec<[f64; 3]>, CliError> {
    let bad = || CliError::Bad { flag: flag.to_owned(), value: text.to_owned() };
    text.split(';')
        .filter(|s| !s.trim().is_empty())
        .map(|item| {
            let v: Vec<f64> =
                item.split(',').map(|c| c.trim().parse().map_err(|_| bad())).collect::<Result<_, _>>()?;
            match v[..] {
                [x, y] => Ok([x, y, 0.0]),
                [x, y, z] => Ok([x, y, z]),
                _ => Err(bad()),
            }
        })
        .collect()
}

fn parse_args(mut it: impl Iterator<Item = String>) -> Result<Option<Args>, CliError> {
    let mut args = Args {
        count: 1,
        host: IpAddr::from([127, 0, 0, 1]),
        base_port: 19850,
        positions: None,
        spacing: 0.5,
        config: SimConfig::default(),
    };
    while let Some(flag) = it.next() {
        match flag.as_str() {
            "-h" | "--help" => return Ok(None),
            "-n" | "--count" => args.count = parse_value(&flag, it.next())?,
            "--host" => args.host = parse_value(&flag, it.next())?,
            "--base-port" => args.base_port = parse_value(&flag, it.next())?,
            "--positions" => {
                let text: String = parse_value(&flag, it.next())?;
                args.positions = Some(parse_positions(&flag, &text)?);
            }
            "--spacing" => args.spacing = parse_value(&flag, it.next())?,
            "--max-accel" => args.config.max_accel = parse_value(&flag, it.next())?,
            "--loss" => {
                let p: f64 = parse_value(&flag, it.next())?;
                args.config.faults = Faults { loss_up: p, loss_down: p, ..args.config.faults };
            }
            "--latency-ms" => {
                let d = Duration::from_millis(parse_value(&flag, it.next())?);
                args.config.faults = Faults { latency_up: d, latency_down: d, ..args.config.faults };
            }
            "--seed" => args.config.seed = parse_value(&flag, it.next())?,
            "--require-arming" => args.config.require_arming = true,
            _ => return Err(CliError::Unknown(flag)),
        }
    }
    if let Some(p) = &args.positions
        && p.len() != args.count
    {
        return Err(CliError::Positions { count: args.count, given: p.len() });
    }
    Ok(Some(args))
}

fn spawn_all(args: &Args) -> Result<Vec<SimHandle>, CliError> {
    (0..args.count)
        .map(|i| {
            let position = match &args.positions {
                Some(p) => p[i],
                None => [i as f64 * args.spacing, 0.0, 0.0],
            };
            let port = args.base_port.saturating_add(i as u16);
            let addr = SocketAddr::new(args.host, port);
            let config = SimConfig {
                initial_position: position,
                seed: args.config.seed.wrapping_add(i as u64),
                ..args.config.clone()
            };
            SimCrazyflie::spawn(addr, config).map_err(|source| CliError::Bind { addr, source })
        })
        .collect()
}

/// Flag that selects the firmware-physics mode.
const FIRMWARE_FLAG: &str = "--firmware";
/// How often the firmware mode reports how the physics keeps up.
const STATUS_EVERY: Duration = Duration::from_secs(10);

/// Options of the firmware-physics mode.
#[derive(Debug)]
struct FirmwareArgs {
    count: usize,
    spacing: f64,
    positions: Option<Vec<[f64; 3]>>,
    config: SitlConfig,
    /// The firmware binary to start for every drone, if any.
    cf2: Option<std::path::PathBuf>,
    /// The firmware's working folder.
    run_dir: Option<std::path::PathBuf>,
}

/// `a,b,...` as exactly `N` numbers.
fn parse_numbers<const N: usize>(flag: &str, value: Option<String>) -> Result<[f64; N], CliError> {
    let text: String = parse_value(flag, value)?;
    let bad = || CliError::Bad { flag: flag.to_owned(), value: text.clone() };
    let v: Vec<f64> =
        text.split(',').map(|c| c.trim().parse().map_err(|_| bad())).collect::<Result<_, _>>()?;
    v.try_into().map_err(|_| bad())
}

fn parse_firmware_args(mut it: impl Iterator<Item = String>) -> Result<Option<FirmwareArgs>, CliError> {
    let mut args = FirmwareArgs {
        count: 1,
        spacing: 0.5,
        positions: None,
        config: SitlConfig::default(),
        cf2: None,
        run_dir: None,
    };
    let c = &mut args.config;
    while let Some(flag) = it.next() {
        match flag.as_str() {
            "-h" | "--help" => return Ok(None),
            FIRMWARE_FLAG => {}
            "-n" | "--count" => args.count = parse_value(&flag, it.next())?,
            "--host" => c.host = parse_value(&flag, it.next())?,
            "--firmware-base-port" => c.firmware_base_port = parse_value(&flag, it.next())?,
            "--base-port" => c.client_base_port = parse_value(&flag, it.next())?,
            "--positions" => {
                let text: String = parse_value(&flag, it.next())?;
                args.positions = Some(parse_positions(&flag, &text)?);
            }
            "--spacing" => args.spacing = parse_value(&flag, it.next())?,
            "--pose-hz" => c.pose_hz = parse_value(&flag, it.next())?,
            "--truth-dir" => c.truth_dir = Some(parse_value::<String>(&flag, it.next())?.into()),
            "--noise" => c.noise = true,
            "--seed" => c.seed = parse_value(&flag, it.next())?,
            "--answer-null" => c.answer_null = true,
            "--loss" => c.faults.link_loss = parse_value(&flag, it.next())?,
            "--wind" => c.faults.wind_force = parse_numbers(&flag, it.next())?,
            "--pose-gap" => {
                let [start, length] = parse_numbers(&flag, it.next())?;
                let seconds = |x: f64| Duration::try_from_secs_f64(x).ok();
                let bad = || CliError::Bad { flag: flag.clone(), value: format!("{start},{length}") };
                let (from, len) = seconds(start).zip(seconds(length)).ok_or_else(bad)?;
                c.faults.pose_gap = Some((from, from.saturating_add(len)));
            }
            "--cf2" => args.cf2 = Some(parse_value::<String>(&flag, it.next())?.into()),
            "--run-dir" => args.run_dir = Some(parse_value::<String>(&flag, it.next())?.into()),
            "--max-accel" | "--latency-ms" | "--require-arming" => {
                return Err(CliError::NotInFirmwareMode(flag));
            }
            _ => return Err(CliError::Unknown(flag)),
        }
    }
    args.config.positions = match args.positions.take() {
        Some(p) if p.len() != args.count => {
            return Err(CliError::Positions { count: args.count, given: p.len() });
        }
        Some(p) => p,
        None => (0..args.count).map(|i| [i as f64 * args.spacing, 0.0, 0.0]).collect(),
    };
    Ok(Some(args))
}

/// Serve the physics of `args.count` firmware processes until Ctrl-C.
async fn run_firmware_physics(args: FirmwareArgs) -> ExitCode {
    let sitl = match SitlHandle::spawn(args.config.clone()) {
        Ok(sitl) => sitl,
        Err(e) => {
            let _ = writeln!(std::io::stderr(), "cfsim: {}", CliError::from(e));
            return ExitCode::FAILURE;
        }
    };
    let mut out = std::io::stdout();
    for (i, p) in args.config.positions.iter().enumerate() {
        let (Some(fw), Some(uri)) = (sitl.firmware_addr(i), sitl.uri(i)) else { continue };
        let _ = writeln!(
            out,
            "drone {i}: cf2 {}, client {uri}, at ({:.2}, {:.2}, {:.2})",
            fw.port(),
            p[0],
            p[1],
            p[2]
        );
    }
    // Kept to the end: dropping it kills the firmware processes.
    let _firmware = match &args.cf2 {
        Some(cf2) => {
            let run_dir = args.run_dir.clone().unwrap_or_else(|| {
                std::env::temp_dir().join(format!("cfsim-firmware-{}", std::process::id()))
            });
            let started = std::fs::create_dir_all(&run_dir)
                .map_err(|e| format!("{}: {e}", run_dir.display()))
                .and_then(|()| {
                    let options = StartOptions::in_dir(&run_dir);
                    tokio::task::block_in_place(|| FirmwareProcesses::start(cf2, &sitl, &options))
                        .map_err(|e| e.to_string())
                });
            match started {
                Ok(processes) => {
                    let _ =
                        writeln!(out, "firmware: {} running, consoles in {}", sitl.len(), run_dir.display());
                    Some(processes)
                }
                Err(e) => {
                    let _ = writeln!(std::io::stderr(), "cfsim: {e}");
                    return ExitCode::FAILURE;
                }
            }
        }
        None => None,
    };
    let _ = writeln!(out, "physics of {} drone(s) for the firmware; Ctrl-C to stop", sitl.len());
    let ctrl_c = tokio::signal::ctrl_c();
    tokio::pin!(ctrl_c);
    let motor_packets = |sitl: &SitlHandle| -> Vec<u64> {
        (0..sitl.len()).map(|i| sitl.stats(i).map_or(0, |d| d.motor_packets)).collect()
    };
    let mut before = (std::time::Instant::now(), motor_packets(&sitl));
    loop {
        tokio::select! {
            _ = &mut ctrl_c => break,
            () = tokio::time::sleep(STATUS_EVERY) => {
                let s = sitl.loop_stats();
                let up = (0..sitl.len()).filter(|&i| sitl.stats(i).is_some_and(|d| d.motor_packets_since_hello > 0)).count();
                let now = (std::time::Instant::now(), motor_packets(&sitl));
                let seconds = (now.0 - before.0).as_secs_f64().max(1e-9);
                let rates = now.1.iter().zip(&before.1).map(|(a, b)| a.saturating_sub(*b) as f64 / seconds);
                let (lo, hi) = rates.fold((f64::INFINITY, 0.0_f64), |(lo, hi), r| (lo.min(r), hi.max(r)));
                before = now;
                let _ = writeln!(
                    out,
                    "physics {:.1} Hz, load {:.1}%, longest tick {:.2} ms, {} resyncs; firmware running {up}/{}, \
                     motor packets {lo:.0}-{hi:.0}/s",
                    s.physics_rate_hz(), 100.0 * s.load(), s.longest_tick.as_secs_f64() * 1e3, s.resyncs, sitl.len()
                );
            }
        }
    }
    match sitl.shutdown() {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            let _ = writeln!(std::io::stderr(), "cfsim: {}", CliError::from(e));
            ExitCode::FAILURE
        }
    }
}

#[tokio::main]
async fn main() -> ExitCode {
    if std::env::args().any(|a| a == FIRMWARE_FLAG) {
        return match parse_firmware_args(std::env::args().skip(1)) {
            Ok(Some(args)) => run_firmware_physics(args).await,
            Ok(None) => {
                let _ = writeln!(std::io::stdout(), "{USAGE}");
                ExitCode::SUCCESS
            }
            Err(e) => {
                let _ = writeln!(std::io::stderr(), "cfsim: {e}\n{USAGE}");
                ExitCode::from(2)
            }
        };
    }
    let args = match parse_args(std::env::args().skip(1)) {
        Ok(Some(args)) => args,
        Ok(None) => {
            // Ignore a closed stdout (e.g. `cfsim --help | head`).
            let _ = writeln!(std::io::stdout(), "{USAGE}");
            return ExitCode::SUCCESS;
        }
        Err(e) => {
            let _ = writeln!(std::io::stderr(), "cfsim: {e}\n{USAGE}");
            return ExitCode::from(2);
        }
    };
    let sims = match spawn_all(&args) {
        Ok(sims) => sims,
        Err(e) => {
            let _ = writeln!(std::io::stderr(), "cfsim: {e}");
            return ExitCode::FAILURE;
        }
    };
    let mut out = std::io::stdout();
    for sim in &sims {
        let p = sim.truth().position;
        let _ = writeln!(out, "{} at ({:.2}, {:.2}, {:.2})", sim.uri(), p[0], p[1], p[2]);
    }
    let _ = writeln!(out, "serving {} simulated Crazyflie(s); Ctrl-C to stop", sims.len());
    let _ = tokio::signal::ctrl_c().await;
    for sim in sims {
        sim.shutdown().await;
    }
    ExitCode::SUCCESS
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(v: &[&str]) -> Result<Option<Args>, CliError> {
        parse_args(v.iter().map(|s| s.to_string()))
    }

    #[test]
    fn arguments() {
        let a =
            parse(&["-n", "2", "--positions", "1,2;3,4,0.5", "--loss", "0.1"]).ok().flatten().expect("valid");
        assert_eq!(a.count, 2);
        assert_eq!(a.positions, Some(vec![[1.0, 2.0, 0.0], [3.0, 4.0, 0.5]]));
        assert_eq!(a.config.faults.loss_down, 0.1);
        assert!(!a.config.require_arming);
        assert!(parse(&["--require-arming"]).ok().flatten().expect("valid").config.require_arming);
        assert!(matches!(parse(&["--help"]), Ok(None)));
        assert!(matches!(parse(&["-n", "2", "--positions", "1,2"]), Err(CliError::Positions { .. })));
        assert!(matches!(parse(&["--count"]), Err(CliError::Missing(_))));
        assert!(matches!(parse(&["--count", "x"]), Err(CliError::Bad { .. })));
        assert!(matches!(parse(&["--positions", "1"]), Err(CliError::Bad { .. })));
        assert!(matches!(parse(&["--bogus"]), Err(CliError::Unknown(_))));
        assert!(matches!(parse(&["--firmware"]), Err(CliError::Unknown(_))), "not an imitation flag");
    }

    fn parse_firmware(v: &[&str]) -> Result<Option<FirmwareArgs>, CliError> {
        parse_firmware_args(v.iter().map(|s| s.to_string()))
    }

    #[test]
    fn firmware_arguments() {
        let a = parse_firmware(&["--firmware", "-n", "3", "--spacing", "1"]).ok().flatten().expect("valid");
        assert_eq!(a.config.positions, vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0]]);
        assert_eq!(
            (a.config.firmware_base_port, a.config.client_base_port, a.config.pose_hz),
            (19950, 19850, 200.0)
        );
        assert!(!a.config.answer_null && !a.config.noise && a.config.truth_dir.is_none());
        let a = parse_firmware(&[
            "--firmware",
            "-n",
            "2",
            "--positions",
            "1,2;3,4",
            "--firmware-base-port",
            "29950",
            "--base-port",
            "29850",
            "--pose-hz",
            "0",
            "--truth-dir",
            "/tmp/t",
            "--noise",
            "--seed",
            "9",
            "--answer-null",
            "--loss",
            "0.2",
            "--wind",
            "0.01,0,-0.02",
            "--pose-gap",
            "5,1.5",
        ])
        .ok()
        .flatten()
        .expect("valid");
        let c = &a.config;
        assert_eq!(c.positions, vec![[1.0, 2.0, 0.0], [3.0, 4.0, 0.0]]);
        assert_eq!((c.firmware_base_port, c.client_base_port, c.pose_hz, c.seed), (29950, 29850, 0.0, 9));
        assert_eq!(c.truth_dir.as_deref(), Some(std::path::Path::new("/tmp/t")));
        assert!(c.noise && c.answer_null);
        assert_eq!(c.faults.link_loss, 0.2);
        assert_eq!(c.faults.wind_force, [0.01, 0.0, -0.02]);
        assert_eq!(c.faults.pose_gap, Some((Duration::from_secs(5), Duration::from_millis(6500))));
        assert!(matches!(parse_firmware(&["--firmware", "--help"]), Ok(None)));
        assert!(matches!(parse_firmware(&["--wind", "1,2"]), Err(CliError::Bad { .. })));
        assert!(matches!(parse_firmware(&["--pose-gap", "-1,2"]), Err(CliError::Bad { .. })));
        assert!(matches!(parse_firmware(&["--require-arming"]), Err(CliError::NotInFirmwareMode(_))));
        assert!(matches!(
            parse_firmware(&["-n", "2", "--positions", "1,2"]),
            Err(CliError::Positions { .. })
        ));
        assert!(matches!(parse_firmware(&["--bogus"]), Err(CliError::Unknown(_))));
    }
}
