//! Where commands go and states come from. The fleet loop talks to every UAV through [`Link`]; this
//! crate has the in-process simulator, and hardware links (the `crazyflie` crate's CRTP relay) slot
//! in beside it. A fleet may mix links.

pub mod schema;
pub mod uri;

use uav::{UavState, Vec2};
pub use uri::{LinkError, LinkRules, LinkUri, parse_link};

/// The link of a UAV that names none: the in-process simulator.
pub const SIM_LINK: &str = "sim";

/// What a UAV's own firmware reports about itself (Crazyflies; in-process UAVs report nothing).
/// Each field is `None` until the firmware has said it (or when it does not log it).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct VehicleReport {
    /// The supervisor's state bitfield (`supervisor.info`: armed, flying, tumbled, locked, ...).
    pub supervisor_info: Option<u16>,
    /// Battery voltage (V, `pm.vbat`).
    pub battery_v: Option<f64>,
    /// Fraction of the expected state samples that arrived over the last second (0–1).
    pub link_quality: Option<f64>,
}

/// Checks a link name with the default [`LinkRules`] (UDP peers on loopback only): `sim`, or a
/// Crazyflie URI (`radio://DEV/CHANNEL/RATE/ADDRESS`, `usb://SERIAL`, `udp://HOST:PORT`; see
/// [`uri`] for the exact forms). The error says what is wrong, e.g.
/// `udp://127.0.0.1:99999: port 99999 is not in 1..=65535`.
pub fn check_link(link: &str) -> Result<(), String> {
    check_link_with(link, &LinkRules::default())
}

/// Checks a link name as [`check_link`] does, with `rules` saying which UDP hosts beyond loopback
/// are allowed.
pub fn check_link_with(link: &str, rules: &LinkRules) -> Result<(), String> {
    parse_link(link, rules).map(drop).map_err(|e| e.to_string())
}

/// Where a linked UAV is in its flight, as its link sees it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum LinkPhase {
    /// Connecting, or reconnecting after a loss; no command reaches the UAV yet.
    Connecting,
    /// Connected and taking off to the flight altitude; commands are not followed yet.
    TakingOff,
    /// Airborne and following each tick's command.
    #[default]
    Flying,
    /// Landing on request (or on shutdown), until the UAV reports it is down with its motors off.
    Landing,
    /// On the ground with motors off after a landing, as the UAV itself reported.
    Landed,
    /// Motors cut by an emergency stop, as the UAV itself confirmed; stays down until the server
    /// restarts the link.
    Stopped,
    /// An emergency stop was requested (and is being resent) but the UAV has not confirmed yet
    /// that its motors are off: it may still be in the air.
    Stopping,
}

impl LinkPhase {
    /// Every phase, in declaration order.
    pub const ALL: [LinkPhase; 7] = [
        LinkPhase::Connecting,
        LinkPhase::TakingOff,
        LinkPhase::Flying,
        LinkPhase::Landing,
        LinkPhase::Landed,
        LinkPhase::Stopped,
        LinkPhase::Stopping,
    ];

    /// The JSON/CLI name.
    pub fn name(&self) -> &'static str {
        match self {
            LinkPhase::Connecting => "connecting",
            LinkPhase::TakingOff => "taking_off",
            LinkPhase::Flying => "flying",
            LinkPhase::Landing => "landing",
            LinkPhase::Landed => "landed",
            LinkPhase::Stopped => "stopped",
            LinkPhase::Stopping => "stopping",
        }
    }

    /// The phase called `name` ([`LinkPhase::name`]), if any.
    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|p| p.name() == name)
    }

    /// The UAV is in the air at the fleet's altitude (or on its way there or down, or not yet
    /// confirmed down after an emergency stop): an obstacle.
    pub fn airborne(&self) -> bool {
        matches!(self, LinkPhase::TakingOff | LinkPhase::Flying | LinkPhase::Landing | LinkPhase::Stopping)
    }
}

