//! The high-level commander's planner: idle / flying / landing, with smooth point-to-point
//! trajectories (the firmware's `planner.c` state machine).
//!
//! The firmware plans 7th-order polynomials with zero velocity, acceleration and jerk at the
//! target; here each trajectory is the 7th-order smoothstep from the start to the target, which
//! has the same end conditions (but also starts from rest).

/// Planner state.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PlanState {
    /// No trajectory: the high-level commander is stopped.
    Idle,
    /// Following or holding the end of a trajectory.
    Flying,
    /// Landing: becomes idle (motors off) when the trajectory ends.
    Landing,
    /// Overridden by low-level setpoints: no output, but a landing is accepted (from the
    /// current position), as in the firmware's `plan_disable`.
    Disabled,
}

/// A straight-line trajectory with a smooth time law.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Trajectory {
    start: [f64; 3],
    end: [f64; 3],
    t0: f64,
    duration: f64,
}

/// Position, velocity and acceleration of the reference.
pub type Goal = ([f64; 3], [f64; 3], [f64; 3]);

impl Trajectory {
    /// From `start` to `end` in `duration` seconds from time `t0`.
    pub fn new(start: [f64; 3], end: [f64; 3], t0: f64, duration: f64) -> Self {
        Self { start, end, t0, duration: duration.max(0.0) }
    }

    /// The reference at time `t`.
    pub fn eval(&self, t: f64) -> Goal {
        if self.duration <= 0.0 || t >= self.t0 + self.duration {
            return (self.end, [0.0; 3], [0.0; 3]);
        }
        let d = self.duration;
        let s = ((t - self.t0) / d).clamp(0.0, 1.0);
        let (s2, s3) = (s * s, s * s * s);
        let pos = s2 * s2 * (35.0 - 84.0 * s + 70.0 * s2 - 20.0 * s3);
        let vel = s3 * (140.0 - 420.0 * s + 420.0 * s2 - 140.0 * s3) / d;
        let acc = s2 * (420.0 - 1680.0 * s + 2100.0 * s2 - 840.0 * s3) / (d * d);
        let mut out = ([0.0; 3], [0.0; 3], [0.0; 3]);
        for k in 0..3 {
            let delta = self.end[k] - self.start[k];
            out.0[k] = self.start[k] + delta * pos;
            out.1[k] = delta * vel;
            out.2[k] = delta * acc;
        }
        out
    }

    /// Whether the trajectory has ended at time `t`.
    pub fn finished(&self, t: f64) -> bool {
        t >= self.t0 + self.duration
    }
}

/// The planner.
#[derive(Debug, Clone, PartialEq)]
pub struct Planner {
    state: PlanState,
    traj: Trajectory,
    group_mask: u8,
}

impl Default for Planner {
    fn default() -> Self {
        Self::new()
    }
}

impl Planner {
    /// Idle, in no group.
    pub fn new() -> Self {
        Self { state: PlanState::Idle, traj: Trajectory::new([0.0; 3], [0.0; 3], 0.0, 0.0), group_mask: 0 }
    }

    /// The state.
    pub fn state(&self) -> PlanState {
        self.state
    }

    /// Whether a command for `mask` applies (0 means all groups).
    pub fn in_group(&self, mask: u8) -> bool {
        mask == 0 || self.group_mask & mask != 0
    }

    /// Set the group mask.
    pub fn set_group_mask(&mut self, mask: u8) {
        self.group_mask = mask;
    }

    /// Stop: idle, motors off.
    pub fn stop(&mut self) {
        self.state = PlanState::Idle;
    }

    /// Disable (a low-level setpoint took over): forget the trajectory.
    pub fn disable(&mut self) {
        self.state = PlanState::Disabled;
    }

