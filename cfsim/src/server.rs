//! The UDP side: one raw CRTP packet per datagram, the tasks that run a simulated Crazyflie,
//! and the handle to observe and disturb it.
//!
//! Connection convention (CrazySim's cflib fork, `cflib/crtp/udpdriver.py`): the client sends
//! the single byte `0xF3` when it connects and `0xF4` when it closes. Upstream cflib's UDP driver
//! sends nothing on connect and probes ports 19850.. with a null packet (`0xFF`), expecting any
//! answer. Like the real firmware, the simulator does not answer null packets (port 15, channel
//! 3) unless [`SimConfig::answer_null`] (`cfsim --answer-null`): then with an empty one (`0xF3`,
//! what the radio returns as an empty acknowledgement), which cflib's scan needs. A client that
//! wants an answer asks for one the firmware gives (a link echo). Answers go to the address of the
//! last client datagram.

use std::io;
use std::net::SocketAddr;
use std::sync::{Arc, Mutex, MutexGuard, PoisonError};
use std::time::{Duration, Instant};

use tokio::net::UdpSocket;
use tokio::sync::{mpsc, watch};
use tokio::task::JoinHandle;

use crate::crtp::Packet;
use crate::dynamics::Gains;
use crate::faults::{Faults, Prng};
use crate::firmware::{Firmware, FirmwareSettings};
use crate::flight::FlightMode;

/// Datagram sent by a CrazySim-style client when it connects.
pub const CONNECT_DATAGRAM: u8 = 0xf3;
/// Datagram sent by a CrazySim-style client when it closes.
pub const CLOSE_DATAGRAM: u8 = 0xf4;

/// Settings of one simulated Crazyflie.
#[derive(Debug, Clone, PartialEq)]
pub struct SimConfig {
    /// Starting position (m); z is normally 0 (on the ground).
    pub initial_position: [f64; 3],
    /// Bound on the commanded acceleration norm (m/s²).
    pub max_accel: f64,
    /// Bound on the velocity commanded by the position loop (m/s).
    pub max_speed: f64,
    /// Position loop gain (1/s).
    pub position_gain: f64,
    /// Velocity loop gain (1/s).
    pub velocity_gain: f64,
    /// Fixed integration step.
    pub step: Duration,
    /// How often the simulation task wakes up to integrate and send log data.
    pub tick: Duration,
    /// Seed of the PRNG that decides packet loss.
    pub seed: u64,
    /// Faults active from the start.
    pub faults: Faults,
    /// Firmware version string reported on the platform port.
    pub firmware_version: String,
    /// Without any datagram for this long the firmware considers the link lost (resets logging).
    pub link_timeout: Duration,
    /// Wait for an arming request before the motors may run (a firmware built with
    /// `CONFIG_MOTORS_REQUIRE_ARMING`); by default it arms itself, like a Crazyflie 2.1.
    pub require_arming: bool,
    /// Answer null packets with an empty one (what cflib's UDP scan needs); the real firmware does
    /// not, and neither does the simulator by default.
    pub answer_null: bool,
}

impl Default for SimConfig {
    fn default() -> Self {
        Self {
            initial_position: [0.0; 3],
            max_accel: 4.0,
            max_speed: 3.0,
            position_gain: 2.0,
            velocity_gain: 8.0,
            step: Duration::from_millis(2),
            tick: Duration::from_millis(5),
            seed: 0x00c0_ffee,
            faults: Faults::NONE,
            firmware_version: "2025.12 (cfsim)".to_owned(),
            link_timeout: Duration::from_secs(1),
            require_arming: false,
            answer_null: false,
        }
    }
}

/// The simulated ground truth (the simulated estimate equals it).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Truth {
    /// Simulation time since boot.
    pub time: Duration,
    /// Position (m).
    pub position: [f64; 3],
    /// Velocity (m/s).
    pub velocity: [f64; 3],
    /// Acceleration applied in the last step (m/s²).
    pub acceleration: [f64; 3],
    /// Whether the motors are on.
    pub motors_on: bool,
    /// What drives the Crazyflie.
    pub mode: FlightMode,
    /// Number of log blocks defined by the client.
    pub log_blocks: usize,
}

