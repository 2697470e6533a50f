//! The SITL physics against a stand-in firmware (plain UDP sockets): the hello, the sensor feed
//! and its rates, motor PWM, the relay in both directions, null packets, restarts, faults, and
//! whether ten drones keep up with real time.

use std::net::{SocketAddr, UdpSocket};
use std::time::{Duration, Instant};

use cfsim::crtp::{f32s_at, i16_at};
use cfsim::quadrotor::QuadParams;
use cfsim::sitl::wire::{EXT_POSE_HEADER, HELLO, NULL_PACKET, SENSOR_BARO, SENSOR_IMU, SIM_HEADER};
use cfsim::sitl::{SitlConfig, SitlFaults, SitlHandle};

/// Ephemeral ports for `n` drones at x = 0, 1, ...
fn config(n: usize) -> SitlConfig {
    SitlConfig {
        positions: (0..n).map(|i| [i as f64, 0.0, 0.0]).collect(),
        firmware_base_port: 0,
        client_base_port: 0,
        ..SitlConfig::default()
    }
}

fn socket_to(peer: SocketAddr) -> UdpSocket {
    let s = UdpSocket::bind("127.0.0.1:0").expect("bind");
    s.connect(peer).expect("connect");
    s.set_read_timeout(Some(Duration::from_millis(20))).expect("timeout");
    s
}

/// A stand-in firmware that has said hello and been answered.
fn firmware(sitl: &SitlHandle, index: usize) -> UdpSocket {
    let fw = socket_to(sitl.firmware_addr(index).expect("drone"));
    let mut buf = [0u8; 64];
    for _ in 0..50 {
        fw.send(&[HELLO]).expect("send hello");
        // Sensor packets may already follow the answer: look for the answer among them.
        let deadline = Instant::now() + Duration::from_millis(100);
        while Instant::now() < deadline {
            if let Ok(n) = fw.recv(&mut buf)
                && buf[..n] == [HELLO]
            {
                return fw;
            }
        }
    }
    panic!("no answer to the hello");
}

/// Every datagram that arrives on `s` within `d`.
fn collect(s: &UdpSocket, d: Duration) -> Vec<Vec<u8>> {
    let mut out = Vec::new();
    let mut buf = [0u8; 64];
    let end = Instant::now() + d;
    while Instant::now() < end {
        if let Ok(n) = s.recv(&mut buf) {
            out.push(buf[..n].to_vec());
        }
    }
    out
}

fn motor_datagram(pwm: [u16; 4]) -> Vec<u8> {
    let mut d = vec![SIM_HEADER];
    pwm.iter().for_each(|v| d.extend_from_slice(&v.to_le_bytes()));
    d
}

fn is_sensor(d: &[u8], kind: u8) -> bool {
    d.len() == 14 && d[0] == SIM_HEADER && d[1] == kind
}

