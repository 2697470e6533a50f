//! Margins measured on ground truth (`MetricsRecorder::record_truth`, used by the runs over the
//! real firmware): a UAV the truth says is not in the air (landed, or fallen after a fault) has no
//! margins, and the others' are measured on their true states, not on what the fleet read.

use fleet::{Fleet, FleetConfig, MetricsRecorder};
use links::SimLink;
use policies::PolicyRegistry;
use roads::{Road, RoadLayout};
use uav::{UavState, Vec2};

/// Two UAVs hovering 1 m apart on a straight road 4 m wide, after one tick.
fn two_uavs() -> Fleet {
    let road = Road::new(RoadLayout::straight(0.0, 20.0, 4.0, 2)).unwrap(); // a valid layout
    let config = FleetConfig::default();
    let (dt, delta) = (config.params.dt, config.params.delta);
    let mut fleet = Fleet::new(config, road, PolicyRegistry::with_pd(delta));
    for (id, x) in [("a", 5.0), ("b", 6.0)] {
        let state = UavState::at_rest(Vec2::new(x, 0.0));
        fleet.add(id.into(), "pd".into(), Box::new(SimLink::new(state, dt)), state, Some(Vec2::new(x, 0.0)));
    }
    fleet.tick();
    fleet
}

#[test]
fn the_truth_replaces_what_the_fleet_read() {
    let fleet = two_uavs();
    let mut read = MetricsRecorder::new();
    read.record(&fleet, 0.0);
    let read = read.finish(&fleet, "t");
    assert!(read.safe && read.min_separation_m.is_some_and(|d| d > 0.9), "{read:?}");
    // Truly 0.2 m apart, one of them 0.05 m from a wall: both are violations.
    let truth =
        [Some(UavState::at_rest(Vec2::new(5.0, 1.95))), Some(UavState::at_rest(Vec2::new(5.2, 1.95)))];
    let mut recorder = MetricsRecorder::new();
    recorder.record_truth(&fleet, 0.0, &truth);
    let m = recorder.finish(&fleet, "t");
    assert!(!m.safe, "{m:?}");
    assert!(m.min_separation_m.is_some_and(|d| (d - 0.2).abs() < 1e-9), "{m:?}");
    assert!((m.min_wall_distance_m - 0.05).abs() < 1e-9, "{m:?}");
}

#[test]
fn a_uav_not_in_the_air_has_no_margins() {
    let fleet = two_uavs();
    // b lies on the floor right under a: no pair, and its place counts for nothing.
    let truth = [Some(UavState::at_rest(Vec2::new(5.0, 0.0))), None];
    let mut recorder = MetricsRecorder::new();
    recorder.record_truth(&fleet, 0.0, &truth);
    let m = recorder.finish(&fleet, "t");
    assert!(m.safe && m.min_separation_m.is_none(), "{m:?}");
    assert!((m.min_wall_distance_m - 2.0).abs() < 1e-9, "{m:?}");
}
