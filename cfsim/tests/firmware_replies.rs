//! End to end: the simulator answers like the firmware where cflib (Bitcraze's Python client)
//! looks: the supervisor port's answers carry the response flag, arming requests are answered and
//! change the armed bit, and the Kalman variances cflib's examples wait on are logged. Raw UDP
//! checks the exact bytes; the official Rust client (crazyflie-lib) checks the same through its API.

mod common;

use std::time::{Duration, Instant};

use cfsim::supervisor::{AUTO_ARM, CAN_BE_ARMED, CAN_FLY, IS_ARMED, IS_FLYING};
use cfsim::{SimConfig, SimCrazyflie, SimHandle};
use common::*;
use tokio::net::UdpSocket;

/// Header bytes (`port << 4 | channel`).
const SUPERVISOR_INFO: u8 = 0x90;
const SUPERVISOR_COMMAND: u8 = 0x91;
const PLATFORM_COMMAND: u8 = 0xd0;

/// A simulator that waits for an arming request (`--require-arming`).
fn sim_requiring_arming() -> SimHandle {
    let config = SimConfig { require_arming: true, ..SimConfig::default() };
    SimCrazyflie::spawn("127.0.0.1:0".parse().expect("addr"), config).expect("spawn simulator")
}

/// A raw UDP socket talking to `sim`.
async fn raw(sim: &SimHandle) -> UdpSocket {
    let sock = UdpSocket::bind("127.0.0.1:0").await.expect("bind");
    sock.connect(sim.addr()).await.expect("connect");
    sock
}

/// Send `datagram` and return the payload of the first answer with header `header` (other
/// datagrams, e.g. log data, are skipped).
async fn ask(sock: &UdpSocket, datagram: &[u8], header: u8) -> Vec<u8> {
    sock.send(datagram).await.expect("send");
    let deadline = Instant::now() + PATIENCE;
    let mut buf = [0u8; 64];
    loop {
        let n = tokio::time::timeout_at(deadline.into(), sock.recv(&mut buf))
            .await
            .unwrap_or_else(|_| panic!("no answer with header {header:#04x} to {datagram:02x?}"))
            .expect("recv");
        if n > 0 && buf[0] == header {
            return buf[1..n].to_vec();
        }
    }
}