/// The connection to one UAV. Implementations never block the caller: the fleet loop calls them
/// every tick and must not wait on a radio or a socket. `Sync` so that the fleet's read-only passes
/// (the published snapshot) can read links from several threads; its `&self` methods only read.
pub trait Link: Send + Sync {
    /// The newest state received since the previous call, or None when none arrived (link slow,
    /// lost, or not connected yet). The fleet counts how long a UAV has gone without one.
    fn state(&mut self) -> Option<UavState>;
    /// Hands over the filtered acceleration for the coming period (latest wins).
    fn send(&mut self, u: Vec2);
    /// Where the UAV is in its flight. In-process links are always flying.
    fn phase(&self) -> LinkPhase {
        LinkPhase::Flying
    }
    /// Lands the UAV, ahead of any queued command. In-process links have nothing to land.
    fn land(&mut self) {}
    /// Cuts the motors at once (emergency stop), ahead of any queued command.
    fn emergency_stop(&mut self) {}
    /// Closes the connection without landing, so that another server can open it (a handover
    /// between regions); the UAV holds its last setpoint meanwhile. In-process links have none.
    fn detach(&mut self) {}
    /// The connection is closed after [`Link::detach`] (at once for in-process links).
    fn detached(&self) -> bool {
        true
    }
    /// What the link is, e.g. `sim` or the Crazyflie URI (shown in the snapshot).
    fn describe(&self) -> &str {
        SIM_LINK
    }
    /// The last error, for the operator: why the link is not connected, or a stop or landing the
    /// UAV did not confirm. In-process links have none.
    fn error(&self) -> Option<String> {
        None
    }
    /// How many emergency stops and landings were given up on without the UAV's confirmation.
    fn unconfirmed_commands(&self) -> u64 {
        0
    }
    /// What the UAV's firmware last reported about itself; in-process links have no firmware.
    fn vehicle(&self) -> Option<VehicleReport> {
        None
    }
}

/// How long an in-process UAV takes to land (s).
pub const SIM_LANDING_S: f64 = 1.0;

/// In-process simulator of one UAV: the exact double-integrator step (paper eq. 1) per command.
/// It lands (in [`SIM_LANDING_S`], following the commands meanwhile) and stops on request.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SimLink {
    state: UavState,
    dt: f64,
    phase: LinkPhase,
    /// Commands left until a landing UAV is down.
    landing_steps: u32,
}

impl SimLink {
    /// A simulated UAV in `state`, advanced by `dt` seconds per command.
    pub fn new(state: UavState, dt: f64) -> Self {
        Self { state, dt, phase: LinkPhase::Flying, landing_steps: 0 }
    }
}

impl Link for SimLink {
    fn state(&mut self) -> Option<UavState> {
        Some(self.state)
    }

    fn send(&mut self, u: Vec2) {
        match self.phase {
            LinkPhase::Landed | LinkPhase::Stopped => return,
            LinkPhase::Landing if self.landing_steps == 0 => {
                self.phase = LinkPhase::Landed;
                self.state.v = Vec2::zeros();
                return;
            }
            LinkPhase::Landing => self.landing_steps -= 1,
            _ => {}
        }
        self.state = self.state.stepped(u, self.dt);
    }

    fn phase(&self) -> LinkPhase {
        self.phase
    }

    fn land(&mut self) {
        if self.phase == LinkPhase::Flying {
            self.phase = LinkPhase::Landing;
            // Saturating float-to-int cast: a non-positive or NaN dt lands at once.
            self.landing_steps = (SIM_LANDING_S / self.dt).ceil() as u32;
        }
    }

    fn emergency_stop(&mut self) {
        self.phase = LinkPhase::Stopped;
        self.state.v = Vec2::zeros();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sim_link_steps_exactly_once_per_command() {
        let mut link = SimLink::new(UavState::at_rest(Vec2::new(1.0, 2.0)), 0.05);
        link.send(Vec2::new(2.0, 0.0));
        let s = link.state().unwrap();
        assert!((s.p - Vec2::new(1.0025, 2.0)).norm() < 1e-15);
        assert!((s.v - Vec2::new(0.1, 0.0)).norm() < 1e-15);
        assert_eq!(link.phase(), LinkPhase::Flying);
    }

    #[test]
    fn sim_link_lands_after_its_landing_time_and_stops_at_once() {
        let mut link = SimLink::new(UavState::at_rest(Vec2::zeros()), 0.05);
        link.land();
        assert_eq!(link.phase(), LinkPhase::Landing);
        for _ in 0..20 {
            link.send(Vec2::zeros());
        }
        assert_eq!(link.phase(), LinkPhase::Landing);
        link.send(Vec2::zeros());
        assert_eq!(link.phase(), LinkPhase::Landed);
        link.send(Vec2::new(1.0, 0.0));
        assert_eq!(link.state().unwrap().p, Vec2::zeros(), "a landed UAV does not move");

        let mut link = SimLink::new(UavState { p: Vec2::zeros(), v: Vec2::new(1.0, 0.0) }, 0.05);
        link.emergency_stop();
        link.send(Vec2::new(1.0, 0.0));
        assert_eq!(link.phase(), LinkPhase::Stopped);
        assert_eq!(link.state().unwrap().p, Vec2::zeros(), "a stopped UAV does not move");
        assert!(!link.phase().airborne());
    }

    #[test]
    fn stopping_is_airborne_until_confirmed() {
        assert_eq!(LinkPhase::Stopping.name(), "stopping");
        assert!(LinkPhase::Stopping.airborne() && LinkPhase::Landing.airborne());
        assert!(!LinkPhase::Stopped.airborne() && !LinkPhase::Landed.airborne());
    }
}
