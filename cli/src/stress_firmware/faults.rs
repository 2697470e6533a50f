//! The faults of `airroads stress --link firmware`: which, drawn at random per case, and how they
//! are applied to the physics and the firmware processes during a flight.

use cfsim::sitl::SitlFaults;
use flights::firmware_fleet::FirmwareFleet;
use rand::Rng;
use rand::rngs::StdRng;
use std::time::Duration;

/// A fault in flight: what, to which Crazyflie, when (s after every Crazyflie flies).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Fault {
    /// No motion capture for this long (s).
    PoseGap { at: f64, uav: usize, seconds: f64 },
    /// A horizontal wind force (N) for this long (s).
    Gust { at: f64, uav: usize, force: [f64; 2], seconds: f64 },
    /// The firmware process is killed.
    Kill { at: f64, uav: usize },
    /// The firmware process stops (SIGSTOP) for the rest of the flight.
    Freeze { at: f64, uav: usize },
    /// Every packet of the link is lost for 3 s: the firmware locks.
    Lock { at: f64, uav: usize },
}

impl Fault {
    /// When it strikes (s of flight).
    pub fn at(&self) -> f64 {
        match *self {
            Fault::PoseGap { at, .. }
            | Fault::Gust { at, .. }
            | Fault::Kill { at, .. }
            | Fault::Freeze { at, .. }
            | Fault::Lock { at, .. } => at,
        }
    }

    /// Whether the Crazyflie it hits stops flying (and need not arrive).
    pub fn downs(&self) -> Option<usize> {
        match *self {
            Fault::Kill { uav, .. } | Fault::Freeze { uav, .. } | Fault::Lock { uav, .. } => Some(uav),
            _ => None,
        }
    }
}

/// Each fault with its own chance, at a random time of the flight, on a random Crazyflie; at most
/// one that downs a Crazyflie.
pub fn draw(rng: &mut StdRng, count: usize) -> Vec<Fault> {
    let mut faults = Vec::new();
    let pick = |rng: &mut StdRng| (rng.random_range(1.0..8.0), rng.random_range(0..count));
    if rng.random_bool(0.5) {
        let ((at, uav), seconds) = (pick(rng), rng.random_range(0.05..=0.2));
        faults.push(Fault::PoseGap { at, uav, seconds });
    }
    if rng.random_bool(0.5) {
        // Up to 0.01 N on a 27 g Crazyflie: 0.37 m/s², for up to 0.5 s.
        let ((at, uav), angle, size) = (pick(rng), rng.random_range(0.0..std::f64::consts::TAU), 0.01);
        let force = [size * angle.cos(), size * angle.sin()];
        faults.push(Fault::Gust { at, uav, force, seconds: rng.random_range(0.1..0.5) });
    }
    let (at, uav) = pick(rng);
    match rng.random_range(0..10) {
        0 | 1 => faults.push(Fault::Kill { at, uav }),
        2 | 3 => faults.push(Fault::Freeze { at, uav }),
        4 => faults.push(Fault::Lock { at, uav }),
        _ => {}
    }
    faults
}

/// Applies the faults due at flight time `now` and restores what gusts and outages changed once
/// they are over (`undo`: until when, which Crazyflie, its faults before).
pub fn inject(
    firmware: &mut FirmwareFleet,
    pending: &mut Vec<Fault>,
    undo: &mut Vec<(f64, usize, SitlFaults)>,
    now: f64,
) {
    let physics = &firmware.physics;
    undo.retain(|(until, uav, before)| {
        let over = now >= *until;
        if over {
            // Only what the fault changed: a motion-capture gap set meanwhile stays.
            if let Some(f) = physics.faults(*uav) {
                physics.set_faults(
                    *uav,
                    SitlFaults { wind_force: before.wind_force, link_loss: before.link_loss, ..f },
                );
            }
        }
        !over
    });
    let (due, later): (Vec<Fault>, Vec<Fault>) = pending.drain(..).partition(|f| f.at() <= now);
    *pending = later;
    for fault in due {
        match fault {
            Fault::PoseGap { uav, seconds, .. } => {
                let from = firmware.physics.elapsed();
                let gap = Some((from, from + Duration::from_secs_f64(seconds)));
                if let Some(f) = firmware.physics.faults(uav) {
                    firmware.physics.set_faults(uav, SitlFaults { pose_gap: gap, ..f });
                }
            }
            Fault::Gust { uav, force, seconds, .. } => {
                if let Some(f) = firmware.physics.faults(uav) {
                    firmware
                        .physics
                        .set_faults(uav, SitlFaults { wind_force: [force[0], force[1], 0.0], ..f });
                    undo.push((now + seconds, uav, f));
                }
            }
            Fault::Kill { uav, .. } => firmware.kill(uav),
            Fault::Freeze { uav, .. } => {
                if let Err(e) = firmware.freeze(uav) {
                    eprintln!("warning: freezing firmware {uav}: {e}");
                }
            }
            Fault::Lock { uav, .. } => {
                if let Some(f) = firmware.physics.faults(uav) {
                    // The case's own loss again after 3 s.
                    firmware.physics.set_faults(uav, SitlFaults { link_loss: 1.0, ..f });
                    undo.push((now + 3.0, uav, f));
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    #[test]
    fn each_case_has_at_most_one_downing_fault_within_the_flight() {
        let mut kinds = [0usize; 5];
        for seed in 0..2000 {
            let faults = draw(&mut StdRng::seed_from_u64(seed), 3);
            assert!(faults.iter().filter(|f| f.downs().is_some()).count() <= 1, "{faults:?}");
            for f in &faults {
                assert!((1.0..8.0).contains(&f.at()), "{f:?}");
                let (k, uav) = match *f {
                    Fault::PoseGap { uav, seconds, .. } => {
                        assert!((0.05..=0.2).contains(&seconds), "{f:?}");
                        (0, uav)
                    }
                    Fault::Gust { uav, force, .. } => {
                        assert!((force[0].hypot(force[1]) - 0.01).abs() < 1e-12, "{f:?}");
                        (1, uav)
                    }
                    Fault::Kill { uav, .. } => (2, uav),
                    Fault::Freeze { uav, .. } => (3, uav),
                    Fault::Lock { uav, .. } => (4, uav),
                };
                assert!(uav < 3);
                kinds[k] += 1;
            }
        }
        // Every kind comes up, about as often as drawn (gaps and gusts in half the cases, a kill
        // or freeze in a fifth each, a lock in a tenth).
        for (k, expected) in [1000, 1000, 400, 400, 200].into_iter().enumerate() {
            assert!(kinds[k].abs_diff(expected) < expected / 4, "{kinds:?}");
        }
    }
}
