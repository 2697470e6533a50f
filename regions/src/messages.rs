//! The handover protocol's messages (`handover`), JSON on the key `PREFIX/region/<to>/handover/<from>`
//! (docs/regions.md, Handover): `offer`, `accept`, `refuse`, `release`.

use engine::snapshot::UavSnapshot;
use serde::{Deserialize, Serialize};
use uav::{UavState, Vec2};

/// Everything the new owner needs to fly a UAV on.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct UavRecord {
    /// Position (m).
    pub p: [f64; 2],
    /// Velocity (m/s).
    pub v: [f64; 2],
    /// Its goal (None: it hovers).
    pub goal: Option<[f64; 2]>,
    /// Its policy's name.
    pub policy: String,
    /// Its link (None: simulated in the owner's process).
    pub link: Option<String>,
    /// It was in the air when recorded: its new owner avoids it as lost until its link reports.
    #[serde(default)]
    pub airborne: bool,
}

impl UavRecord {
    /// The record of a UAV as a snapshot shows it (link None for a simulated one).
    pub fn of_snapshot(u: &UavSnapshot) -> Self {
        Self {
            p: u.p,
            v: u.v,
            goal: u.goal,
            policy: u.policy.to_string(),
            link: (*u.link != *links::SIM_LINK).then(|| u.link.to_string()),
            airborne: u.lost || u.phase.airborne(),
        }
    }

    /// The record's state.
    pub fn state(&self) -> UavState {
        UavState { p: Vec2::new(self.p[0], self.p[1]), v: Vec2::new(self.v[0], self.v[1]) }
    }
}

/// A handover message, on the key `PREFIX/region/<to>/handover/<from>` (JSON).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum Message {
    /// `from` offers UAV `id` to `to`; `seq` names this offer.
    Offer {
        /// The owner.
        from: String,
        /// The region asked to take it.
        to: String,
        /// The UAV.
        id: String,
        /// The offer's number (per owner).
        seq: u64,
        /// The UAV as it is now.
        uav: UavRecord,
    },
    /// `from` has reserved the id and will take the UAV when released.
    Accept {
        /// The region taking it.
        from: String,
        /// The owner.
        to: String,
        /// The UAV.
        id: String,
        /// The offer answered.
        seq: u64,
    },
    /// `from` will not take the UAV (`reason` says why); the owner keeps flying it.
    Refuse {
        /// The region asked.
        from: String,
        /// The owner.
        to: String,
        /// The UAV.
        id: String,
        /// The offer answered.
        seq: u64,
        /// Why not.
        reason: String,
    },
    /// `from` no longer commands the UAV: `to` owns it from now on, with this record.
    Release {
        /// The old owner.
        from: String,
        /// The new owner.
        to: String,
        /// The UAV.
        id: String,
        /// The accepted offer.
        seq: u64,
        /// The UAV when released.
        uav: UavRecord,
    },
}

impl Message {
    /// The region the message is for.
    pub fn to(&self) -> &str {
        match self {
            Message::Offer { to, .. }
            | Message::Accept { to, .. }
            | Message::Refuse { to, .. }
            | Message::Release { to, .. } => to,
        }
    }

    /// The region that sent it.
    pub fn from(&self) -> &str {
        match self {
            Message::Offer { from, .. }
            | Message::Accept { from, .. }
            | Message::Refuse { from, .. }
            | Message::Release { from, .. } => from,
        }
    }
}