/// Datagram counters.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct LinkStats {
    /// Datagrams received and processed.
    pub received: u64,
    /// Datagrams from the client dropped by fault injection.
    pub dropped_up: u64,
    /// Datagrams sent to the client.
    pub sent: u64,
    /// Datagrams to the client dropped by fault injection (or with no client known).
    pub dropped_down: u64,
    /// Generic setpoints (port 7, channel 0) processed.
    pub setpoints: u64,
    /// When the last generic setpoint was processed (for latency measurements).
    pub last_setpoint: Option<Instant>,
    /// Emergency-stop packets received (supervisor or localization port), obeyed or not.
    pub emergency_stops: u64,
    /// Emergency-stop packets ignored because of [`Faults::ignore_stop`].
    pub stops_ignored: u64,
}

struct Shared {
    fw: Mutex<Firmware>,
    faults: Mutex<Faults>,
    rng: Mutex<Prng>,
    client: Mutex<Option<SocketAddr>>,
    stats: Mutex<LinkStats>,
    start: Instant,
}

/// Lock ignoring poisoning: the state stays usable even if a task panicked while holding it.
fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(PoisonError::into_inner)
}

impl Shared {
    fn now(&self) -> f64 {
        self.start.elapsed().as_secs_f64()
    }

    fn drops(&self, up: bool) -> bool {
        let faults = *lock(&self.faults);
        faults.drops(up, &mut lock(&self.rng))
    }
}

/// Entry point: spawns simulated Crazyflies.
#[derive(Debug, Clone, Copy)]
pub struct SimCrazyflie;

impl SimCrazyflie {
    /// Bind `bind` (port 0 for any) and run a simulated Crazyflie on the current tokio runtime.
    ///
    /// Fails if the address cannot be bound or if called outside a tokio runtime.
    pub fn spawn(bind: SocketAddr, config: SimConfig) -> io::Result<SimHandle> {
        if tokio::runtime::Handle::try_current().is_err() {
            return Err(io::Error::other("SimCrazyflie::spawn needs a tokio runtime"));
        }
        let std_socket = std::net::UdpSocket::bind(bind)?;
        std_socket.set_nonblocking(true)?;
        let socket = Arc::new(UdpSocket::from_std(std_socket)?);
        let addr = socket.local_addr()?;
        let step = config.step.as_secs_f64().max(1e-4);
        let settings = FirmwareSettings {
            initial_position: config.initial_position,
            gains: Gains {
                kp: config.position_gain,
                kv: config.velocity_gain,
                max_accel: config.max_accel,
                max_speed: config.max_speed,
            },
            step,
            version: config.firmware_version.clone(),
            link_timeout: config.link_timeout.as_secs_f64(),
            auto_arm: !config.require_arming,
            answer_null: config.answer_null,
        };
        let shared = Arc::new(Shared {
            fw: Mutex::new(Firmware::new(settings)),
            faults: Mutex::new(config.faults),
            rng: Mutex::new(Prng::new(config.seed)),
            client: Mutex::new(None),
            stats: Mutex::new(LinkStats::default()),
            start: Instant::now(),
        });
        let (stop_tx, stop_rx) = watch::channel(false);
        let (up_tx, up_rx) = mpsc::unbounded_channel();
        let (down_tx, down_rx) = mpsc::unbounded_channel();
        let tick = config.tick.max(Duration::from_millis(1));
        let tasks = vec![
            tokio::spawn(receive(socket.clone(), shared.clone(), up_tx, stop_rx.clone())),
            tokio::spawn(process(shared.clone(), up_rx, down_tx.clone(), stop_rx.clone())),
            tokio::spawn(simulate(shared.clone(), tick, down_tx, stop_rx.clone())),
            tokio::spawn(transmit(socket, shared.clone(), down_rx, stop_rx)),
        ];
        Ok(SimHandle { addr, shared, stop: stop_tx, tasks })
    }
}

