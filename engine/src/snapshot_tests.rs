//! The snapshot's per-UAV collision margins as the rows stage measures them
//! (`FleetConfig::uav_collision_margins`) equal those it measures itself from the neighbour lists,
//! and the run's metrics are the same with or without them;
//! the loop's counts of a tick are the same counted in chunks on all cores as in one pass.

use super::*;
use fleet::{FleetConfig, trunk::trunk_scenario};
use links::SimLink;
use policies::PolicyRegistry;
use uav::UavState;

/// A `pd` fleet flying the `bench scale` trunk of `uavs` UAVs, measuring per-UAV collision margins
/// in its rows stage or not.
fn trunk_fleet(uavs: usize, measured_by_rows: bool) -> Fleet {
    let scenario = trunk_scenario(uavs, 3).expect("a trunk road").validate().expect("a valid scenario");
    let params = scenario.params;
    let config = FleetConfig { params, uav_collision_margins: measured_by_rows, ..FleetConfig::default() };
    let mut fleet = Fleet::new(config, scenario.road.clone(), PolicyRegistry::with_pd(params.delta));
    for u in &scenario.uavs {
        let state = UavState::at_rest(u.start);
        fleet.add(u.id.clone(), "pd".into(), Box::new(SimLink::new(state, params.dt)), state, Some(u.goal));
    }
    fleet
}

#[test]
fn collision_margins_from_the_rows_equal_the_snapshots_own() {
    let (mut from_rows, mut own) = (trunk_fleet(400, true), trunk_fleet(400, false));
    let mut measured = 0;
    // The run's metrics, whose closest pairs the rows stage measures either way.
    let mut recorders = (fleet::MetricsRecorder::new(), fleet::MetricsRecorder::new());
    for tick in 1..=160u64 {
        if tick == 40 {
            // Landing UAVs leave the air: their neighbours no longer count them (nor they anyone).
            for k in (0..400).step_by(7) {
                let id = from_rows.uavs()[k].id.clone();
                from_rows.land(&id).unwrap();
                own.land(&id).unwrap();
            }
        }
        from_rows.tick();
        own.tick();
        let (a, b) = (Snapshot::of(&from_rows, tick, 0.0, 0), Snapshot::of(&own, tick, 0.0, 0));
        assert!(from_rows.tick_margins().and_then(|m| m.collision(0)).is_some(), "the rows measured them");
        assert!(own.tick_margins().and_then(|m| m.collision(0)).is_none(), "the snapshot measured them");
        for (x, y) in a.uavs.iter().zip(&b.uavs) {
            let bits = |m: Option<f64>| m.map(f64::to_bits);
            assert_eq!(bits(x.collision_margin_m), bits(y.collision_margin_m), "tick {tick}, {}", x.id);
            measured += usize::from(x.collision_margin_m.is_some());
        }
        assert_eq!(a, b, "tick {tick}: the same flight and snapshot either way");
        recorders.0.record(&from_rows, tick as f64);
        recorders.1.record(&own, tick as f64);
    }
    let (x, y) = (recorders.0.finish(&from_rows, "t"), recorders.1.finish(&own, "t"));
    let bits = |m: Option<f64>| m.map(f64::to_bits);
    assert_eq!(bits(x.min_collision_margin_m), bits(y.min_collision_margin_m));
    assert_eq!(bits(x.min_separation_m), bits(y.min_separation_m));
    assert!(x.min_collision_margin_m.is_some(), "pairs were measured");
    let grounded = from_rows.uavs().iter().filter(|u| !u.condition.in_the_air()).count();
    assert!(measured > 1000 && grounded > 0, "pairs measured ({measured}), UAVs landed ({grounded})");
}

#[test]
fn a_tick_counted_in_chunks_gives_the_counts_of_one_pass() {
    let mut fleet = trunk_fleet(600, true);
    let dt = fleet.config.params.dt;
    let (mut stalled, mut solved) = (0, 0);
    for tick in 1..=200u64 {
        fleet.tick();
        let snapshot = Snapshot::of(&fleet, tick, 0.0, 0);
        let one = crate::tick_counts::TickCounts::in_chunks(fleet.uavs(), &snapshot.uavs, dt, usize::MAX);
        let chunked = crate::tick_counts::TickCounts::in_chunks(fleet.uavs(), &snapshot.uavs, dt, 50);
        // Only the stall time's sum may round differently.
        assert!((one.stall_s - chunked.stall_s).abs() <= 1e-12 * (1.0 + one.stall_s), "tick {tick}");
        assert_eq!(crate::tick_counts::TickCounts { stall_s: one.stall_s, ..chunked }, one, "tick {tick}");
        (stalled, solved) = (stalled + one.stalled_uavs, solved + one.solves);
    }
    assert!(stalled > 0 && solved > 0, "stalls ({stalled}) and solves ({solved}) were counted");
}
