//! One drone of the SITL simulator: its two sockets, its model, the relay between firmware and
//! client, the sensor feed and the ground-truth file.

use std::fs::File;
use std::io::{self, BufWriter, ErrorKind, Write};
use std::net::{SocketAddr, UdpSocket};
use std::path::PathBuf;

use super::wire::{self, CLIENT_CLOSE, HELLO, NULL_PACKET};
use super::{DroneStats, SitlFaults};
use crate::faults::Prng;
use crate::quadrotor::{ImuNoise, Quadrotor};

/// Most datagrams read from one socket in one tick, so a flood cannot stall the loop.
const MAX_READS_PER_TICK: usize = 256;
/// Physics ticks per barometer sample (50 Hz at 1 kHz).
const TICKS_PER_BARO: u64 = 20;
/// Physics ticks per ground-truth row (100 Hz at 1 kHz).
const TICKS_PER_TRUTH_ROW: u64 = 10;
/// Physics ticks per second of [`DroneStats::slowest_second`] (1 s at 1 kHz).
const TICKS_PER_SECOND: u64 = 1000;
/// Ground-truth rows between flushes of the file.
const ROWS_PER_FLUSH: u64 = 100;
/// The ground-truth file's header line.
const TRUTH_HEADER: &str = "t,x,y,z,vx,vy,vz,roll,pitch,yaw,m1,m2,m3,m4";

/// The ground-truth CSV of one drone.
pub(super) struct TruthFile {
    path: PathBuf,
    out: BufWriter<File>,
    rows: u64,
}

impl TruthFile {
    /// Create (truncate) `path` and write the header.
    pub(super) fn create(path: PathBuf) -> io::Result<Self> {
        let mut out = BufWriter::new(File::create(&path)?);
        writeln!(out, "{TRUTH_HEADER}")?;
        Ok(Self { path, out, rows: 0 })
    }

    fn write_row(&mut self, q: &Quadrotor) -> io::Result<()> {
        let t = q.truth();
        let [x, y, z] = t.position;
        let [vx, vy, vz] = t.velocity;
        let [roll, pitch, yaw] = t.euler.map(f64::to_degrees);
        let [m1, m2, m3, m4] = t.pwm;
        writeln!(
            self.out,
            "{:.3},{x:.4},{y:.4},{z:.4},{vx:.3},{vy:.3},{vz:.3},{roll:.2},{pitch:.2},{yaw:.2},{m1},{m2},{m3},{m4}",
            t.time
        )?;
        self.rows += 1;
        if self.rows.is_multiple_of(ROWS_PER_FLUSH) {
            self.out.flush()?;
        }
        Ok(())
    }
}

/// Physics ticks (1 ms) without a motor packet after which the motors stop: the STM32's
/// independent watchdog resets a Crazyflie whose firmware hangs; the SITL build has none.
pub(super) const MOTOR_WATCHDOG_TICKS: u64 = 100;

/// One simulated drone and its link to a firmware process and a client.
pub(super) struct Drone {
    pub(super) firmware_socket: UdpSocket,
    pub(super) client_socket: UdpSocket,
    firmware: Option<SocketAddr>,
    client: Option<SocketAddr>,
    pub(super) quad: Quadrotor,
    noise: Option<ImuNoise>,
    loss_rng: Prng,
    answer_null: bool,
    pose_phase: f64,
    /// Physics ticks since the firmware's last motor packet (see [`MOTOR_WATCHDOG_TICKS`]).
    ticks_without_motors: u64,
    /// The motor packets counted when the current second began, if the stabilizer ran by then.
    motors_at_second_start: Option<u64>,
    pub(super) stats: DroneStats,
    truth_file: Option<TruthFile>,
    /// The first error writing the ground-truth file (the file is abandoned then).
    pub(super) truth_error: Option<(PathBuf, io::Error)>,
}

