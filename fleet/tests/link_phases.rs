//! A UAV whose link says it is landing or stopping (an emergency stop not yet confirmed by the
//! vehicle) may still be in the air: it does not fly the filter, and its neighbours avoid it. Once
//! the vehicle confirmed it is down (landed, stopped) it is out of the airspace.

use fleet::{Fleet, FleetConfig};
use links::{Link, LinkPhase, SimLink};
use policies::PolicyRegistry;
use roads::{Road, RoadLayout};
use uav::{UavState, Vec2};

/// A UAV hovering where it is, in a phase the test chooses.
struct Hovering {
    state: UavState,
    phase: LinkPhase,
}

impl Link for Hovering {
    fn state(&mut self) -> Option<UavState> {
        Some(self.state)
    }

    fn send(&mut self, _u: Vec2) {}

    fn phase(&self) -> LinkPhase {
        self.phase
    }
}

/// UAV `a` flies from x = 10 towards x = 30 through `b`, which hovers at x = 20 in `phase`.
/// Returns the fleet after `ticks` ticks and the smallest distance between them.
fn fly_past(phase: LinkPhase, ticks: u32) -> (Fleet, f64) {
    let road = Road::new(RoadLayout::straight(0.0, 40.0, 6.0, 4)).unwrap();
    let config = FleetConfig::default();
    let dt = config.params.dt;
    let mut fleet = Fleet::new(config, road, PolicyRegistry::with_pd(config.params.delta));
    let a = UavState::at_rest(Vec2::new(10.0, 0.0));
    let b = UavState::at_rest(Vec2::new(20.0, 0.0));
    fleet.add("a".into(), "pd".into(), Box::new(SimLink::new(a, dt)), a, Some(Vec2::new(30.0, 0.0)));
    fleet.add("b".into(), "pd".into(), Box::new(Hovering { state: b, phase }), b, None);
    let mut min_distance = f64::INFINITY;
    for _ in 0..ticks {
        fleet.tick();
        let u = fleet.uavs();
        min_distance = min_distance.min((u[0].state.p - u[1].state.p).norm());
    }
    (fleet, min_distance)
}

#[test]
fn a_stopping_or_landing_uav_is_an_obstacle_that_does_not_fly_the_filter() {
    let d_c = FleetConfig::default().params.d_c;
    for phase in [LinkPhase::Stopping, LinkPhase::Landing, LinkPhase::TakingOff] {
        let (fleet, min_distance) = fly_past(phase, 400);
        let b = &fleet.uavs()[1];
        assert!(b.condition.in_the_air(), "{phase:?} must count as in the air");
        assert!(!b.condition.flying() && !b.condition.cooperates(), "{phase:?} must not fly the filter");
        assert!(b.condition != fleet::Condition::Lost, "{phase:?} with fresh states is not lost");
        assert_eq!(b.last.u, fleet.uavs()[1].last.u_ref, "{phase:?} brakes");
        assert!(min_distance >= d_c, "{phase:?}: a came {min_distance} m close, less than D_c {d_c}");
    }
}

#[test]
fn a_uav_confirmed_down_is_out_of_the_airspace() {
    for phase in [LinkPhase::Stopped, LinkPhase::Landed] {
        let (fleet, _) = fly_past(phase, 1);
        let b = &fleet.uavs()[1];
        assert!(!b.condition.in_the_air() && !b.condition.flying(), "{phase:?} is on the ground");
    }
}

/// A link that is still connecting: no state yet, commands go nowhere.
struct Connecting;

impl Link for Connecting {
    fn state(&mut self) -> Option<UavState> {
        None
    }

    fn send(&mut self, _u: Vec2) {}

    fn phase(&self) -> LinkPhase {
        LinkPhase::Connecting
    }
}

#[test]
fn a_uav_taken_over_in_the_air_is_avoided_as_lost_while_its_new_link_connects() {
    // Another server flew it to x = 20 and handed it over: its new link has not connected yet.
    let road = Road::new(RoadLayout::straight(0.0, 40.0, 6.0, 4)).unwrap();
    let config = FleetConfig::default();
    let (dt, d_c) = (config.params.dt, config.params.d_c);
    let mut fleet = Fleet::new(config, road, PolicyRegistry::with_pd(config.params.delta));
    let a = UavState::at_rest(Vec2::new(10.0, 0.0));
    let b = UavState::at_rest(Vec2::new(20.0, 0.0));
    fleet.add("a".into(), "pd".into(), Box::new(SimLink::new(a, dt)), a, Some(Vec2::new(30.0, 0.0)));
    fleet.add("b".into(), "pd".into(), Box::new(Connecting), b, None).mark_airborne();
    assert_eq!(fleet.uavs()[1].condition, fleet::Condition::Lost, "lost from the start");
    let mut min_distance = f64::INFINITY;
    for _ in 0..400 {
        fleet.tick();
        assert_eq!(fleet.uavs()[1].condition, fleet::Condition::Lost);
        min_distance = min_distance.min((fleet.uavs()[0].state.p - b.p).norm());
    }
    assert!(min_distance >= d_c, "a came {min_distance} m close to where b may be, less than D_c {d_c}");
    // Added as new (a UAV never flown), a connecting link is on the ground: no obstacle.
    let road = Road::new(RoadLayout::straight(0.0, 40.0, 6.0, 4)).unwrap();
    let mut fresh = Fleet::new(config, road, PolicyRegistry::with_pd(config.params.delta));
    fresh.add("b".into(), "pd".into(), Box::new(Connecting), b, None);
    assert_eq!(fresh.uavs()[0].condition, fleet::Condition::Grounded);
}