#[test]
fn feeds_sensors_at_their_rates_and_takes_motor_pwm() {
    let sitl = SitlHandle::spawn(config(1)).expect("spawn");
    let fw = firmware(&sitl, 0);
    let got = collect(&fw, Duration::from_secs(1));
    let count = |f: &dyn Fn(&[u8]) -> bool| got.iter().filter(|d| f(d)).count();
    let imu = count(&|d| is_sensor(d, SENSOR_IMU));
    let baro = count(&|d| is_sensor(d, SENSOR_BARO));
    let pose = count(&|d| d.len() == 30 && d[0] == EXT_POSE_HEADER && d[1] == 8);
    assert!((900..=1100).contains(&imu), "IMU {imu}/s");
    assert!((45..=55).contains(&baro), "barometer {baro}/s");
    assert!((180..=220).contains(&pose), "pose {pose}/s");
    // At rest on the floor: 1 g up, no rotation; the pose is where the drone starts.
    let last_imu = got.iter().rev().find(|d| is_sensor(d, SENSOR_IMU)).expect("an IMU packet");
    let values: Vec<i16> = (0..6).filter_map(|k| i16_at(last_imu, 2 + 2 * k)).collect();
    assert_eq!(values, [0, 0, 2048, 0, 0, 0]);
    let last_pose = got.iter().rev().find(|d| d[0] == EXT_POSE_HEADER).expect("a pose");
    assert_eq!(f32s_at::<7>(last_pose, 2), Some([0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0]));

    // The firmware sends its motors every 2 ms; here every 5 ms for half a second.
    let lift = QuadParams::CRAZYFLIE_2_1.hover_pwm() as u16 + 4_000;
    for _ in 0..100 {
        fw.send(&motor_datagram([lift; 4])).expect("send motors");
        std::thread::sleep(Duration::from_millis(5));
    }
    let truth = sitl.truth(0).expect("drone 0");
    assert_eq!(truth.pwm, [lift; 4]);
    assert!(truth.position[2] > 0.05 && !truth.on_floor, "{truth:?}");
    let stats = sitl.stats(0).expect("drone 0");
    assert_eq!(stats.hellos, 1);
    assert!(stats.motor_packets_since_hello >= 90, "{stats:?}");
    assert_eq!(stats.motor_watchdog_cuts, 0);
    assert!((5..100).contains(&stats.longest_motor_gap), "every 5 ms: {stats:?}");
    assert_eq!(sitl.fell_behind(0), None, "kept up so far");
    // A firmware that stops sending (killed, frozen) has its motors stopped within 100 ms, as a
    // real Crazyflie's watchdog would: it falls, and the flight says nothing about the server.
    std::thread::sleep(Duration::from_millis(300));
    let truth = sitl.truth(0).expect("drone 0");
    assert_eq!(truth.pwm, [0; 4]);
    assert!(truth.velocity[2] < -0.5, "falling: {truth:?}");
    let stats = sitl.stats(0).expect("drone 0");
    assert_eq!((stats.motor_watchdog_cuts, stats.longest_motor_gap), (1, 100), "cut at 100 ms, then off");
    let behind = sitl.fell_behind(0).expect("a firmware silent in flight fell behind");
    assert!(behind.contains("cut its motors 1 time(s)"), "{behind}");

    // A restarted firmware says hello from a new socket: its motors start off.
    let restarted = firmware(&sitl, 0);
    std::thread::sleep(Duration::from_millis(20));
    assert_eq!(sitl.truth(0).expect("drone 0").pwm, [0; 4]);
    let stats = sitl.stats(0).expect("drone 0");
    assert_eq!((stats.hellos, stats.motor_packets_since_hello), (2, 0));
    // The old process is ignored now.
    fw.send(&motor_datagram([lift; 4])).expect("send motors");
    std::thread::sleep(Duration::from_millis(20));
    assert_eq!(sitl.truth(0).expect("drone 0").pwm, [0; 4]);
    drop(restarted);
    sitl.shutdown().expect("shutdown");
}

/// The slowest second of a firmware: none before its stabilizer ran a whole second; then the
/// fewest motor packets of any second, so a firmware that falls to a fifth of its pace shows it.
#[test]
fn the_slowest_second_shows_a_firmware_that_fell_behind() {
    let sitl = SitlHandle::spawn(config(1)).expect("spawn");
    let fw = firmware(&sitl, 0);
    let send_for = |period: Duration, run: Duration| {
        let end = Instant::now() + run;
        while Instant::now() < end {
            fw.send(&motor_datagram([0; 4])).expect("send motors");
            std::thread::sleep(period);
        }
    };
    assert_eq!(sitl.stats(0).expect("drone 0").slowest_second, None, "no motor packet yet");
    // At its pace (every 2 ms) for more than two seconds: at least one whole second counted.
    send_for(Duration::from_millis(2), Duration::from_millis(2300));
    let at_pace = sitl.stats(0).expect("drone 0").slowest_second.expect("a whole second counted");
    assert!(at_pace > 150, "{at_pace} motor packets in the slowest second at 500/s");
    // Then every 10 ms (at most 100/s) for more than two seconds.
    send_for(Duration::from_millis(10), Duration::from_millis(2300));
    let behind = sitl.stats(0).expect("drone 0").slowest_second.expect("counted");
    assert!(behind <= 110 && behind < at_pace, "{behind} in the slowest second at 100/s");
    sitl.shutdown().expect("shutdown");
}

