//! Whether a firmware ran in real time, and the tries of a flight that depends on it.
//!
//! The firmware's FreeRTOS POSIX port takes about 35 % of a core per process and does not always
//! keep its pace: under host load, and at times with a third of the host's CPU idle (measured on
//! 2026-12-07 on 2 cores: one to three firmwares silent at once, their log stream first, then their
//! motor commands, for up to a whole second), it stalls; the physics' watchdog then cuts the
//! motors. Such a flight fails for the firmware's sake, not the server's.
//! [`DroneStats::motor_watchdog_cuts`] and [`DroneStats::slowest_second`] show it; [`Tries`] gives
//! such a flight more tries, and skips rather than fails when none kept up.
//!
//! [`DroneStats::motor_watchdog_cuts`]: super::DroneStats::motor_watchdog_cuts
//! [`DroneStats::slowest_second`]: super::DroneStats::slowest_second

use super::SitlHandle;

/// A firmware that sent fewer motor packets than this in a second of physics (500 at its pace)
/// did not run in real time.
pub const KEEPING_UP: u64 = 300;

impl SitlHandle {
    /// Why drone `i`'s flight says nothing about what it tested, if its firmware went silent in
    /// flight (the physics cut its spinning motors after 100 ms without a motor packet: it fell,
    /// which the firmware's own watchdog would have prevented on a real Crazyflie) or fell below
    /// [`KEEPING_UP`] in some second; `None` while it kept up (or has not run a whole second).
    pub fn fell_behind(&self, i: usize) -> Option<String> {
        let stats = self.stats(i)?;
        if stats.motor_watchdog_cuts > 0 {
            return Some(format!(
                "drone {i}'s firmware went silent in flight: the physics cut its motors {} time(s) after \
                 100 ms without a motor packet",
                stats.motor_watchdog_cuts
            ));
        }
        let slowest = stats.slowest_second?;
        (slowest < KEEPING_UP).then(|| {
            format!(
                "drone {i}'s firmware did not run in real time ({slowest} motor packets in its slowest \
                 second, 500 at its pace)"
            )
        })
    }
}

/// The tries of a firmware flight: a failed flight gets one retry (the firmware's emulated clock
/// can slip under load), however many tries before it did not count; one whose firmware fell
/// behind real time does not count, up to [`Tries::MAX_BEHIND`] of them.
#[derive(Debug, Default)]
pub struct Tries {
    /// Every failure so far, with why it did not count when it did not.
    failures: Vec<String>,
    /// Failures of flights whose firmware kept up.
    counted: usize,
}

impl Tries {
    /// Tries whose firmware fell behind, at most.
    pub const MAX_BEHIND: usize = 4;

    /// Records a failed try (`behind`: why it does not count, from [`SitlHandle::fell_behind`]);
    /// true when another try is due.
    pub fn failed(&mut self, reason: String, behind: Option<String>) -> bool {
        match behind {
            Some(behind) => self.failures.push(format!("{reason} ({behind})")),
            None => {
                self.failures.push(reason);
                self.counted += 1;
            }
        }
        self.counted < 2 && self.failures.len() - self.counted < Self::MAX_BEHIND
    }

    /// After the last failed try: `Ok` with a skip message when no try's firmware kept up, else
    /// `Err` with every failure.
    pub fn verdict(self) -> Result<String, String> {
        let all = self.failures.join(" / ");
        if self.counted == 0 {
            Ok(format!(
                "skipped: in {} tries the firmware never ran in real time: {all}",
                self.failures.len()
            ))
        } else {
            Err(all)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::Tries;

    #[test]
    fn a_failure_gets_one_retry_and_a_firmware_that_never_kept_up_skips() {
        let mut tries = Tries::default();
        assert!(tries.failed("lost".into(), None), "one retry");
        assert!(!tries.failed("lost again".into(), None), "two counted failures end it");
        assert_eq!(tries.verdict(), Err("lost / lost again".into()));

        let mut tries = Tries::default();
        for _ in 0..3 {
            assert!(tries.failed("late".into(), Some("slow".into())));
        }
        assert!(tries.failed("lost".into(), None), "a counted failure after three slow tries gets its retry");
        assert!(!tries.failed("late".into(), Some("slow".into())), "the fourth slow try ends it");
        assert!(tries.verdict().is_err(), "a counted failure and no pass fails");

        let mut tries = Tries::default();
        while tries.failed("late".into(), Some("slow".into())) {}
        let skip = tries.verdict().expect("every try fell behind: skipped");
        assert!(skip.starts_with("skipped: in 4 tries") && skip.contains("late (slow)"), "{skip}");
    }
}
