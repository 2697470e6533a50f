//! Simulated Crazyflies (cfsim) in a process of their own, so that they outlive the servers that
//! fly them: the test binary runs itself again as the host (an ignored test named `cfsim_host`
//! that calls [`host`], with `AIRROADS_CFSIM_HOST=x,y;x,y;...`), which prints each simulator's URI
//! and then, every 20 ms, what the simulators' own state says: the closest pair and how many fly.

use super::procs::{Proc, distance};
use std::io::{BufRead, BufReader};
use std::process::{Command, Stdio};
use std::sync::{Arc, Mutex};
use std::time::Duration;

/// The host's body: one simulator per position of `AIRROADS_CFSIM_HOST` (nothing without it);
/// prints `uri URI` per simulator, then `truth CLOSEST AIRBORNE` every 20 ms until killed.
pub fn host() {
    let Ok(positions) = std::env::var("AIRROADS_CFSIM_HOST") else { return };
    let runtime = tokio::runtime::Runtime::new().unwrap();
    runtime.block_on(async {
        let sims: Vec<cfsim::SimHandle> = positions
            .split(';')
            .map(|xy| {
                let (x, y) = xy.split_once(',').unwrap();
                let start = [x.parse().unwrap(), y.parse().unwrap(), 0.0];
                let config =
                    cfsim::SimConfig { initial_position: start, max_accel: 6.0, ..Default::default() };
                cfsim::SimCrazyflie::spawn("127.0.0.1:0".parse().unwrap(), config).unwrap()
            })
            .collect();
        for sim in &sims {
            println!("uri {}", sim.uri());
        }
        loop {
            tokio::time::sleep(Duration::from_millis(20)).await;
            let at: Vec<[f64; 3]> = sims.iter().map(|s| s.truth().position).collect();
            let airborne = at.iter().filter(|p| p[2] > 0.3).count();
            let mut closest = f64::INFINITY;
            for (i, a) in at.iter().enumerate() {
                for b in &at[i + 1..] {
                    closest = closest.min(distance([a[0], a[1]], [b[0], b[1]]));
                }
            }
            println!("truth {closest} {airborne}");
        }
    });
}

/// The simulators' latest `truth` line, and what was seen since `watching` was set.
#[derive(Debug, Default)]
pub struct Truth {
    /// How many fly now.
    pub airborne: usize,
    /// The closest pair seen while watching (m).
    pub closest_while_flying: f64,
    /// Set by the test once every Crazyflie is up.
    pub watching: bool,
    /// One came down while watching.
    pub fell: bool,
}

/// The host process (killed when dropped), its simulators' URIs and their truth.
pub struct Crazyflies {
    _host: Proc,
    /// One `udp://` URI per start.
    pub uris: Vec<String>,
    /// Updated by a thread reading the host's lines.
    pub truth: Arc<Mutex<Truth>>,
}

/// Starts the host with one simulator on the ground at each of `starts`.
pub fn start(starts: &[[f64; 2]]) -> Crazyflies {
    let n = starts.len();
    let list = starts.iter().map(|p| format!("{},{}", p[0], p[1])).collect::<Vec<_>>().join(";");
    let mut host = Command::new(std::env::current_exe().unwrap())
        .args(["--exact", "cfsim_host", "--ignored", "--nocapture", "--test-threads", "1"])
        .env("AIRROADS_CFSIM_HOST", list)
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let lines = BufReader::new(host.stdout.take().unwrap()).lines().map_while(Result::ok);
    let host = Proc(host);
    // The harness prints `test cfsim_host ... ` before the first line: find the words anywhere.
    let after = |line: &str, word: &str| line.find(word).map(|i| line[i + word.len()..].to_string());
    let truth = Arc::new(Mutex::new(Truth { closest_while_flying: f64::INFINITY, ..Default::default() }));
    let (kept, (uri_tx, uri_rx)) = (truth.clone(), std::sync::mpsc::channel());
    std::thread::spawn(move || {
        for line in lines {
            if let Some(uri) = after(&line, "uri ") {
                let _ = uri_tx.send(uri);
            }
            let Some(rest) = after(&line, "truth ") else { continue };
            let mut parts = rest.split(' ');
            let closest: f64 = parts.next().unwrap().parse().unwrap();
            let airborne: usize = parts.next().unwrap().parse().unwrap();
            let mut t = kept.lock().unwrap();
            if t.watching {
                t.closest_while_flying = t.closest_while_flying.min(closest);
                t.fell |= airborne < n;
            }
            t.airborne = airborne;
        }
    });
    let uris = (0..n)
        .map(|_| {
            uri_rx.recv_timeout(Duration::from_secs(30)).expect("the simulators' process prints its URIs")
        })
        .collect();
    Crazyflies { _host: host, uris, truth }
}
