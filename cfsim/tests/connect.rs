//! End to end: the official client (crazyflie-lib) connects to the simulator over real UDP and
//! uses the platform, param, log, link and supervisor services.

mod common;

use std::collections::HashMap;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use common::*;
use crazyflie_lib::TocCache;

#[derive(Clone, Default)]
struct MemCache(Arc<Mutex<HashMap<Vec<u8>, String>>>);

impl TocCache for MemCache {
    fn get_toc(&self, key: &[u8]) -> Option<String> {
        self.0.lock().ok()?.get(key).cloned()
    }
    fn store_toc(&self, key: &[u8], toc: &str) {
        if let Ok(mut m) = self.0.lock() {
            m.insert(key.to_vec(), toc.to_owned());
        }
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn connect_from_link_fetches_versions_and_tocs() {
    let sim = sim_at([0.5, -0.25, 0.0]);
    let cache = MemCache::default();
    let cf = connect_with(&sim, cache.clone()).await;

    let proto = cf.platform.protocol_version().await.expect("protocol version");
    assert!(
        (crazyflie_lib::MIN_SUPPORTED_PROTOCOL_VERSION..=crazyflie_lib::MAX_SUPPORTED_PROTOCOL_VERSION)
            .contains(&proto)
    );
    let fw = cf.platform.firmware_version().await.expect("firmware version");
    assert!(fw.contains("cfsim"), "{fw}");
    assert_eq!(cf.platform.device_type_name().await.expect("device type"), "Crazyflie 2.1");

    let logs = cf.log.names();
    for axis in ["x", "y", "z", "vx", "vy", "vz"] {
        let name = format!("stateEstimate.{axis}");
        assert!(logs.contains(&name), "{name} missing from {logs:?}");
        assert_eq!(cf.log.get_type(&name).expect("type"), crazyflie_lib::ValueType::F32);
    }
    assert!(logs.contains(&"pm.vbat".to_owned()) && logs.contains(&"supervisor.info".to_owned()));
    let params = cf.param.names();
    for p in
        ["commander.enHighLevel", "stabilizer.estimator", "kalman.resetEstimation", "locSrv.extPosStdDev"]
    {
        assert!(params.contains(&p.to_owned()), "{p} missing from {params:?}");
    }
    // Both TOCs were stored under their CRC keys.
    assert_eq!(cache.0.lock().expect("cache").len(), 2);
    drop(cf);

    // A second connection is served from the cache (the CRCs did not change).
    let cf = connect_with(&sim, cache.clone()).await;
    assert_eq!(cf.log.names(), logs);
    assert_eq!(cache.0.lock().expect("cache").len(), 2);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn params_read_and_write() {
    let sim = sim_at([0.0; 3]);
    let cf = connect(&sim).await;
    let en: u8 = cf.param.get("commander.enHighLevel").await.expect("read");
    assert_eq!(en, 1);
    let est: u8 = cf.param.get("stabilizer.estimator").await.expect("read");
    assert_eq!(est, 2);
    let std_dev: f32 = cf.param.get("locSrv.extPosStdDev").await.expect("read");
    assert!((std_dev - 0.01).abs() < 1e-6);
    cf.param.set("locSrv.extPosStdDev", 0.05f32).await.expect("write");
    assert!((sim.param("locSrv.extPosStdDev").expect("exists") - 0.05).abs() < 1e-6);
    cf.param.set("kalman.resetEstimation", 1u8).await.expect("write");
    assert_eq!(sim.param("kalman.resetEstimation"), Some(0.0), "the firmware clears the flag");
    assert!(!cf.param.is_writable("firmware.revision0").expect("exists"));
    assert!(cf.param.set("stabilizer.estimator", 1.0f32).await.is_err(), "type mismatch");
    let default: u8 = match cf.param.get_default_value("commander.enHighLevel").await.expect("default") {
        crazyflie_lib::Value::U8(v) => v,
        other => panic!("unexpected {other:?}"),
    };
    assert_eq!(default, 1);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn log_block_streams_at_the_requested_rate() {
    let sim = sim_at([0.5, -0.25, 0.0]);
    let cf = connect(&sim).await;
    // The variables the relay logs.
    let vars = crazyflie::STATE_VARIABLES;
    let stream = log_stream(&cf, &vars, 10).await;
    assert_eq!(sim.truth().log_blocks, 1);

    // One second of the firmware's clock (its timestamps), however long it takes to arrive.
    let mut stamps: Vec<u32> = Vec::new();
    while stamps.last().zip(stamps.first()).is_none_or(|(last, first)| last - first < 1000) {
        let data = tokio::time::timeout(PATIENCE, stream.next())
            .await
            .expect("log data keeps coming")
            .expect("log data");
        let x = data.data["stateEstimate.x"].to_f64_lossy();
        let y = data.data["stateEstimate.y"].to_f64_lossy();
        let z = data.data["stateEstimate.z"].to_f64_lossy();
        assert_eq!((x, y, z), (0.5, -0.25, 0.0));
        assert_eq!(data.data.len(), 6);
        stamps.push(data.timestamp);
    }
    // Every 10 ms of the firmware's clock: a simulation run late by a loaded machine skips the
    // periods it missed (whole multiples), it never bursts or drifts.
    let steps: Vec<u32> = stamps.windows(2).map(|w| w[1] - w[0]).collect();
    assert!(steps.iter().all(|d| *d > 0 && d % 10 == 0), "timestamps not on the 10 ms grid: {steps:?}");
    let exact = steps.iter().filter(|d| **d == 10).count();
    assert!(exact * 2 >= steps.len(), "most samples not 10 ms apart: {steps:?}");
    assert!(stamps.len() <= 102, "more than 100 Hz: {} samples", stamps.len());

    // Stopping stops the stream; dropping the block deletes it in the firmware.
    let block = stream.stop().await.expect("stop");
    tokio::time::sleep(Duration::from_millis(50)).await;
    drop(block);
    let _other = cf.log.create_block().await.expect("create another block");
    assert!(eventually(PATIENCE, || sim.truth().log_blocks == 1).await.is_some());
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn link_echo_and_supervisor() {
    let sim = sim_at([0.0; 3]);
    let cf = connect(&sim).await;
    let ms = cf.link_service.ping().await.expect("ping");
    assert!(ms < PATIENCE.as_secs_f64() * 1000.0, "{ms} ms");
    let info = cf.supervisor.read_bitfield().await.expect("supervisor");
    assert!(info.can_fly() && info.is_armed() && !info.is_flying() && !info.is_locked());
    let echo = cf.link_service.test_echo_bandwidth(20).await.expect("echo");
    assert!(echo.packets_per_sec > 0.0);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn garbage_datagrams_are_survived() {
    let sim = sim_at([0.0; 3]);
    let sock = tokio::net::UdpSocket::bind("127.0.0.1:0").await.expect("bind");
    sock.connect(sim.addr()).await.expect("connect");
    let mut x = 0x1234_5678u32;
    for i in 0..2000 {
        x ^= x << 13;
        x ^= x >> 17;
        x ^= x << 5;
        let len = i % 40;
        let d: Vec<u8> = (0..len).map(|k| (x >> (k % 24)) as u8).collect();
        sock.send(&d).await.expect("send");
        if i % 50 == 49 {
            // Pace the burst so the kernel's receive buffer does not overflow.
            tokio::time::sleep(Duration::from_millis(2)).await;
        }
    }
    // Still alive: an echo sent after the garbage comes back (so all of it was processed)...
    let probe = [0xf0, 0xde, 0xad, 0xbe, 0xef];
    sock.send(&probe).await.expect("send");
    let mut buf = [0u8; 64];
    let deadline = Instant::now() + PATIENCE;
    loop {
        let n = tokio::time::timeout_at(deadline.into(), sock.recv(&mut buf))
            .await
            .expect("answer")
            .expect("recv");
        if buf[..n] == probe {
            break;
        }
    }
    let received = sim.stats().received;
    assert!(received > 1900, "{received} of 2001 datagrams received");
    // ... and, once the garbage's side effects (maybe an emergency stop) are cleared, a full
    // client connects.
    sim.reboot();
    let cf = connect(&sim).await;
    let ping = cf.link_service.ping().await;
    assert!(ping.is_ok(), "{ping:?}");
}
