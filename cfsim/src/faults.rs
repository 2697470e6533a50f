//! Fault injection: packet loss and latency per direction, a full disconnection switch, and a
//! firmware that ignores emergency stops.

use crate::commands::Command;
use std::time::Duration;

/// Link faults, changeable at run time with [`crate::SimHandle::set_faults`].
///
/// "Up" is client → Crazyflie, "down" is Crazyflie → client. Loss is decided per datagram with
/// the simulator's seeded PRNG, so a run with the same seed and traffic drops the same datagrams.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Faults {
    /// Probability in [0, 1] that a datagram from the client is dropped.
    pub loss_up: f64,
    /// Probability in [0, 1] that a datagram to the client is dropped.
    pub loss_down: f64,
    /// Added delay before a datagram from the client is processed.
    pub latency_up: Duration,
    /// Added delay before a datagram to the client is sent.
    pub latency_down: Duration,
    /// Drop everything in both directions (out of radio range) until cleared.
    pub disconnected: bool,
    /// Ignore emergency stops (supervisor and localization ports) until cleared: they arrive and
    /// are counted ([`crate::LinkStats::stops_ignored`]) but the motors keep running and the
    /// supervisor does not lock. Stands for stop packets lost on the way however often they are
    /// sent.
    pub ignore_stop: bool,
}

impl Faults {
    /// No faults: a perfect link.
    pub const NONE: Self = Self {
        loss_up: 0.0,
        loss_down: 0.0,
        latency_up: Duration::ZERO,
        latency_down: Duration::ZERO,
        disconnected: false,
        ignore_stop: false,
    };

    /// Whether the firmware ignores `command` under these faults.
    pub fn ignores(&self, command: &Command) -> bool {
        self.ignore_stop && *command == Command::EmergencyStop
    }

    /// Whether a datagram in the given direction is dropped, drawing from `rng` only when needed.
    pub(crate) fn drops(&self, up: bool, rng: &mut Prng) -> bool {
        if self.disconnected {
            return true;
        }
        let p = if up { self.loss_up } else { self.loss_down };
        // NaN or <= 0 never drops; >= 1 always drops.
        if p.is_nan() || p <= 0.0 {
            return false;
        }
        p >= 1.0 || rng.next_f64() < p
    }
}

/// A small deterministic PRNG (SplitMix64), enough for loss decisions.
#[derive(Debug, Clone)]
pub struct Prng(u64);

impl Prng {
    /// A generator started from `seed`.
    pub fn new(seed: u64) -> Self {
        Self(seed)
    }

    /// The next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }

    /// A uniform sample in [0, 1).
    pub fn next_f64(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn loss_rate_is_close_to_the_probability_and_deterministic() {
        let f = Faults { loss_up: 0.2, ..Faults::NONE };
        let mut a = Prng::new(7);
        let mut b = Prng::new(7);
        let drops: Vec<bool> = (0..10_000).map(|_| f.drops(true, &mut a)).collect();
        let again: Vec<bool> = (0..10_000).map(|_| f.drops(true, &mut b)).collect();
        assert_eq!(drops, again);
        let rate = drops.iter().filter(|d| **d).count() as f64 / 10_000.0;
        assert!((rate - 0.2).abs() < 0.02, "rate {rate}");
        assert!(!f.drops(false, &mut a));
    }

    #[test]
    fn ignore_stop_ignores_emergency_stops_only() {
        let f = Faults { ignore_stop: true, ..Faults::NONE };
        assert!(f.ignores(&Command::EmergencyStop));
        assert!(!f.ignores(&Command::EmergencyStopWatchdog));
        assert!(!f.ignores(&Command::ExternalPosition([0.0; 3])));
        assert!(!Faults::NONE.ignores(&Command::EmergencyStop));
    }

    #[test]
    fn extremes_and_disconnection() {
        let mut r = Prng::new(1);
        let all = Faults { loss_down: 1.0, ..Faults::NONE };
        assert!((0..100).all(|_| all.drops(false, &mut r)));
        let nan = Faults { loss_down: f64::NAN, ..Faults::NONE };
        assert!(!nan.drops(false, &mut r));
        let off = Faults { disconnected: true, ..Faults::NONE };
        assert!(off.drops(true, &mut r) && off.drops(false, &mut r));
    }
}
