//! A UAV's condition in one tick: computed once, when the tick reads its link, from the phase the
//! link reports, whether the UAV was airborne when last heard from, and how long the link has been
//! silent. The tick's stages, the metrics and the server's status all read this one word.

use links::LinkPhase;

/// What a UAV is this tick, for the filter and for its neighbours.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Condition {
    /// Following commands on a fresh state: it flies its policy through the filter and shares pair
    /// rows with its cooperating neighbours.
    #[default]
    Cooperating,
    /// Following commands, but its link gave no state this tick (not lost yet): it is filtered on
    /// its last state; its neighbours keep D_c from its reach disk alone.
    Stale,
    /// In the air but not following commands (taking off, landing, an unconfirmed emergency stop):
    /// its link brakes it; its neighbours keep D_c from it alone.
    Transit,
    /// Silent for `stale_after`, or reconnecting, after it was airborne: it may be anywhere in its
    /// reach disk; it brakes and its neighbours keep D_c from the disk.
    Lost,
    /// On the ground (landed, stopped, or connecting without having flown): no rows, no obstacle.
    Grounded,
}

impl Condition {
    /// The condition of a UAV whose link reports `phase`, that was airborne when last heard from
    /// (`was_airborne`), whose link gave no fresh state for `stale_ticks` ticks, `silent` once that
    /// reaches `stale_after`.
    pub fn of(phase: LinkPhase, was_airborne: bool, stale_ticks: u32, silent: bool) -> Self {
        if was_airborne && (silent || phase == LinkPhase::Connecting) {
            Condition::Lost
        } else if phase == LinkPhase::Flying {
            if stale_ticks == 0 { Condition::Cooperating } else { Condition::Stale }
        } else if phase.airborne() {
            Condition::Transit
        } else {
            Condition::Grounded
        }
    }

    /// It flies its policy through the filter this tick (following commands, not lost).
    pub fn flying(self) -> bool {
        matches!(self, Condition::Cooperating | Condition::Stale)
    }

    /// In the air, or possibly so while lost: its neighbours must keep D_c from it.
    pub fn in_the_air(self) -> bool {
        self != Condition::Grounded
    }

    /// It shares pair rows with its neighbours: flying the filter on a fresh state. Any other UAV in
    /// the air is avoided by its neighbours alone, as its reach disk.
    pub fn cooperates(self) -> bool {
        self == Condition::Cooperating
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every combination: lost exactly when it was airborne and is silent or reconnecting; flying
    /// exactly when its link flies and it is not lost; in the air when its phase is airborne or it is
    /// lost; cooperating exactly when flying on a fresh state.
    #[test]
    fn conditions_follow_phase_memory_and_silence() {
        for phase in LinkPhase::ALL {
            for was_airborne in [false, true] {
                for (stale_ticks, silent) in [(0, false), (2, false), (9, true)] {
                    let c = Condition::of(phase, was_airborne, stale_ticks, silent);
                    let lost = was_airborne && (silent || phase == LinkPhase::Connecting);
                    assert_eq!(c == Condition::Lost, lost, "{phase:?} {was_airborne} {stale_ticks}");
                    assert_eq!(c.flying(), phase == LinkPhase::Flying && !lost, "{phase:?}");
                    assert_eq!(c.in_the_air(), phase.airborne() || lost, "{phase:?}");
                    assert_eq!(c.cooperates(), c.flying() && stale_ticks == 0, "{phase:?}");
                }
            }
        }
    }
}
