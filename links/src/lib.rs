//! Where commands go and states come from. The fleet loop talks to every UAV through [`Link`]; this
//! crate has the in-process simulator, and hardware links (Crazyflie over CRTP) slot in beside it.

use uav::{UavState, Vec2};

/// The connection to one UAV. Implementations never block the caller.
pub trait Link: Send {
    /// The latest state estimate, or None when the link has none (lost, not yet connected).
    fn state(&mut self) -> Option<UavState>;
    /// Hands over the filtered acceleration for the coming period (latest wins).
    fn send(&mut self, u: Vec2);
}

/// In-process simulator of one UAV: the exact double-integrator step (paper eq. 1) per command.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SimLink {
    state: UavState,
    dt: f64,
}

impl SimLink {
    /// A simulated UAV in `state`, advanced by `dt` seconds per command.
    pub fn new(state: UavState, dt: f64) -> Self {
        Self { state, dt }
    }
}

impl Link for SimLink {
    fn state(&mut self) -> Option<UavState> {
        Some(self.state)
    }

    fn send(&mut self, u: Vec2) {
        self.state = self.state.stepped(u, self.dt);
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
    }
}
