//! `cfsim`: serve N simulated Crazyflies over UDP on consecutive ports (19850 and up by
//! default), so a CRTP client (`udp://127.0.0.1:19850`, ...) can fly them.

use std::io::Write;
use std::net::{IpAddr, SocketAddr};
use std::process::ExitCode;
use std::time::Duration;

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
  -h, --help             this help";

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

#[tokio::main]
async fn main() -> ExitCode {
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
    }
}