impl Drone {
    /// A drone on two bound sockets, switched to non-blocking mode here.
    pub(super) fn new(
        firmware_socket: UdpSocket,
        client_socket: UdpSocket,
        quad: Quadrotor,
        noise: Option<ImuNoise>,
        loss_seed: u64,
        answer_null: bool,
        truth_file: Option<TruthFile>,
    ) -> io::Result<Self> {
        firmware_socket.set_nonblocking(true)?;
        client_socket.set_nonblocking(true)?;
        Ok(Self {
            firmware_socket,
            client_socket,
            firmware: None,
            client: None,
            quad,
            noise,
            loss_rng: Prng::new(loss_seed),
            answer_null,
            pose_phase: 0.0,
            ticks_without_motors: 0,
            motors_at_second_start: None,
            stats: DroneStats::default(),
            truth_file,
            truth_error: None,
        })
    }

    /// Read everything waiting on both sockets: hellos, motor PWM, and the relay.
    pub(super) fn poll(&mut self, faults: &SitlFaults, buf: &mut [u8]) {
        for _ in 0..MAX_READS_PER_TICK {
            match self.firmware_socket.recv_from(buf) {
                Ok((n, from)) => self.handle_firmware_datagram(&buf[..n], from, faults),
                Err(e) if e.kind() == ErrorKind::WouldBlock => break,
                Err(_) => self.stats.receive_errors += 1,
            }
        }
        for _ in 0..MAX_READS_PER_TICK {
            match self.client_socket.recv_from(buf) {
                Ok((n, from)) => self.handle_client_datagram(&buf[..n], from, faults),
                Err(e) if e.kind() == ErrorKind::WouldBlock => break,
                Err(_) => self.stats.receive_errors += 1,
            }
        }
    }

    fn handle_firmware_datagram(&mut self, datagram: &[u8], from: SocketAddr, faults: &SitlFaults) {
        if datagram == [HELLO] {
            // A (re)started firmware: it starts with its motors off.
            self.firmware = Some(from);
            self.quad.set_pwm([0; 4]);
            self.stats.hellos += 1;
            self.stats.motor_packets_since_hello = 0;
            // A second with a restart in it is not one the stabilizer ran through.
            self.motors_at_second_start = None;
            self.stats.firmware = Some(from);
            self.send_to_firmware(&[HELLO]);
            return;
        }
        if self.firmware != Some(from) {
            // Not the firmware that said hello: a stale process or a stranger.
            self.stats.ignored += 1;
            return;
        }
        if let Some(pwm) = wire::motor_pwm(datagram) {
            self.quad.set_pwm(pwm);
            self.ticks_without_motors = 0;
            self.stats.motor_packets += 1;
            self.stats.motor_packets_since_hello += 1;
            return;
        }
        match self.client {
            Some(client) if !datagram.is_empty() => {
                if faults.drops(&mut self.loss_rng) {
                    self.stats.dropped_to_client += 1;
                } else if self.client_socket.send_to(datagram, client).is_ok() {
                    self.stats.to_client += 1;
                } else {
                    self.stats.send_errors += 1;
                }
            }
            _ => self.stats.ignored += 1,
        }
    }

    fn handle_client_datagram(&mut self, datagram: &[u8], from: SocketAddr, faults: &SitlFaults) {
        match datagram {
            [] => self.stats.ignored += 1,
            [HELLO] => self.set_client(Some(from)),
            [CLIENT_CLOSE] => self.set_client(None),
            _ => {
                // Whoever sent last is the client.
                if self.client != Some(from) {
                    self.set_client(Some(from));
                }
                if self.answer_null && datagram == [NULL_PACKET] {
                    // An empty acknowledgement, as a Crazyradio would return.
                    self.stats.nulls_answered += 1;
                    if self.client_socket.send_to(&[NULL_PACKET], from).is_err() {
                        self.stats.send_errors += 1;
                    }
                }
                if self.firmware.is_none() {
                    self.stats.ignored += 1;
                } else if faults.drops(&mut self.loss_rng) {
                    self.stats.dropped_to_firmware += 1;
                } else {
                    self.send_to_firmware(datagram);
                    self.stats.to_firmware += 1;
                    if datagram.first().is_some_and(|h| h >> 4 == wire::SETPOINT_PORT) {
                        self.stats.setpoints += 1;
                        self.stats.last_setpoint = Some(std::time::Instant::now());
                    }
                }
            }
        }
    }

