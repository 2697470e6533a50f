//! The simulation loop: every drone polled, stepped and fed once per millisecond of wall time.

use std::sync::atomic::Ordering;
use std::time::Instant;

use super::drone::Drone;
use super::{LoopStats, MAX_LAG, PHYSICS_STEP, Shared, SitlError, lock};

/// Large enough for any CRTP datagram (a header and 30 bytes) and then some.
const DATAGRAM_BUFFER: usize = 256;

/// Run until the handle asks to stop; then flush the truth files.
pub(super) fn run(mut drones: Vec<Drone>, shared: &Shared, pose_hz: f64) -> Result<(), SitlError> {
    let dt = PHYSICS_STEP.as_secs_f64();
    let mut buf = [0u8; DATAGRAM_BUFFER];
    let mut faults = Vec::with_capacity(drones.len());
    let mut stats = LoopStats::default();
    let loop_start = Instant::now();
    let mut deadline = loop_start;
    while !shared.stop.load(Ordering::Relaxed) {
        let now = Instant::now();
        if now < deadline {
            std::thread::sleep(deadline - now);
        }
        let work_start = Instant::now();
        if work_start.duration_since(deadline) > MAX_LAG {
            deadline = work_start;
            stats.resyncs += 1;
        }
        let elapsed = shared.start.elapsed().as_secs_f64();
        faults.clear();
        faults.extend(shared.drones.iter().map(|v| lock(v).faults));
        for (drone, faults) in drones.iter_mut().zip(&faults) {
            drone.poll(faults, &mut buf);
            drone.tick(stats.ticks, dt, elapsed, faults, pose_hz);
        }
        for (drone, view) in drones.iter().zip(&shared.drones) {
            let mut view = lock(view);
            view.truth = drone.quad.truth();
            view.stats = drone.stats;
        }
        stats.ticks += 1;
        deadline += PHYSICS_STEP;
        let work = work_start.elapsed();
        stats.busy += work;
        stats.longest_tick = stats.longest_tick.max(work);
        stats.elapsed = loop_start.elapsed();
        *lock(&shared.loop_stats) = stats;
    }
    let mut first_error = None;
    for drone in &mut drones {
        if let Some((path, source)) = drone.finish() {
            first_error.get_or_insert(SitlError::Truth { path, source });
        }
    }
    first_error.map_or(Ok(()), Err)
}
