//! A UAV flown by another region is known only from that region's messages, late and sometimes
//! lost. Flying straight at such a foreign UAV, which itself moves with any acceleration up to δ
//! and does not avoid anybody, an own UAV keeps D_c from where it truly is: its reach disk grows
//! with the message's age (`fleet/src/foreign.rs`).

use fleet::{Fleet, FleetConfig, ForeignUav};
use links::Link;
use policies::PolicyRegistry;
use proptest::prelude::*;
use roads::{Road, RoadLayout};
use std::sync::{Arc, Mutex};
use uav::{UavState, Vec2};

const DT: f64 = 0.05;
/// Below D_c by at most this much at a tick (sampled states; the filter keeps 25 mm beyond D_c).
const TOLERANCE_M: f64 = 0.005;

/// The own vehicle behind its link: commands reach it at once.
struct Vehicle(Arc<Mutex<UavState>>);

impl Link for Vehicle {
    fn state(&mut self) -> Option<UavState> {
        Some(*self.0.lock().unwrap()) // the test never panics while holding the lock
    }

    fn send(&mut self, u: Vec2) {
        let mut s = self.0.lock().unwrap(); // as above
        *s = s.stepped(u, DT);
    }
}

/// splitmix64: the foreign UAV's random commands and the message losses, from one seed.
struct Random(u64);

impl Random {
    fn next(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// How the foreign UAV's messages arrive.
#[derive(Debug, Clone, Copy)]
struct Delivery {
    /// Each message carries the state of this many ticks before it arrives (0..1 s).
    lag_ticks: u32,
    /// The chance that a tick's message is lost.
    loss: f64,
}

/// An own UAV flies from x = 10 to x = 35 while a foreign UAV flies the other way at `speed`,
/// `offset` to the side, pushed around by random commands (|u| ≤ δ throughout); returns the smallest
/// true distance between them at the ticks.
fn head_on_with_foreign(offset: f64, speed: f64, delivery: Delivery, seed: u64) -> f64 {
    let road = Road::new(RoadLayout::straight(0.0, 40.0, 6.0, 4)).unwrap(); // a valid layout
    let config = FleetConfig::default();
    let delta = config.params.delta;
    let mut fleet = Fleet::new(config, road, PolicyRegistry::with_pd(delta));
    let a0 = UavState { p: Vec2::new(10.0, 0.0), v: Vec2::new(speed, 0.0) };
    let a = Arc::new(Mutex::new(a0));
    fleet.add("a".into(), "pd".into(), Box::new(Vehicle(a.clone())), a0, Some(Vec2::new(35.0, 0.0)));
    let mut b = UavState { p: Vec2::new(30.0, offset), v: Vec2::new(-speed, 0.0) };
    let mut random = Random(seed);
    // B's states by tick; the newest message delivered (its state and the tick it was taken).
    let mut history = vec![b];
    let mut delivered: Option<(UavState, usize)> = None;
    let mut min_distance = f64::INFINITY;
    for tick in 0..240usize {
        if random.next() >= delivery.loss {
            let taken = tick.saturating_sub(delivery.lag_ticks as usize);
            if delivered.is_none_or(|(_, t)| taken > t) {
                delivered = Some((history[taken], taken));
            }
        }
        let foreign: Vec<ForeignUav> = delivered
            .iter()
            .map(|&(state, taken)| ForeignUav { id: "b".into(), state, age_s: (tick - taken) as f64 * DT })
            .collect();
        fleet.set_foreign(&foreign);
        min_distance = min_distance.min((a.lock().unwrap().p - b.p).norm());
        fleet.tick();
        // B: towards its speed along −x, plus a random push, all within δ.
        let track = (Vec2::new(-speed, 0.0) - b.v) / DT;
        let angle = random.next() * std::f64::consts::TAU;
        let push = Vec2::new(angle.cos(), angle.sin()) * delta * random.next();
        b = b.stepped(uav::saturate(track * 0.5 + push, delta), DT);
        history.push(b);
    }
    min_distance.min((a.lock().unwrap().p - b.p).norm())
}

#[test]
fn a_fresh_foreign_uav_head_on_is_avoided() {
    let d_c = FleetConfig::default().params.d_c;
    let min = head_on_with_foreign(0.0, 2.0, Delivery { lag_ticks: 0, loss: 0.0 }, 1);
    assert!(min >= d_c - TOLERANCE_M, "true distance {min} < D_c {d_c}");
}

#[test]
fn the_foreign_uav_is_never_commanded_nor_counted_as_own() {
    let road = Road::new(RoadLayout::straight(0.0, 40.0, 6.0, 4)).unwrap(); // a valid layout
    let config = FleetConfig::default();
    let mut fleet = Fleet::new(config, road, PolicyRegistry::with_pd(config.params.delta));
    let b = UavState { p: Vec2::new(20.0, 0.0), v: Vec2::zeros() };
    fleet.set_foreign(&[ForeignUav { id: "b".into(), state: b, age_s: 0.2 }]);
    fleet.tick();
    assert!(fleet.uavs().is_empty());
    assert_eq!(fleet.foreign().len(), 1);
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 2000, ..ProptestConfig::default() })]

    /// Random offsets, speeds, lags of 0–1 s, message losses and random foreign commands: the true
    /// distance never drops below D_c (less the tolerance of sampled states).
    #[test]
    fn late_foreign_messages_never_lead_to_a_collision(
        offset in -1.0f64..1.0,
        speed in 0.0f64..3.0,
        lag_ticks in 0u32..=20,
        loss in 0.0f64..0.5,
        seed in any::<u64>(),
    ) {
        let d_c = FleetConfig::default().params.d_c;
        let min = head_on_with_foreign(offset, speed, Delivery { lag_ticks, loss }, seed);
        prop_assert!(min >= d_c - TOLERANCE_M, "true distance {} < D_c {}", min, d_c);
    }
}
