//! A policy that produces garbage (NaN, infinity, an error) degrades only its own UAVs: they brake,
//! the event is counted, and a UAV on another policy is unaffected.

use fleet::{Fleet, FleetConfig};
use links::SimLink;
use policies::{Observation, Policy, PolicyError, PolicyRegistry};
use roads::{Road, RoadLayout};
use uav::{UavState, Vec2};

/// Outputs NaN for the first UAV of each batch, +∞ for the second, and fails every third call.
struct Garbage {
    calls: usize,
}

impl Policy for Garbage {
    fn act(&mut self, observations: &[Observation], actions: &mut Vec<Vec2>) -> Result<(), PolicyError> {
        self.calls += 1;
        if self.calls.is_multiple_of(3) {
            return Err(PolicyError { policy: "garbage".into(), reason: "deliberate failure".into() });
        }
        actions.clear();
        actions.extend(
            observations
                .iter()
                .enumerate()
                .map(|(i, _)| if i == 0 { Vec2::new(f64::NAN, 1.0) } else { Vec2::new(f64::INFINITY, 0.0) }),
        );
        Ok(())
    }
}

#[test]
fn garbage_policy_output_brakes_only_its_uavs() {
    let road = Road::new(RoadLayout::straight(0.0, 40.0, 6.0, 4)).unwrap();
    let mut registry = PolicyRegistry::with_pd(5.0);
    registry.insert("garbage", Box::new(Garbage { calls: 0 }));
    let mut fleet = Fleet::new(FleetConfig::default(), road, registry);
    let moving = |x: f64, y: f64| UavState { p: Vec2::new(x, y), v: Vec2::new(2.0, 0.0) };
    for (id, policy, state) in [
        ("a", "garbage", moving(5.0, -1.5)),
        ("b", "garbage", moving(5.0, 1.5)),
        ("c", "pd", moving(5.0, 0.0)),
    ] {
        fleet.add(
            id.into(),
            policy.into(),
            Box::new(SimLink::new(state, 0.05)),
            state,
            Some(Vec2::new(35.0, state.p.y)),
        );
    }
    for _ in 0..30 {
        fleet.tick();
        for u in fleet.uavs() {
            assert!(uav::is_finite(&u.last.u) && u.last.u.norm() <= 5.0 + 1e-9);
            assert!(u.state.is_finite());
            if u.policy == "garbage" {
                assert!(u.last.policy_fallback, "{}: garbage must be replaced", u.id);
                // Braking: the input opposes the velocity (or is zero once stopped).
                assert!(u.last.u_ref.dot(&u.state.v) <= 0.0, "{}: {:?}", u.id, u.last.u_ref);
            } else {
                assert!(!u.last.policy_fallback);
            }
        }
    }
    let garbage_speed = fleet.uavs()[0].state.v.norm();
    assert!(garbage_speed < 1e-9, "garbage UAVs end stopped, not drifting: {garbage_speed}");
    assert!(fleet.uavs()[2].state.p.x > 8.0, "the pd UAV keeps flying towards its goal");
}

/// A link still taking off: its UAV is an obstacle the fleet brakes, not flown by a policy.
struct TakingOff(UavState);

impl links::Link for TakingOff {
    fn state(&mut self) -> Option<UavState> {
        Some(self.0)
    }

    fn send(&mut self, _u: Vec2) {}

    fn phase(&self) -> links::LinkPhase {
        links::LinkPhase::TakingOff
    }
}

/// A UAV that is not flying (taking off, landing, lost) runs no policy: braking it is no policy
/// fallback, which counts only policies that gave no finite action.
#[test]
fn a_uav_that_is_not_flying_is_no_policy_fallback() {
    let road = Road::new(RoadLayout::straight(0.0, 40.0, 6.0, 4)).unwrap();
    let mut fleet = Fleet::new(FleetConfig::default(), road, PolicyRegistry::with_pd(5.0));
    let at = |x: f64| UavState { p: Vec2::new(x, 0.0), v: Vec2::zeros() };
    fleet.add("up".into(), "pd".into(), Box::new(TakingOff(at(5.0))), at(5.0), Some(Vec2::new(35.0, 0.0)));
    fleet.add(
        "on".into(),
        "pd".into(),
        Box::new(SimLink::new(at(10.0), 0.05)),
        at(10.0),
        Some(Vec2::new(35.0, 0.0)),
    );
    for _ in 0..10 {
        fleet.tick();
        assert!(fleet.uavs().iter().all(|u| !u.last.policy_fallback), "no policy gave garbage");
    }
}
