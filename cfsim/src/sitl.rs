//! The physics side of the Crazyflie firmware's software-in-the-loop (SITL) build: N drones in
//! one process, each a [`Quadrotor`] that a real `cf2` firmware process flies over UDP.
//!
//! Per drone N: a firmware socket on `firmware_base_port + N` and a client socket on
//! `client_base_port + N` (127.0.0.1 by default).
//! - The firmware repeats a hello (`0xF3`) until it is answered with the same byte; a new hello is
//!   accepted at any time, so a restarted firmware reconnects.
//! - The physics sends the firmware the IMU at 1 kHz and the barometer at 50 Hz (CRTP port 10,
//!   channel 0) and an external pose (localization port, `EXT_POSE`) at `pose_hz`; the firmware
//!   answers with motor PWM on port 10. Every other datagram of the firmware goes to the client.
//! - Every datagram from the client goes to the firmware, null packets included (not answered,
//!   like the real firmware, unless [`SitlConfig::answer_null`]); its sender becomes the client.
//!   `0xF3` alone registers a client and `0xF4` forgets it (CrazySim's conventions).
//!
//! All drones step in one loop on one thread, paced by the wall clock at 1 kHz; it catches up
//! after short delays and starts again from now after one of more than 100 ms.
//! [`SitlHandle`] reads each drone's ground truth and counters and switches faults at run time.

mod drone;
pub mod firmware;
pub mod pace;
mod run;
pub mod wire;

use std::io;
use std::net::{IpAddr, Ipv4Addr, SocketAddr, UdpSocket};
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, MutexGuard, PoisonError};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use crate::faults::Prng;
use crate::quadrotor::{GroundTruth, ImuNoise, QuadParams, Quadrotor};
use drone::{Drone, TruthFile};

/// The physics period: 1 ms.
pub const PHYSICS_STEP: Duration = Duration::from_millis(1);
/// Falling further behind the wall clock than this restarts the pacing from now.
const MAX_LAG: Duration = Duration::from_millis(100);

/// Errors starting or stopping the simulator.
#[derive(Debug, thiserror::Error)]
pub enum SitlError {
    /// The configuration has no drone.
    #[error("no drones to simulate")]
    NoDrones,
    /// A drone's port would be past 65535.
    #[error("drone {index}: port {base} + {index} is past 65535")]
    PortRange {
        /// First port of the range.
        base: u16,
        /// The drone.
        index: usize,
    },
    /// The pose rate is not a number from 0 to 1000.
    #[error("pose rate {0} Hz is not in 0..=1000")]
    PoseRate(f64),
    /// A socket could not be bound.
    #[error("cannot bind {addr}: {source}")]
    Bind {
        /// The address.
        addr: SocketAddr,
        /// Why.
        source: io::Error,
    },
    /// A socket could not be set up after binding.
    #[error("cannot set up the socket of drone {index}: {source}")]
    Socket {
        /// The drone.
        index: usize,
        /// Why.
        source: io::Error,
    },
    /// A ground-truth file could not be created or written.
    #[error("ground truth file {path}: {source}")]
    Truth {
        /// The file.
        path: PathBuf,
        /// Why.
        source: io::Error,
    },
    /// The simulation thread could not be started.
    #[error("cannot start the simulation thread: {0}")]
    Thread(io::Error),
    /// The simulation thread panicked.
    #[error("the simulation thread panicked")]
    Panicked,
}

/// Faults of one drone, changeable at run time with [`SitlHandle::set_faults`].
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct SitlFaults {
    /// Fraction in [0, 1] of datagrams between client and firmware dropped, in each direction
    /// (decided by a PRNG seeded from [`SitlConfig::seed`]).
    pub link_loss: f64,
    /// A motion-capture gap: no external pose from `.0` to `.1` after the simulator started.
    pub pose_gap: Option<(Duration, Duration)>,
    /// Wind gust: a force in the world frame (N) on the drone.
    pub wind_force: [f64; 3],
}

impl SitlFaults {
    /// Whether a datagram of the relay is dropped, drawing from `rng` only when needed.
    fn drops(&self, rng: &mut Prng) -> bool {
        let p = self.link_loss;
        // NaN or <= 0 never drops; >= 1 always drops.
        !(p.is_nan() || p <= 0.0) && (p >= 1.0 || rng.next_f64() < p)
    }