#[test]
fn relays_client_and_firmware_and_leaves_null_packets_unanswered() {
    let sitl = SitlHandle::spawn(config(1)).expect("spawn");
    let fw = firmware(&sitl, 0);
    let client = socket_to(sitl.client_addr(0).expect("drone"));
    let non_sensor = |got: Vec<Vec<u8>>| -> Vec<Vec<u8>> {
        got.into_iter().filter(|d| d[0] != SIM_HEADER && d[0] != EXT_POSE_HEADER).collect()
    };
    client.send(&[0x30, 1, 2, 3]).expect("send");
    client.send(&[NULL_PACKET]).expect("send");
    assert_eq!(
        non_sensor(collect(&fw, Duration::from_millis(200))),
        vec![vec![0x30, 1, 2, 3], vec![NULL_PACKET]]
    );
    assert!(collect(&client, Duration::from_millis(200)).is_empty(), "nothing answers a null packet");
    fw.send(b"\x00hello").expect("send");
    assert_eq!(collect(&client, Duration::from_millis(200)), vec![b"\x00hello".to_vec()]);
    // The latest sender is the client.
    let other = socket_to(sitl.client_addr(0).expect("drone"));
    other.send(&[0x5c, 9]).expect("send");
    std::thread::sleep(Duration::from_millis(50));
    fw.send(&[0x50, 7]).expect("send");
    assert_eq!(collect(&other, Duration::from_millis(200)), vec![vec![0x50, 7]]);
    assert!(collect(&client, Duration::from_millis(50)).is_empty());
    let stats = sitl.stats(0).expect("drone 0");
    assert_eq!((stats.to_firmware, stats.to_client, stats.nulls_answered), (3, 2, 0));
}

#[test]
fn answers_null_packets_when_asked_and_applies_faults() {
    let sitl = SitlHandle::spawn(SitlConfig { answer_null: true, ..config(1) }).expect("spawn");
    let fw = firmware(&sitl, 0);
    let client = socket_to(sitl.client_addr(0).expect("drone"));
    client.send(&[NULL_PACKET]).expect("send");
    assert_eq!(collect(&client, Duration::from_millis(200)), vec![vec![NULL_PACKET]]);

    // Total loss: the relay drops everything both ways; sensors still flow.
    let gap_from = sitl.elapsed();
    let gap = SitlFaults {
        link_loss: 1.0,
        pose_gap: Some((gap_from, gap_from + Duration::from_secs(60))),
        ..SitlFaults::default()
    };
    assert!(sitl.set_faults(0, gap));
    assert!(!sitl.set_faults(1, gap), "no drone 1");
    std::thread::sleep(Duration::from_millis(20));
    collect(&fw, Duration::from_millis(20));
    for _ in 0..10 {
        client.send(&[0x30, 1]).expect("send");
        fw.send(&[0x00, 1]).expect("send");
    }
    let got = collect(&fw, Duration::from_millis(300));
    assert!(got.iter().all(|d| d[0] == SIM_HEADER), "only sensors, no pose, nothing relayed");
    assert!(got.len() > 200, "sensors keep flowing");
    assert!(collect(&client, Duration::from_millis(50)).is_empty());
    let stats = sitl.stats(0).expect("drone 0");
    assert_eq!((stats.dropped_to_firmware, stats.dropped_to_client), (10, 10));

    // Half loss, seeded: about half gets through.
    sitl.set_faults(0, SitlFaults { link_loss: 0.5, ..SitlFaults::default() });
    std::thread::sleep(Duration::from_millis(20));
    for _ in 0..200 {
        client.send(&[0x30, 2]).expect("send");
    }
    let relayed = collect(&fw, Duration::from_millis(300)).iter().filter(|d| d[..] == [0x30, 2]).count();
    assert!((60..140).contains(&relayed), "{relayed} of 200 relayed");
}

