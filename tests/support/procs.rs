//! Servers as separate processes (`airroads serve`), for the tests of regions over Zenoh: started on
//! 127.0.0.1:0, read over HTTP, killed when dropped.

use serde_json::Value;
use std::io::{BufRead, BufReader};
use std::net::SocketAddr;
use std::path::PathBuf;
use std::process::{Child, Command, Stdio};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// D_c of the scenarios' default parameters (m).
pub const D_C: f64 = 0.3;
/// How far below D_c two UAVs may be seen (m), beyond what the snapshots' skew explains.
pub const TOLERANCE_M: f64 = 0.02;
/// A snapshot may be this old when served (one tick, s).
pub const TICK_S: f64 = 0.05;

/// A fresh scratch directory `airroads-<kind>-<pid>-<name>` under the system's temporary one.
pub fn scratch(kind: &str, name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("airroads-{kind}-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// A child process, killed when dropped (a failing test leaves nothing running).
pub struct Proc(pub Child);

impl Proc {
    /// Its process id.
    pub fn pid(&self) -> String {
        self.0.id().to_string()
    }

    /// kill -9, and reaped.
    pub fn kill(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

impl Drop for Proc {
    fn drop(&mut self) {
        // A test that stopped it (SIGSTOP) and failed before SIGCONT: kill needs it running.
        let _ = Command::new("kill").args(["-CONT", &self.pid()]).stderr(Stdio::null()).status();
        self.kill();
    }
}

/// The lines a server printed on stdout (read by a thread).
pub type Banner = Arc<Mutex<Vec<String>>>;

/// The region network's certificates of this test process (made by `airroads certs`, the
/// authority once, each region's certificates when first asked for): the `--zenoh-ca`,
/// `--zenoh-cert` and `--zenoh-key` arguments of a server of `region` in `role`.
pub fn tls_args(region: &str, role: &str) -> Vec<String> {
    static MADE: Mutex<()> = Mutex::new(());
    let _one_at_a_time = MADE.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
    let dir = std::env::temp_dir().join(format!("airroads-certs-{}", std::process::id()));
    let cert = dir.join(format!("{region}.{role}.pem"));
    if !cert.exists() {
        let out = Command::new(env!("CARGO_BIN_EXE_airroads"))
            .args(["certs", "--out"])
            .arg(&dir)
            .args(["--region", region, "--roles", role, "--days", "2"])
            .output()
            .unwrap();
        assert!(out.status.success(), "airroads certs: {}", String::from_utf8_lossy(&out.stderr));
    }
    let path = |p: PathBuf| p.display().to_string();
    vec![
        "--zenoh-ca".into(),
        path(dir.join("ca.pem")),
        "--zenoh-cert".into(),
        path(cert),
        "--zenoh-key".into(),
        path(dir.join(format!("{region}.{role}.key"))),
    ]
}

/// Starts `airroads serve --ephemeral` on 127.0.0.1:0 with `args`; returns it, its address and its
/// stdout lines. A region server (`--region`, `--standby-for`) gets this test's certificates of its
/// region unless `args` choose the transport.
pub fn serve(args: &[&str]) -> (Proc, SocketAddr, Banner) {
    let chosen = args.iter().any(|a| a.starts_with("--zenoh-ca") || *a == "--zenoh-insecure");
    let region = args.windows(2).find(|w| w[0] == "--region" || w[0] == "--standby-for");
    let tls = match region {
        Some(w) if !chosen => tls_args(w[1], if w[0] == "--region" { "primary" } else { "standby" }),
        _ => Vec::new(),
    };
    let mut child = Command::new(env!("CARGO_BIN_EXE_airroads"))
        .args(["serve", "--addr", "127.0.0.1:0", "--ephemeral"])
        .args(args)
        .args(&tls)
        .env_remove("AIRROADS_TOKEN")
        .stdout(Stdio::piped())
        .stderr(Stdio::inherit())
        .spawn()
        .unwrap();
    let mut lines = BufReader::new(child.stdout.take().unwrap()).lines();
    let child = Proc(child);
    let first = lines.next().expect("a banner line").unwrap();
    let addr = first.rsplit("http://").next().unwrap().trim().parse().unwrap_or_else(|_| panic!("{first}"));
    let banner = Arc::new(Mutex::new(vec![first]));
    let kept = banner.clone();
    // Keep draining stdout so the server never blocks on a full pipe.
    std::thread::spawn(move || {
        for line in lines.map_while(Result::ok) {
            kept.lock().unwrap().push(line);
        }
    });
    (child, addr, banner)
}

/// Whether a banner line contains `text` (waits up to 2 s for the reading thread).
pub fn banner_has(banner: &Banner, text: &str) -> bool {
    let deadline = Instant::now() + Duration::from_secs(2);
    while Instant::now() < deadline {
        if banner.lock().unwrap().iter().any(|l| l.contains(text)) {
            return true;
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    false
}

/// A Zenoh TLS endpoint on a loopback port that was free a moment ago.
pub fn free_endpoint() -> String {
    let port = std::net::TcpListener::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port();
    format!("tls/127.0.0.1:{port}")
}

/// `GET path` answered 200 with JSON.
pub async fn get(addr: SocketAddr, path: &str) -> Value {
    let (status, body) = super::raw(addr, "GET", path, None, &[]).await;
    assert_eq!(status, 200, "{path}: {body}");
    serde_json::from_str(&body).unwrap()
}

/// (id, position, velocity, arrived) of every UAV in a `/api/state` document.
pub fn uavs(state: &Value) -> Vec<(String, [f64; 2], [f64; 2], bool)> {
    let pair = |v: &Value| [v[0].as_f64().unwrap(), v[1].as_f64().unwrap()];
    state["uavs"]
        .as_array()
        .unwrap()
        .iter()
        .map(|u| (u["id"].as_str().unwrap().to_string(), pair(&u["p"]), pair(&u["v"]), u["arrived"] == true))
        .collect()
}

/// Euclidean distance.
pub fn distance(a: [f64; 2], b: [f64; 2]) -> f64 {
    (a[0] - b[0]).hypot(a[1] - b[1])
}
