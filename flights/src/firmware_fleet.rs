//! Real Crazyflie firmware for a scenario (`airroads run --link firmware --cf2 PATH`): one firmware
//! process (`cf2`, the crazyflie-firmware SITL build) per UAV on cfsim's physics of a Crazyflie
//! 2.1, standing on the ground at the UAV's start with the UAV's link pointed at it; the physics
//! gives the ground truth the run's margins are measured on.

use anyhow::Context as _;
use cfsim::sitl::firmware::{FirmwareProcesses, StartOptions};
use cfsim::sitl::{SitlConfig, SitlHandle};
use fleet::ValidScenario;
use std::path::{Path, PathBuf};
use uav::{UavState, Vec2};

/// The physics and the firmware processes of a scenario's UAVs (killed when dropped).
pub struct FirmwareFleet {
    /// The physics of every UAV, in the scenario's order.
    pub physics: SitlHandle,
    /// Where each firmware's console is written (`fwN.out`).
    pub run_dir: PathBuf,
    firmware: FirmwareProcesses,
    /// Whether every UAV has been airborne at once (from then on, truth is reported). A cell: a
    /// run reads the truth and the setpoints from two closures at once.
    flown: std::cell::Cell<bool>,
}

impl FirmwareFleet {
    /// Starts the physics and one `cf2` per UAV of `scenario` (each until its stabilizer runs),
    /// and points the UAVs' links at them.
    pub fn start(scenario: &mut ValidScenario, cf2: &Path) -> anyhow::Result<Self> {
        let run_dir =
            std::env::temp_dir().join(format!("airroads-firmware-{}-{}", std::process::id(), scenario.name));
        std::fs::create_dir_all(&run_dir).with_context(|| format!("{}", run_dir.display()))?;
        let config = SitlConfig {
            positions: scenario.uavs.iter().map(|u| [u.start.x, u.start.y, 0.0]).collect(),
            firmware_base_port: 0,
            client_base_port: 0,
            noise: true,
            ..SitlConfig::default()
        };
        let physics = SitlHandle::spawn(config).context("the physics of the firmware")?;
        let firmware = FirmwareProcesses::start(cf2, &physics, &StartOptions::in_dir(&run_dir))
            .with_context(|| format!("starting {} (consoles in {})", cf2.display(), run_dir.display()))?;
        for (i, uav) in scenario.uavs.iter_mut().enumerate() {
            uav.link = Some(physics.uri(i).context("a drone per UAV")?);
        }
        Ok(Self { physics, run_dir, firmware, flown: Default::default() })
    }

    /// Every UAV's true horizontal state, in the scenario's order: `None` for one below
    /// `airborne_m` (on the ground, taking off, landing or fallen: it has no margins); `None`
    /// altogether until every UAV has been above it once (the margins are for flight).
    pub fn truth(&self, airborne_m: f64) -> Option<Vec<Option<UavState>>> {
        let states: Vec<Option<UavState>> = (0..self.physics.len())
            .map(|i| {
                let t = self.physics.truth(i)?;
                (t.position[2] > airborne_m).then(|| UavState {
                    p: Vec2::new(t.position[0], t.position[1]),
                    v: Vec2::new(t.velocity[0], t.velocity[1]),
                })
            })
            .collect();
        self.flown.set(self.flown.get() || states.iter().all(Option::is_some));
        self.flown.get().then_some(states)
    }

    /// Kills UAV `i`'s firmware (a firmware that dies in flight).
    pub fn kill(&mut self, i: usize) {
        self.firmware.kill(i);
    }

    /// Freezes UAV `i`'s firmware (SIGSTOP: a hung microcontroller); it stays frozen until the
    /// fleet is dropped.
    pub fn freeze(&self, i: usize) -> std::io::Result<()> {
        let pid = self.firmware.pid(i).and_then(|p| rustix::process::Pid::from_raw(p as i32));
        let pid = pid.ok_or_else(|| std::io::Error::other(format!("firmware {i} is not running")))?;
        rustix::process::kill_process(pid, rustix::process::Signal::STOP)?;
        Ok(())
    }

    /// Motor packets received from each UAV's firmware so far (500 per second from an idle
    /// machine's firmware), with the time they were read.
    pub fn motor_packets(&self) -> (std::time::Instant, Vec<u64>) {
        let now = std::time::Instant::now();
        (now, (0..self.physics.len()).map(|i| self.physics.stats(i).map_or(0, |s| s.motor_packets)).collect())
    }

    /// Each UAV's motor commands per second since `since` (an earlier [`Self::motor_packets`]).
    pub fn motor_rates_since(&self, since: &(std::time::Instant, Vec<u64>)) -> Vec<f64> {
        let (now, after) = self.motor_packets();
        let seconds = (now - since.0).as_secs_f64().max(1e-9);
        after.iter().zip(&since.1).map(|(a, b)| (a - b) as f64 / seconds).collect()
    }

    /// The fewest motor packets any UAV's firmware sent in one second of physics since its
    /// stabilizer started (500 at its pace; `None` before a whole second).
    pub fn slowest_second(&self) -> Option<u64> {
        (0..self.physics.len()).filter_map(|i| self.physics.stats(i)?.slowest_second).min()
    }

    /// Times the physics cut a firmware's spinning motors after 100 ms without a motor packet, over
    /// every UAV (a firmware silent in flight: it fell).
    pub fn motor_cuts(&self) -> u64 {
        (0..self.physics.len()).filter_map(|i| self.physics.stats(i)).map(|s| s.motor_watchdog_cuts).sum()
    }

    /// Setpoints relayed to each UAV's firmware so far, and when the last one was.
    pub fn setpoints(&self) -> Vec<(u64, Option<std::time::Instant>)> {
        (0..self.physics.len())
            .map(|i| self.physics.stats(i).map_or((0, None), |s| (s.setpoints, s.last_setpoint)))
            .collect()
    }

    /// How often the firmware consoles said their own loops were late so far: the stabilizer's and
    /// the Kalman filter's rate supervisors (`... rate is off`), summed over every UAV. An idle
    /// machine shows a few at start (the POSIX port's emulated clock).
    pub fn rate_warnings(&self) -> usize {
        (0..self.physics.len())
            .filter_map(|i| std::fs::read_to_string(self.run_dir.join(format!("fw{i}.out"))).ok())
            .map(|console| {
                console.lines().filter(|l| l.contains("rate is off") || l.contains("rate off")).count()
            })
            .sum()
    }
}