    /// The current reference, or `None` when idle; a finished landing becomes idle.
    pub fn goal(&mut self, t: f64) -> Option<Goal> {
        match self.state {
            PlanState::Idle | PlanState::Disabled => None,
            PlanState::Landing if self.traj.finished(t) => {
                self.state = PlanState::Idle;
                None
            }
            _ => Some(self.traj.eval(t)),
        }
    }

    /// Whether the current trajectory has ended.
    pub fn finished(&self, t: f64) -> bool {
        self.traj.finished(t)
    }

    /// Take off from `pos` to `height`; refused unless idle or disabled.
    pub fn takeoff(&mut self, pos: [f64; 3], height: f64, duration: f64, t: f64) -> bool {
        if !matches!(self.state, PlanState::Idle | PlanState::Disabled) {
            return false;
        }
        self.traj = Trajectory::new(pos, [pos[0], pos[1], height], t, duration);
        self.state = PlanState::Flying;
        true
    }

    /// Land from the current goal (or `pos`) to `height`; refused when idle or landing.
    pub fn land(&mut self, pos: [f64; 3], height: f64, duration: f64, t: f64) -> bool {
        if !matches!(self.state, PlanState::Flying | PlanState::Disabled) {
            return false;
        }
        let from = self.goal(t).map_or(pos, |g| g.0);
        self.traj = Trajectory::new(from, [from[0], from[1], height], t, duration);
        self.state = PlanState::Landing;
        true
    }

    /// Go to `target` (relative to the current goal, or `pos` when idle, if `relative`).
    /// Allowed in any state, so it can also take off or abort a landing.
    pub fn go_to(&mut self, pos: [f64; 3], relative: bool, target: [f64; 3], duration: f64, t: f64) {
        let from = self.goal(t).map_or(pos, |g| g.0);
        let end = if relative { [0, 1, 2].map(|k| from[k] + target[k]) } else { target };
        self.traj = Trajectory::new(from, end, t, duration);
        self.state = PlanState::Flying;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn smooth_endpoints() {
        let tr = Trajectory::new([0.0; 3], [0.0, 0.0, 1.0], 1.0, 2.0);
        assert_eq!(tr.eval(0.0).0[2], 0.0);
        let mid = tr.eval(2.0);
        assert!((mid.0[2] - 0.5).abs() < 1e-12);
        assert!(mid.1[2] > 0.5);
        assert_eq!(tr.eval(3.5).0[2], 1.0);
        let late = tr.eval(2.999);
        assert!(late.1[2].abs() < 1e-3 && late.2[2].abs() < 0.1);
    }

    #[test]
    fn state_machine() {
        let mut p = Planner::new();
        assert!(!p.land([0.0; 3], 0.0, 1.0, 0.0));
        assert!(p.takeoff([1.0, 2.0, 0.0], 1.0, 1.0, 0.0));
        assert!(!p.takeoff([0.0; 3], 1.0, 1.0, 0.5));
        assert_eq!(p.goal(2.0).map(|g| g.0), Some([1.0, 2.0, 1.0]));
        p.go_to([0.0; 3], true, [1.0, 0.0, 0.0], 1.0, 2.0);
        assert_eq!(p.goal(3.0).map(|g| g.0), Some([2.0, 2.0, 1.0]));
        assert!(p.land([0.0; 3], 0.0, 1.0, 3.0));
        assert_eq!(p.state(), PlanState::Landing);
        assert!(p.goal(3.5).is_some());
        assert!(p.goal(4.0).is_none());
        assert_eq!(p.state(), PlanState::Idle);
        p.go_to([0.0; 3], false, [0.0, 0.0, 1.0], 1.0, 4.0);
        p.disable();
        assert!(p.goal(4.5).is_none());
        assert!(p.land([0.0, 0.0, 0.7], 0.0, 1.0, 4.5));
        assert_eq!(p.goal(5.0).map(|g| g.0[2]), Some(0.35));
        p.set_group_mask(0b10);
        assert!(p.in_group(0) && p.in_group(0b110) && !p.in_group(0b1));
    }
}
