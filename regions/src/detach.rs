//! Crazyflies leaving the region (`handover`): a UAV whose link is a real connection leaves the
//! fleet as soon as its new owner accepted it (nothing commands it after that), its link is
//! detached (closed without landing; the Crazyflie holds its last setpoint), and the release goes
//! out only once the link is closed, so the new owner never opens a link the old one still holds.
//! Meanwhile the UAV is a ghost of this fleet: a reach disk growing from when it left.

use super::handover::record;
use super::loop_hook::RegionLoop;
use std::time::{Duration, Instant};

/// A detach that takes longer than this is logged (the session closes within 0.5 s).
const SLOW_DETACH: Duration = Duration::from_secs(1);

/// Takes the newest state the link gives (its last command went out in the last tick: that is
/// where the new owner takes it on).
fn settle(uav: &mut fleet::Uav) {
    uav.state = uav.link.state().filter(|s| s.is_finite()).unwrap_or(uav.state);
}

/// A UAV released to another region whose link is still closing.
pub(super) struct Detaching {
    uav: fleet::Uav,
    to: String,
    seq: u64,
    since: Instant,
    warned: bool,
}

impl RegionLoop {
    /// UAV `uav` has left the fleet for region `to` (offer `seq`): released at once if its link is
    /// closed (a simulated one), else detached and released by [`RegionLoop::release_detached`].
    pub(super) fn release(&mut self, mut uav: fleet::Uav, to: String, seq: u64) {
        let now = Instant::now();
        settle(&mut uav);
        if uav.link.detached() {
            self.handover.released(uav.id.clone(), to, seq, record(&uav), now);
            return;
        }
        uav.link.detach();
        self.handover.detaching(&uav.id, uav.state, now);
        self.detaching.push(Detaching { uav, to, seq, since: now, warned: false });
    }

    /// The UAVs whose links are closing, as the mirror lists them (a standby that takes over
    /// before their release flies them on; one that saw the release leaves them to the neighbour).
    pub(super) fn leaving(&self) -> Vec<super::failover::MirrorUav> {
        let record = |d: &Detaching| super::failover::MirrorUav { id: d.uav.id.clone(), uav: record(&d.uav) };
        self.detaching.iter().map(record).collect()
    }

    /// Releases the UAVs whose links have closed since the last gap (while the handover queue has
    /// room for their releases).
    pub(super) fn release_detached(&mut self) {
        if self.detaching.is_empty() {
            return;
        }
        let now = Instant::now();
        let mut waiting = Vec::with_capacity(self.detaching.len());
        for mut d in std::mem::take(&mut self.detaching) {
            if !d.uav.link.detached() || !self.handover.can_send() {
                if !d.warned && now.saturating_duration_since(d.since) > SLOW_DETACH {
                    d.warned = true;
                    tracing::warn!("UAV `{}`: its link has not closed after {SLOW_DETACH:?}", d.uav.id);
                }
                waiting.push(d);
                continue;
            }
            settle(&mut d.uav);
            self.handover.released(d.uav.id.clone(), d.to, d.seq, record(&d.uav), now);
        }
        self.detaching = waiting;
    }
}