    /// Whether the pose is sent `elapsed` seconds after the start.
    fn pose_sent_at(&self, elapsed: f64) -> bool {
        match self.pose_gap {
            Some((from, to)) => !(from.as_secs_f64() <= elapsed && elapsed < to.as_secs_f64()),
            None => true,
        }
    }
}

/// Settings of the simulator.
#[derive(Debug, Clone, PartialEq)]
pub struct SitlConfig {
    /// Start position of each drone (m), one drone per entry; z = 0 is on the floor.
    pub positions: Vec<[f64; 3]>,
    /// Address both sockets of every drone bind to.
    pub host: IpAddr,
    /// Firmware port of drone 0; drone N uses this + N. 0 binds ephemeral ports (see
    /// [`SitlHandle::firmware_addr`]).
    pub firmware_base_port: u16,
    /// Client port of drone 0; drone N uses this + N. 0 binds ephemeral ports.
    pub client_base_port: u16,
    /// Rate of the external pose sent to the firmware (Hz); 0 sends none.
    pub pose_hz: f64,
    /// Folder for one ground-truth CSV per drone (`truthN.csv`, 100 Hz), or none.
    pub truth_dir: Option<PathBuf>,
    /// Add IMU noise ([`ImuNoise::bmi088`]).
    pub noise: bool,
    /// Seed of the PRNGs of IMU noise and link loss (drone N uses seed + N).
    pub seed: u64,
    /// Answer each null packet from the client with a null packet (a radio's acknowledgement).
    pub answer_null: bool,
    /// Physical parameters of every drone.
    pub params: QuadParams,
    /// Faults of every drone from the start.
    pub faults: SitlFaults,
}

impl Default for SitlConfig {
    fn default() -> Self {
        Self {
            positions: vec![[0.0; 3]],
            host: IpAddr::V4(Ipv4Addr::LOCALHOST),
            firmware_base_port: 19950,
            client_base_port: 19850,
            pose_hz: 200.0,
            truth_dir: None,
            noise: false,
            seed: 0x00c0_ffee,
            answer_null: false,
            params: QuadParams::CRAZYFLIE_2_1,
            faults: SitlFaults::default(),
        }
    }
}

/// Datagram counters of one drone.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct DroneStats {
    /// Hellos answered (firmware starts and restarts).
    pub hellos: u64,
    /// The firmware that said hello last.
    pub firmware: Option<SocketAddr>,
    /// The current client.
    pub client: Option<SocketAddr>,
    /// Motor packets received.
    pub motor_packets: u64,
    /// Motor packets received since the last hello (0: the stabilizer has not run yet).
    pub motor_packets_since_hello: u64,
    /// The fewest motor packets the firmware sent in one second of physics (1000 ticks) since its
    /// stabilizer started, over the whole seconds it ran through (none yet: `None`). 500 on an
    /// idle machine; far less is a firmware that did not run in real time (a loaded host, or its
    /// FreeRTOS POSIX port stalling: [`pace`]) or one that stopped (killed, frozen).
    pub slowest_second: Option<u64>,
    /// Times the motors were stopped because the firmware sent no motor packet for 100 ms (a
    /// killed or frozen firmware; a real Crazyflie's watchdog resets it).
    pub motor_watchdog_cuts: u64,
    /// The longest the firmware went without a motor packet while the motors spun (physics ticks,
    /// ms; 2 at its pace, more when the firmware or the physics ran late).
    pub longest_motor_gap: u64,
    /// Datagrams relayed from the firmware to the client.
    pub to_client: u64,
    /// Datagrams relayed from the client to the firmware.
    pub to_firmware: u64,
    /// Generic setpoints (CRTP port 7) among them.
    pub setpoints: u64,
    /// When the last of those was relayed (the loop reads its sockets every physics tick, 1 ms).
    pub last_setpoint: Option<Instant>,
    /// Relayed datagrams dropped towards the client by [`SitlFaults::link_loss`].
    pub dropped_to_client: u64,
    /// Relayed datagrams dropped towards the firmware by [`SitlFaults::link_loss`].
    pub dropped_to_firmware: u64,
    /// Null packets answered ([`SitlConfig::answer_null`]).
    pub nulls_answered: u64,
    /// IMU packets sent.
    pub imu_sent: u64,
    /// Barometer packets sent.
    pub baro_sent: u64,
    /// External poses sent.
    pub pose_sent: u64,
    /// Datagrams ignored: from a stranger on the firmware socket, or with nowhere to go.
    pub ignored: u64,
    /// Failed sends.
    pub send_errors: u64,
    /// Failed receives.
    pub receive_errors: u64,
}

