//! Whether the host ran a firmware in real time, and the tries of a flight that depends on it.
//!
//! The firmware's FreeRTOS POSIX port takes about 40 % of a core per process; a host that starves
//! it stalls the firmware for whole seconds (no motor commands: the physics' watchdog cuts the
//! motors), which fails a flight for the host's sake, not the flight's. [`DroneStats::slowest_second`]
//! shows it; [`Tries`] gives such a flight more tries, and skips rather than fails when none kept up.
//!
//! [`DroneStats::slowest_second`]: super::DroneStats::slowest_second

use super::SitlHandle;

/// A firmware that sent fewer motor packets than this in a second of physics (500 at its pace)
/// was not run in real time by the host.
pub const KEEPING_UP: u64 = 300;

impl SitlHandle {
    /// Why drone `i`'s flight says nothing about what it tested, if its firmware fell below
    /// [`KEEPING_UP`] in some second; `None` while it kept up (or has not run a whole second).
    pub fn fell_behind(&self, i: usize) -> Option<String> {
        let slowest = self.stats(i)?.slowest_second?;
        (slowest < KEEPING_UP).then(|| {
            format!(
                "the host did not run drone {i}'s firmware in real time ({slowest} motor packets in its \
                 slowest second, 500 at its pace)"
            )
        })
    }
}

/// The tries of a firmware flight: a failed flight gets one retry (the firmware's emulated clock
/// can slip under load); one whose firmware fell behind real time does not count, up to
/// [`Tries::MAX`] in all.
#[derive(Debug, Default)]
pub struct Tries {
    /// Every failure so far, with why it did not count when it did not.
    failures: Vec<String>,
    /// Failures of flights whose firmware kept up.
    counted: usize,
}

impl Tries {
    /// Flights tried at most.
    pub const MAX: usize = 4;

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
        self.counted < 2 && self.failures.len() < Self::MAX
    }

    /// After the last failed try: `Ok` with a skip message when no try's firmware kept up (the
    /// host could not run it), else `Err` with every failure.
    pub fn verdict(self) -> Result<String, String> {
        let all = self.failures.join(" / ");
        if self.counted == 0 {
            Ok(format!(
                "skipped: in {} tries the host never ran the firmware in real time: {all}",
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
    fn a_failure_gets_one_retry_and_a_host_that_never_kept_up_skips() {
        let mut tries = Tries::default();
        assert!(tries.failed("lost".into(), None), "one retry");
        assert!(!tries.failed("lost again".into(), None), "two counted failures end it");
        assert_eq!(tries.verdict(), Err("lost / lost again".into()));

        let mut tries = Tries::default();
        assert!(tries.failed("late".into(), Some("slow".into())));
        assert!(tries.failed("late".into(), Some("slow".into())));
        assert!(tries.failed("lost".into(), None), "one counted failure of three");
        assert!(!tries.failed("late".into(), Some("slow".into())), "four tries in all");
        assert!(tries.verdict().is_err(), "a counted failure and no pass fails");

        let mut tries = Tries::default();
        while tries.failed("late".into(), Some("slow".into())) {}
        let skip = tries.verdict().expect("every try fell behind: skipped");
        assert!(skip.starts_with("skipped: in 4 tries") && skip.contains("late (slow)"), "{skip}");
    }
}
