//! A UAV whose link goes silent mid-flight (no states; commands do not reach it) keeps moving on its
//! own, as a Crazyflie does: its last command for the setpoint watchdog's 0.5 s, then level (no
//! acceleration). The fleet marks it lost and its neighbours avoid everywhere it could have got to;
//! the true distance between the UAVs never drops below D_c.

use fleet::{Fleet, FleetConfig};
use links::Link;
use policies::PolicyRegistry;
use proptest::prelude::*;
use roads::{Road, RoadLayout};
use std::sync::{Arc, Mutex};
use uav::{UavState, Vec2};

const DT: f64 = 0.05;
/// The Crazyflie keeps its last setpoint this long before levelling out (s).
const WATCHDOG_LEVEL_S: f64 = 0.5;

/// The true vehicle behind a link, shared with the test.
struct Vehicle {
    state: UavState,
    /// The last command that reached it.
    u: Vec2,
    /// Ticks since the link went silent (None: connected).
    silent_for: Option<u32>,
}

/// A link whose silence the test switches on and off.
struct SilentLink(Arc<Mutex<Vehicle>>);

impl Link for SilentLink {
    fn state(&mut self) -> Option<UavState> {
        let v = self.0.lock().unwrap(); // the test never panics while holding the lock
        v.silent_for.is_none().then_some(v.state)
    }

    fn send(&mut self, u: Vec2) {
        let mut v = self.0.lock().unwrap(); // as above
        match v.silent_for {
            None => v.u = u,
            Some(n) if f64::from(n) * DT >= WATCHDOG_LEVEL_S => v.u = Vec2::zeros(),
            Some(_) => {}
        }
        let u = v.u;
        v.state = v.state.stepped(u, DT);
        if let Some(n) = &mut v.silent_for {
            *n += 1;
        }
    }
}

/// Runs a head-on swap of two UAVs where `a` goes silent at tick `from` for `ticks` ticks and
/// returns the smallest true distance between them.
fn head_on_with_silence(offset: f64, from: u32, ticks: u32, speed: f64) -> (f64, bool) {
    let road = Road::new(RoadLayout::straight(0.0, 40.0, 6.0, 4)).unwrap();
    let config = FleetConfig::default();
    let mut fleet = Fleet::new(config, road, PolicyRegistry::with_pd(config.params.delta));
    let a0 = UavState { p: Vec2::new(10.0, 0.0), v: Vec2::new(speed, 0.0) };
    let b0 = UavState { p: Vec2::new(30.0, offset), v: Vec2::new(-speed, 0.0) };
    let a = Arc::new(Mutex::new(Vehicle { state: a0, u: Vec2::zeros(), silent_for: None }));
    let b = Arc::new(Mutex::new(Vehicle { state: b0, u: Vec2::zeros(), silent_for: None }));
    fleet.add("a".into(), "pd".into(), Box::new(SilentLink(a.clone())), a0, Some(Vec2::new(35.0, offset)));
    fleet.add("b".into(), "pd".into(), Box::new(SilentLink(b.clone())), b0, Some(Vec2::new(5.0, 0.0)));
    let mut min_distance = f64::INFINITY;
    let mut was_lost = false;
    for tick in 0..400 {
        if tick == from {
            a.lock().unwrap().silent_for = Some(0);
        }
        if tick == from + ticks {
            a.lock().unwrap().silent_for = None;
        }
        fleet.tick();
        was_lost |= fleet.uavs()[0].condition == fleet::Condition::Lost;
        let (pa, pb) = (a.lock().unwrap().state.p, b.lock().unwrap().state.p);
        min_distance = min_distance.min((pa - pb).norm());
    }
    (min_distance, was_lost)
}

#[test]
fn a_long_silence_marks_the_uav_lost_and_the_swap_stays_safe() {
    let d_c = FleetConfig::default().params.d_c;
    let (min_distance, was_lost) = head_on_with_silence(0.2, 60, 40, 2.0);
    assert!(was_lost, "2 s without states must mark the UAV lost");
    assert!(min_distance >= d_c, "true distance {min_distance} < D_c {d_c}");
}

#[test]
fn a_short_gap_is_stale_but_not_lost() {
    let (_, was_lost) = head_on_with_silence(0.2, 60, 5, 2.0);
    assert!(!was_lost, "0.25 s without states is under stale_after (0.3 s)");
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 1000, ..ProptestConfig::default() })]

    /// Across random offsets, speeds, and silences starting anywhere in the approach and lasting up
    /// to the watchdog's 2 s, the true distance never drops below D_c.
    #[test]
    fn silence_never_leads_to_a_collision(
        offset in -1.0f64..1.0,
        from in 0u32..140,
        ticks in 1u32..40,
        speed in 0.0f64..3.0,
    ) {
        let d_c = FleetConfig::default().params.d_c;
        let (min_distance, _) = head_on_with_silence(offset, from, ticks, speed);
        prop_assert!(min_distance >= d_c, "true distance {} < D_c {}", min_distance, d_c);
    }
}