/// How well the loop keeps up with the wall clock.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct LoopStats {
    /// Physics ticks run.
    pub ticks: u64,
    /// Wall time since the loop started.
    pub elapsed: Duration,
    /// Wall time spent working (the rest is sleep).
    pub busy: Duration,
    /// The longest single tick of work.
    pub longest_tick: Duration,
    /// Times the loop fell more than 100 ms behind and dropped the lost time.
    pub resyncs: u64,
}

impl LoopStats {
    /// Physics ticks per wall-clock second (1000 when keeping up).
    pub fn physics_rate_hz(&self) -> f64 {
        let s = self.elapsed.as_secs_f64();
        if s > 0.0 { self.ticks as f64 / s } else { 0.0 }
    }

    /// Fraction of wall time spent working.
    pub fn load(&self) -> f64 {
        let s = self.elapsed.as_secs_f64();
        if s > 0.0 { self.busy.as_secs_f64() / s } else { 0.0 }
    }
}

/// What the loop shares with the handle about one drone.
#[derive(Debug, Clone, Copy)]
struct DroneView {
    truth: GroundTruth,
    stats: DroneStats,
    faults: SitlFaults,
}

struct Shared {
    stop: AtomicBool,
    start: Instant,
    drones: Vec<Mutex<DroneView>>,
    loop_stats: Mutex<LoopStats>,
}

/// Lock ignoring poisoning: the values stay meaningful even if a holder panicked.
fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(PoisonError::into_inner)
}

/// The running simulator: read ground truth and counters, switch faults, stop it.
///
/// Dropping the handle stops the simulation thread.
pub struct SitlHandle {
    shared: Arc<Shared>,
    firmware_addrs: Vec<SocketAddr>,
    client_addrs: Vec<SocketAddr>,
    thread: Option<JoinHandle<Result<(), SitlError>>>,
}

impl SitlHandle {
    /// Bind every socket, create the truth files and start the simulation thread.
    pub fn spawn(config: SitlConfig) -> Result<Self, SitlError> {
        if config.positions.is_empty() {
            return Err(SitlError::NoDrones);
        }
        if !(0.0..=1000.0).contains(&config.pose_hz) {
            return Err(SitlError::PoseRate(config.pose_hz));
        }
        let mut drones = Vec::with_capacity(config.positions.len());
        for (index, &position) in config.positions.iter().enumerate() {
            drones.push(make_drone(&config, index, position)?);
        }
        let addr =
            |s: &UdpSocket, index| s.local_addr().map_err(|source| SitlError::Socket { index, source });
        let mut firmware_addrs = Vec::new();
        let mut client_addrs = Vec::new();
        for (index, d) in drones.iter().enumerate() {
            firmware_addrs.push(addr(&d.firmware_socket, index)?);
            client_addrs.push(addr(&d.client_socket, index)?);
        }
        let views = drones
            .iter()
            .map(|d| Mutex::new(DroneView { truth: d.quad.truth(), stats: d.stats, faults: config.faults }))
            .collect();
        let shared = Arc::new(Shared {
            stop: AtomicBool::new(false),
            start: Instant::now(),
            drones: views,
            loop_stats: Mutex::new(LoopStats::default()),
        });
        let pose_hz = config.pose_hz;
        let loop_shared = shared.clone();
        let thread = std::thread::Builder::new()
            .name("cfsim-sitl".to_owned())
            .spawn(move || run::run(drones, &loop_shared, pose_hz))
            .map_err(SitlError::Thread)?;
        Ok(Self { shared, firmware_addrs, client_addrs, thread: Some(thread) })
    }

