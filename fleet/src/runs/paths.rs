//! Where each UAV flew in a headless run (`airroads run --plot`): its path from start to goal and
//! the intervals in which a traffic rule held it back, with where they began.

use crate::fleet::Fleet;
use crate::member::WaitReason;

/// An interval in which a traffic rule held one UAV back.
#[derive(Debug, Clone, PartialEq)]
pub struct Wait {
    /// Why.
    pub reason: WaitReason,
    /// Where the UAV was when it began (m).
    pub at: [f64; 2],
    /// When it began (s of the run).
    pub start_s: f64,
    /// How long it lasted (s).
    pub duration_s: f64,
}

/// One UAV's flight in a run.
#[derive(Debug, Clone, PartialEq)]
pub struct UavPath {
    /// The UAV.
    pub id: String,
    /// Its goal, if it had one (m).
    pub goal: Option<[f64; 2]>,
    /// Its position at every tick, from the start (m).
    pub points: Vec<[f64; 2]>,
    /// Every interval in which it waited, in time order.
    pub waits: Vec<Wait>,
}

/// Records the paths of a run tick by tick.
#[derive(Debug, Default)]
pub struct PathRecorder {
    paths: Vec<UavPath>,
}

impl PathRecorder {
    /// Starts recording the UAVs of `fleet` where they are now.
    pub fn new(fleet: &Fleet) -> Self {
        let paths = fleet
            .uavs()
            .iter()
            .map(|u| UavPath {
                id: u.id.clone(),
                goal: u.nav.goal().map(|g| [g.x, g.y]),
                points: vec![[u.state.p.x, u.state.p.y]],
                waits: Vec::new(),
            })
            .collect();
        Self { paths }
    }

    /// Records the tick that ended at time `t` (s). The fleet's UAVs must be those it started with.
    pub fn record(&mut self, fleet: &Fleet, t: f64) {
        let dt = fleet.config.params.dt;
        for (path, u) in self.paths.iter_mut().zip(fleet.uavs()) {
            let at = [u.state.p.x, u.state.p.y];
            path.points.push(at);
            let Some(reason) = u.traffic.waiting else { continue };
            match path.waits.last_mut() {
                // The same wait goes on when it held the UAV at the previous tick too.
                Some(w) if w.reason == reason && (w.start_s + w.duration_s - (t - dt)).abs() < dt / 2.0 => {
                    w.duration_s += dt;
                }
                _ => path.waits.push(Wait { reason, at, start_s: t - dt, duration_s: dt }),
            }
        }
    }

    /// The paths recorded.
    pub fn finish(self) -> Vec<UavPath> {
        self.paths
    }
}