/// Handle on a running simulated Crazyflie; dropping it stops the simulation.
pub struct SimHandle {
    addr: SocketAddr,
    shared: Arc<Shared>,
    stop: watch::Sender<bool>,
    tasks: Vec<JoinHandle<()>>,
}

impl std::fmt::Debug for SimHandle {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SimHandle").field("addr", &self.addr).finish_non_exhaustive()
    }
}

impl SimHandle {
    /// The bound UDP address.
    pub fn addr(&self) -> SocketAddr {
        self.addr
    }

    /// The URI a client uses to connect (`udp://HOST:PORT`).
    pub fn uri(&self) -> String {
        format!("udp://{}", self.addr)
    }

    /// The ground truth as of the last simulation tick (at most one tick old).
    pub fn truth(&self) -> Truth {
        let fw = lock(&self.shared.fw);
        let b = fw.flight.body;
        Truth {
            time: Duration::from_secs_f64(fw.time()),
            position: b.p,
            velocity: b.v,
            acceleration: b.a,
            motors_on: fw.flight.motors_on,
            mode: fw.flight.mode,
            log_blocks: fw.log.block_count(),
        }
    }

    /// The last external position received on the localization port.
    pub fn last_external_position(&self) -> Option<[f32; 3]> {
        lock(&self.shared.fw).flight.external
    }

    /// How many external positions were received.
    pub fn external_position_count(&self) -> u64 {
        lock(&self.shared.fw).flight.external_count
    }

    /// The value of the param `group.name`, as the firmware holds it.
    pub fn param(&self, name: &str) -> Option<f64> {
        let (group, var) = name.split_once('.')?;
        lock(&self.shared.fw).params.get(group, var)
    }

    /// Replace the active faults.
    pub fn set_faults(&self, faults: Faults) {
        *lock(&self.shared.faults) = faults;
    }

    /// The active faults.
    pub fn faults(&self) -> Faults {
        *lock(&self.shared.faults)
    }

    /// Datagram counters.
    pub fn stats(&self) -> LinkStats {
        *lock(&self.shared.stats)
    }

    /// The address answers go to (the source of the last client datagram).
    pub fn client(&self) -> Option<SocketAddr> {
        *lock(&self.shared.client)
    }

    /// Simulate a reboot: clears an emergency-stop lock, setpoints, log blocks, the supervisor
    /// (disarmed unless it auto-arms) and the estimator; the Crazyflie stays where it is.
    pub fn reboot(&self) {
        lock(&self.shared.fw).reboot();
    }

    /// The supervisor bitfield (`supervisor.info`) as of the last simulation tick.
    pub fn supervisor_bits(&self) -> u16 {
        lock(&self.shared.fw).supervisor_bits()
    }

    /// Stop the simulation and wait for its tasks to end.
    pub async fn shutdown(mut self) {
        self.stop.send_replace(true);
        for task in self.tasks.drain(..) {
            let _ = task.await;
        }
    }
}

impl Drop for SimHandle {
    fn drop(&mut self) {
        self.stop.send_replace(true);
    }
}

/// Resolves when the stop flag is set (or its sender is gone).
async fn stopped(stop: &mut watch::Receiver<bool>) {
    let _ = stop.wait_for(|s| *s).await;
}

type Uplink = (Instant, SocketAddr, Vec<u8>);