    fn set_client(&mut self, client: Option<SocketAddr>) {
        self.client = client;
        self.stats.client = client;
    }

    fn send_to_firmware(&mut self, datagram: &[u8]) {
        if let Some(fw) = self.firmware
            && self.firmware_socket.send_to(datagram, fw).is_err()
        {
            self.stats.send_errors += 1;
        }
    }

    /// Physics tick `tick` (0, 1, ...) of `dt` seconds, `elapsed` seconds after the start: the
    /// model steps, then the firmware gets its sensors and the truth file its row.
    pub(super) fn tick(&mut self, tick: u64, dt: f64, elapsed: f64, faults: &SitlFaults, pose_hz: f64) {
        self.quad.external_force = faults.wind_force;
        // A firmware that stopped commanding its motors (killed, frozen) is reset by the
        // microcontroller's watchdog on a real Crazyflie: the motors stop, it falls.
        self.ticks_without_motors = self.ticks_without_motors.saturating_add(1);
        if self.quad.pwm() != [0; 4] {
            self.stats.longest_motor_gap = self.stats.longest_motor_gap.max(self.ticks_without_motors);
            if self.ticks_without_motors == MOTOR_WATCHDOG_TICKS {
                self.quad.set_pwm([0; 4]);
                self.stats.motor_watchdog_cuts += 1;
            }
        }
        self.quad.step(dt);
        if self.firmware.is_some() {
            let imu = self.quad.imu(self.noise.as_mut());
            self.send_to_firmware(&wire::imu_datagram(&imu));
            self.stats.imu_sent += 1;
            if tick.is_multiple_of(TICKS_PER_BARO) {
                self.send_to_firmware(&wire::baro_datagram(&self.quad.barometer()));
                self.stats.baro_sent += 1;
            }
            self.pose_phase += pose_hz * dt;
            if self.pose_phase >= 1.0 {
                self.pose_phase -= 1.0;
                if faults.pose_sent_at(elapsed) {
                    let s = &self.quad.state;
                    self.send_to_firmware(&wire::pose_datagram(s.position, s.attitude));
                    self.stats.pose_sent += 1;
                }
            }
        }
        if tick.is_multiple_of(TICKS_PER_TRUTH_ROW) {
            self.write_truth_row();
        }
        if tick.is_multiple_of(TICKS_PER_SECOND) {
            self.count_second();
        }
    }

    /// At the end of a second of physics: the firmware's motor packets in it, when its stabilizer
    /// ran through all of it, lower [`DroneStats::slowest_second`].
    fn count_second(&mut self) {
        if let Some(at_start) = self.motors_at_second_start {
            let in_second = self.stats.motor_packets - at_start;
            self.stats.slowest_second =
                Some(self.stats.slowest_second.map_or(in_second, |s| s.min(in_second)));
        }
        self.motors_at_second_start =
            (self.stats.motor_packets_since_hello > 0).then_some(self.stats.motor_packets);
    }

    fn write_truth_row(&mut self) {
        let Some(file) = &mut self.truth_file else { return };
        if let Err(e) = file.write_row(&self.quad) {
            self.truth_error = Some((file.path.clone(), e));
            self.truth_file = None;
        }
    }

    /// Flush the truth file; the first error met while writing it, if any.
    pub(super) fn finish(&mut self) -> Option<(PathBuf, io::Error)> {
        if let Some(mut file) = self.truth_file.take()
            && let Err(e) = file.out.flush()
        {
            self.truth_error.get_or_insert((file.path, e));
        }
        self.truth_error.take()
    }
}