#[test]
fn wind_pushes_a_drone() {
    // High up with the motors off: it falls, and the wind (1 m/s² on this mass) pushes it along x.
    let mass = QuadParams::CRAZYFLIE_2_1.mass;
    let faults = SitlFaults { wind_force: [mass, 0.0, 0.0], ..SitlFaults::default() };
    let sitl = SitlHandle::spawn(SitlConfig { positions: vec![[0.0, 0.0, 100.0]], faults, ..config(1) })
        .expect("spawn");
    std::thread::sleep(Duration::from_millis(500));
    let t = sitl.truth(0).expect("drone 0");
    // The same pull as the loop's simulated time: v = a t in both directions.
    assert!((t.velocity[0] - t.time).abs() < 1e-6, "{t:?}");
    assert!((t.velocity[2] + QuadParams::CRAZYFLIE_2_1.gravity * t.time).abs() < 1e-6, "{t:?}");
    assert_eq!(t.velocity[1], 0.0);
    assert_eq!(sitl.faults(0), Some(faults));
}

#[test]
fn writes_ground_truth_csv() {
    let dir = std::env::temp_dir().join(format!("cfsim-sitl-truth-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let sitl = SitlHandle::spawn(SitlConfig { truth_dir: Some(dir.clone()), ..config(2) }).expect("spawn");
    std::thread::sleep(Duration::from_millis(500));
    sitl.shutdown().expect("shutdown");
    let text = std::fs::read_to_string(dir.join("truth1.csv")).expect("truth1.csv");
    let mut lines = text.lines();
    assert_eq!(lines.next(), Some("t,x,y,z,vx,vy,vz,roll,pitch,yaw,m1,m2,m3,m4"));
    let rows: Vec<Vec<f64>> =
        lines.map(|l| l.split(',').map(|c| c.parse().expect("a number")).collect()).collect();
    assert!((40..=60).contains(&rows.len()), "{} rows in 0.5 s", rows.len());
    assert!(rows.iter().all(|r| r.len() == 14 && r[1] == 1.0 && r[3] == 0.0), "drone 1 rests at x = 1");
    assert!(rows.windows(2).all(|w| (w[1][0] - w[0][0] - 0.01).abs() < 1e-6), "100 Hz of simulated time");
    std::fs::remove_dir_all(&dir).expect("clean up");
}

#[test]
fn ten_drones_keep_up_with_real_time() {
    const N: usize = 10;
    let sitl = SitlHandle::spawn(config(N)).expect("spawn");
    let firmwares: Vec<UdpSocket> = (0..N).map(|i| firmware(&sitl, i)).collect();
    for fw in &firmwares {
        fw.set_nonblocking(true).expect("non-blocking");
    }
    // Each stand-in firmware answers every IMU packet with motor PWM, as cf2 does.
    let before = sitl.loop_stats();
    let hover = QuadParams::CRAZYFLIE_2_1.hover_pwm() as u16;
    let mut buf = [0u8; 64];
    let end = Instant::now() + Duration::from_secs(3);
    while Instant::now() < end {
        for fw in &firmwares {
            while let Ok(n) = fw.recv(&mut buf) {
                if is_sensor(&buf[..n], SENSOR_IMU) {
                    let _ = fw.send(&motor_datagram([hover - 2_000; 4]));
                }
            }
        }
        std::thread::sleep(Duration::from_micros(200));
    }
    let after = sitl.loop_stats();
    let ticks = after.ticks - before.ticks;
    let seconds = (after.elapsed - before.elapsed).as_secs_f64();
    let rate = ticks as f64 / seconds;
    let load = (after.busy - before.busy).as_secs_f64() / seconds;
    println!(
        "{N} drones: physics {rate:.1} Hz, load {:.1}%, longest tick {:.2} ms, {} resyncs",
        100.0 * load,
        after.longest_tick.as_secs_f64() * 1e3,
        after.resyncs
    );
    assert!(rate > 950.0, "physics at {rate:.1} Hz");
    for i in 0..N {
        let s = sitl.stats(i).expect("drone");
        assert!(s.motor_packets > 2_000, "drone {i}: {s:?}");
        assert_eq!(sitl.truth(i).expect("drone").pwm, [hover - 2_000; 4]);
    }
}