    /// Number of drones.
    pub fn len(&self) -> usize {
        self.client_addrs.len()
    }

    /// Always false: a simulator has at least one drone.
    pub fn is_empty(&self) -> bool {
        self.client_addrs.is_empty()
    }

    /// The address drone `index`'s firmware sends to (`cf2 PORT`).
    pub fn firmware_addr(&self, index: usize) -> Option<SocketAddr> {
        self.firmware_addrs.get(index).copied()
    }

    /// The address a client of drone `index` talks to.
    pub fn client_addr(&self, index: usize) -> Option<SocketAddr> {
        self.client_addrs.get(index).copied()
    }

    /// The link URI of drone `index` (`udp://127.0.0.1:19850`).
    pub fn uri(&self, index: usize) -> Option<String> {
        self.client_addr(index).map(|a| format!("udp://{a}"))
    }

    /// Drone `index`'s ground truth after the last physics tick.
    pub fn truth(&self, index: usize) -> Option<GroundTruth> {
        self.shared.drones.get(index).map(|v| lock(v).truth)
    }

    /// Drone `index`'s datagram counters.
    pub fn stats(&self, index: usize) -> Option<DroneStats> {
        self.shared.drones.get(index).map(|v| lock(v).stats)
    }

    /// Drone `index`'s faults.
    pub fn faults(&self, index: usize) -> Option<SitlFaults> {
        self.shared.drones.get(index).map(|v| lock(v).faults)
    }

    /// Replace drone `index`'s faults from the next tick on; false if there is no such drone.
    pub fn set_faults(&self, index: usize, faults: SitlFaults) -> bool {
        self.shared.drones.get(index).map(|v| lock(v).faults = faults).is_some()
    }

    /// Wall time since the simulator started (the clock of [`SitlFaults::pose_gap`]).
    pub fn elapsed(&self) -> Duration {
        self.shared.start.elapsed()
    }

    /// How well the loop keeps up with real time.
    pub fn loop_stats(&self) -> LoopStats {
        *lock(&self.shared.loop_stats)
    }

    /// Stop the loop, flush the truth files and report the first error writing one.
    pub fn shutdown(mut self) -> Result<(), SitlError> {
        self.stop()
    }

    fn stop(&mut self) -> Result<(), SitlError> {
        self.shared.stop.store(true, Ordering::Relaxed);
        match self.thread.take() {
            Some(thread) => thread.join().map_err(|_| SitlError::Panicked)?,
            None => Ok(()),
        }
    }
}

impl Drop for SitlHandle {
    fn drop(&mut self) {
        // Errors are reported by `shutdown`; a dropped handle only stops the thread.
        let _ = self.stop();
    }
}

/// Bind drone `index`'s sockets and build its model.
fn make_drone(config: &SitlConfig, index: usize, position: [f64; 3]) -> Result<Drone, SitlError> {
    let port = |base: u16| -> Result<u16, SitlError> {
        if base == 0 {
            return Ok(0);
        }
        u16::try_from(usize::from(base) + index).map_err(|_| SitlError::PortRange { base, index })
    };
    let bind = |port: u16| {
        let addr = SocketAddr::new(config.host, port);
        UdpSocket::bind(addr).map_err(|source| SitlError::Bind { addr, source })
    };
    let firmware_socket = bind(port(config.firmware_base_port)?)?;
    let client_socket = bind(port(config.client_base_port)?)?;
    let seed = config.seed.wrapping_add(index as u64);
    let noise = config.noise.then(|| ImuNoise::bmi088(seed));
    let truth_file = match &config.truth_dir {
        Some(dir) => {
            let path = dir.join(format!("truth{index}.csv"));
            Some(TruthFile::create(path.clone()).map_err(|source| SitlError::Truth { path, source })?)
        }
        None => None,
    };
    let quad = Quadrotor::new(config.params, position);
    // A different stream from the noise's: the loss decisions must not shift the noise.
    let loss_seed = seed ^ 0x5eed_1055;
    Drone::new(firmware_socket, client_socket, quad, noise, loss_seed, config.answer_null, truth_file)
        .map_err(|source| SitlError::Socket { index, source })
}
