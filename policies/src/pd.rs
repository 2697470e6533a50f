//! The saturated PD baseline: u = sat_δ(k_p(p_r − p) + k_d(v_r − v)).

use crate::{Observation, Policy, PolicyError};
use uav::Vec2;

/// Saturated PD tracking law on the observation [p − p_r, v − v_r, v].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PdPolicy {
    /// Position gain k_p (1/s²). Default 1.5.
    pub kp: f64,
    /// Velocity gain k_d (1/s). Default 2.
    pub kd: f64,
    /// Saturation ‖u‖ ≤ δ (m/s²). Default 5.
    pub delta: f64,
}

impl Default for PdPolicy {
    fn default() -> Self {
        Self { kp: 1.5, kd: 2.0, delta: 5.0 }
    }
}

impl PdPolicy {
    /// The PD law for one observation.
    pub fn law(&self, s: &Observation) -> Vec2 {
        let u = Vec2::new(s[0], s[1]) * -self.kp - Vec2::new(s[2], s[3]) * self.kd;
        uav::saturate(u, self.delta)
    }
}

impl Policy for PdPolicy {
    fn act(&mut self, observations: &[Observation], actions: &mut Vec<Vec2>) -> Result<(), PolicyError> {
        actions.clear();
        actions.extend(observations.iter().map(|s| self.law(s)));
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::observation;
    use uav::UavState;

    #[test]
    fn pd_drives_towards_target_and_saturates() {
        let pd = PdPolicy::default();
        let s = UavState { p: Vec2::new(0.0, 0.0), v: Vec2::new(0.0, 1.0) };
        let u = pd.law(&observation(&s, Vec2::new(1.0, 0.0), Vec2::zeros()));
        assert!((u - Vec2::new(1.5, -2.0)).norm() < 1e-12);
        let far = pd.law(&observation(&s, Vec2::new(100.0, 0.0), Vec2::zeros()));
        assert!((far.norm() - 5.0).abs() < 1e-12);
    }

    #[test]
    fn pd_settles_on_its_target_in_closed_loop() {
        let pd = PdPolicy::default();
        let target = Vec2::new(3.0, -2.0);
        let mut s = UavState::at_rest(Vec2::zeros());
        for _ in 0..400 {
            s = s.stepped(pd.law(&observation(&s, target, Vec2::zeros())), 0.05);
        }
        assert!((s.p - target).norm() < 1e-3 && s.v.norm() < 1e-3);
    }
}