async fn receive(
    socket: Arc<UdpSocket>,
    shared: Arc<Shared>,
    up: mpsc::UnboundedSender<Uplink>,
    mut stop: watch::Receiver<bool>,
) {
    let mut buf = vec![0u8; 2048];
    loop {
        let (n, from) = tokio::select! {
            _ = stopped(&mut stop) => return,
            r = socket.recv_from(&mut buf) => match r {
                Ok(x) => x,
                Err(_) => {
                    // Transient socket errors (e.g. ICMP reports): keep serving.
                    tokio::time::sleep(Duration::from_millis(1)).await;
                    continue;
                }
            },
        };
        if shared.drops(true) {
            lock(&shared.stats).dropped_up += 1;
            continue;
        }
        let latency = lock(&shared.faults).latency_up;
        if up.send((Instant::now() + latency, from, buf[..n].to_vec())).is_err() {
            return;
        }
    }
}

async fn process(
    shared: Arc<Shared>,
    mut up: mpsc::UnboundedReceiver<Uplink>,
    down: mpsc::UnboundedSender<(Instant, Vec<u8>)>,
    mut stop: watch::Receiver<bool>,
) {
    loop {
        let (due, from, datagram) = tokio::select! {
            _ = stopped(&mut stop) => return,
            item = up.recv() => match item { Some(x) => x, None => return },
        };
        tokio::time::sleep_until(due.into()).await;
        lock(&shared.stats).received += 1;
        let answers = {
            let now = shared.now();
            let mut fw = lock(&shared.fw);
            let mut answers: Vec<Packet> = fw.advance_to(now);
            if datagram == [CLOSE_DATAGRAM] {
                *lock(&shared.client) = None;
                fw.on_disconnect();
            } else {
                *lock(&shared.client) = Some(from);
                if datagram == [CONNECT_DATAGRAM] {
                    answers.extend(fw.on_connect());
                } else if let Some(pk) = Packet::parse(&datagram) {
                    if pk.port == crate::crtp::PORT_SETPOINT_GENERIC && pk.channel == 0 {
                        let mut stats = lock(&shared.stats);
                        stats.setpoints += 1;
                        stats.last_setpoint = Some(Instant::now());
                    }
                    let command = crate::commands::decode(&pk);
                    let ignored = command.is_some_and(|c| lock(&shared.faults).ignores(&c));
                    if command == Some(crate::commands::Command::EmergencyStop) {
                        let mut stats = lock(&shared.stats);
                        stats.emergency_stops += 1;
                        stats.stops_ignored += u64::from(ignored);
                    }
                    if !ignored {
                        answers.extend(fw.handle(&pk));
                    }
                }
            }
            answers
        };
        let now = Instant::now();
        for pk in answers {
            if down.send((now, pk.to_datagram())).is_err() {
                return;
            }
        }
    }
}

async fn simulate(
    shared: Arc<Shared>,
    tick: Duration,
    down: mpsc::UnboundedSender<(Instant, Vec<u8>)>,
    mut stop: watch::Receiver<bool>,
) {
    let mut interval = tokio::time::interval(tick);
    interval.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Skip);
    loop {
        tokio::select! {
            _ = stopped(&mut stop) => return,
            _ = interval.tick() => {}
        }
        let packets = {
            let now = shared.now();
            lock(&shared.fw).advance_to(now)
        };
        let now = Instant::now();
        for pk in packets {
            if down.send((now, pk.to_datagram())).is_err() {
                return;
            }
        }
    }
}

async fn transmit(
    socket: Arc<UdpSocket>,
    shared: Arc<Shared>,
    mut down: mpsc::UnboundedReceiver<(Instant, Vec<u8>)>,
    mut stop: watch::Receiver<bool>,
) {
    loop {
        let (queued, datagram) = tokio::select! {
            _ = stopped(&mut stop) => return,
            item = down.recv() => match item { Some(x) => x, None => return },
        };
        let client = *lock(&shared.client);
        let Some(client) = client.filter(|_| !shared.drops(false)) else {
            lock(&shared.stats).dropped_down += 1;
            continue;
        };
        let latency = lock(&shared.faults).latency_down;
        tokio::time::sleep_until((queued + latency).into()).await;
        if socket.send_to(&datagram, client).await.is_ok() {
            lock(&shared.stats).sent += 1;
        }
    }
}