/// The state bitfield as the supervisor port answers it, checking the response flag.
async fn bitfield(sock: &UdpSocket) -> u16 {
    let answer = ask(sock, &[SUPERVISOR_INFO, 0x0c], SUPERVISOR_INFO).await;
    assert_eq!(answer.len(), 3, "{answer:02x?}");
    assert_eq!(answer[0], 0x8c, "the firmware answers 0x80 | CMD_GET_STATE_BITFIELD");
    u16::from_le_bytes([answer[1], answer[2]])
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn supervisor_answers_carry_the_response_flag_and_the_bits() {
    let sim = sim_at([0.0; 3]);
    let sock = raw(&sim).await;
    // On the ground and auto-armed (the Crazyflie 2.1 default): armed, can fly, not flying.
    let bits = bitfield(&sock).await;
    assert_eq!(bits & 0xff, IS_ARMED | AUTO_ARM | CAN_FLY, "{bits:#06x}");
    assert_eq!(bits, sim.supervisor_bits());
    // The single-bit requests (CMD_CAN_BE_ARMED = 1 .. CMD_HL_CONTROL_DISABLED = 11).
    assert_eq!(ask(&sock, &[SUPERVISOR_INFO, 0x01], SUPERVISOR_INFO).await, vec![0x81, 0], "can be armed");
    assert_eq!(ask(&sock, &[SUPERVISOR_INFO, 0x02], SUPERVISOR_INFO).await, vec![0x82, 1], "is armed");
    assert_eq!(ask(&sock, &[SUPERVISOR_INFO, 0x04], SUPERVISOR_INFO).await, vec![0x84, 1], "can fly");
    assert_eq!(ask(&sock, &[SUPERVISOR_INFO, 0x05], SUPERVISOR_INFO).await, vec![0x85, 0], "is flying");
    assert_eq!(
        ask(&sock, &[SUPERVISOR_COMMAND, 0x02], SUPERVISOR_COMMAND).await,
        vec![0x82, 1, 1],
        "recovery"
    );

    // In flight the bitfield says so, through the official client too.
    let cf = connect(&sim).await;
    take_off(&cf, &sim, 0.5).await;
    let bits = bitfield(&sock).await;
    assert_eq!(bits & (IS_FLYING | CAN_FLY | IS_ARMED), IS_FLYING | CAN_FLY | IS_ARMED, "{bits:#06x}");
    let info = cf.supervisor.read_bitfield().await.expect("bitfield");
    assert!(info.is_flying() && info.can_fly() && info.is_armed() && info.is_auto_armed());
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn arming_requests_are_answered_and_gate_the_motors() {
    let sim = sim_requiring_arming();
    let sock = raw(&sim).await;
    assert_eq!(bitfield(&sock).await & 0xff, CAN_BE_ARMED, "waits for arming: not armed, cannot fly");

    // Arm on the supervisor port: [0x81, success, armed].
    assert_eq!(ask(&sock, &[SUPERVISOR_COMMAND, 0x01, 1], SUPERVISOR_COMMAND).await, vec![0x81, 1, 1]);
    let armed = eventually(PATIENCE, || sim.supervisor_bits() & CAN_FLY != 0).await;
    assert!(armed.is_some(), "ready to fly within a supervisor cycle");
    assert_eq!(bitfield(&sock).await & 0xff, IS_ARMED | CAN_FLY);
    // Disarm: granted, the armed bit clears at once, "can fly" in the next supervisor cycle.
    assert_eq!(ask(&sock, &[SUPERVISOR_COMMAND, 0x01, 0], SUPERVISOR_COMMAND).await, vec![0x81, 1, 0]);
    assert_eq!(bitfield(&sock).await & IS_ARMED, 0);
    eventually(PATIENCE, || sim.supervisor_bits() & CAN_FLY == 0).await.expect("cannot fly");
    assert_eq!(bitfield(&sock).await & 0xff, CAN_BE_ARMED);
    // The legacy platform request (protocol < 12) arms too; the firmware answers [0x01, success].
    assert_eq!(ask(&sock, &[PLATFORM_COMMAND, 0x01, 1], PLATFORM_COMMAND).await, vec![0x01, 1]);
    eventually(PATIENCE, || sim.supervisor_bits() & CAN_FLY != 0).await.expect("armed again");
    ask(&sock, &[SUPERVISOR_COMMAND, 0x01, 0], SUPERVISOR_COMMAND).await;

    // With the official client: not armed, a take-off leaves it on the ground...
    let cf = connect(&sim).await;
    assert!(!cf.supervisor.read_bitfield().await.expect("bitfield").is_armed());
    cf.high_level_commander.take_off(0.5, None, 1.0, None).await.expect("take off");
    tokio::time::sleep(Duration::from_millis(600)).await;
    assert!(!sim.truth().motors_on && sim.truth().position[2] == 0.0, "flew unarmed");
    // ... armed, it climbs to the planned height.
    cf.supervisor.send_arming_request(true).await.expect("arm");
    eventually(PATIENCE, || (sim.truth().position[2] - 0.5).abs() < 0.02).await.expect("takes off");
    let info = cf.supervisor.read_bitfield().await.expect("bitfield");
    assert!(info.is_armed() && info.can_fly() && info.is_flying() && !info.is_auto_armed());
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn kalman_variances_are_logged_and_settle() {
    let sim = sim_at([0.0; 3]);
    let cf = connect(&sim).await;
    let vars = ["kalman.varPX", "kalman.varPY", "kalman.varPZ", "kalman.varX", "kalman.varY", "kalman.varZ"];
    let names = cf.log.names();
    for v in vars {
        assert!(names.contains(&v.to_owned()), "{v} missing from the log TOC");
        assert_eq!(cf.log.get_type(v).expect("type"), crazyflie_lib::ValueType::F32, "{v}");
    }
    // cflib's "wait for the position estimator": the last 10 samples of each variance spread by
    // less than 0.001 (its examples log every 500 ms; 100 ms keeps the test short).
    let stream = log_stream(&cf, &vars, 100).await;
    let mut history: Vec<Vec<f64>> = Vec::new();
    let settled = tokio::time::timeout(PATIENCE, async {
        loop {
            let data = stream.next().await.expect("log data");
            let sample: Vec<f64> = vars.iter().map(|v| data.data[*v].to_f64_lossy()).collect();
            assert!(sample.iter().all(|x| x.is_finite() && *x > 0.0), "{sample:?}");
            history.push(sample);
            let window = &history[history.len().saturating_sub(10)..];
            let spread = |k: usize| {
                let v = window.iter().map(|s| s[k]);
                v.clone().fold(f64::MIN, f64::max) - v.fold(f64::MAX, f64::min)
            };
            if window.len() == 10 && (0..3).all(|k| spread(k) < 0.001) {
                return window.last().cloned().unwrap_or_default();
            }
        }
    })
    .await
    .expect("the estimator settles");
    assert!(settled.iter().all(|v| *v < 0.001), "settled variances {settled:?}");
    assert!(history.len() < 40, "{} samples to settle", history.len());
}
