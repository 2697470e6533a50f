//! Every message from another region is untrusted input (docs/regions.md, Security):
//! before a neighbour's states reach the fleet they are screened as strictly as a REST body, and
//! every refusal is counted by name in `GET /api/metrics` `region.peer_refused`.
//!
//! A state message is refused whole (the region's previous entry stays and ages, so its UAVs'
//! reach disks grow: safe, never blind) when its sender sends faster than [`MESSAGES_PER_SECOND`]
//! allows, names a region the road does not have, lists more than [`MAX_UAVS_PER_REGION`] UAVs, an
//! id that breaks the id rule or comes twice, or a UAV farther than [`NEAR_M`] from the sender's
//! segments (and the one next to each end, where its UAVs cross or are handed over); on a network,
//! farther than [`NEAR_M`] from the box of every cell of the sender's region and of every cell a
//! passage joins to one of them.

use roads::Airspace;
use serde::Serialize;
use std::collections::{HashMap, HashSet};
use std::sync::atomic::{AtomicU64, Ordering::Relaxed};
use std::sync::{Arc, Mutex, MutexGuard, PoisonError};
use std::time::Instant;

/// Most UAVs one region's message may list (a region server flies at most `--max-uavs`; 10,000
/// UAVs over four regions is 2,500 each).
pub const MAX_UAVS_PER_REGION: usize = 16_384;
/// A UAV may be this far outside its region's segments (m): a lost UAV drifting, a braking one.
pub const NEAR_M: f64 = 10.0;
/// State messages a region may send per second on average (two per tick at 20 Hz).
pub const MESSAGES_PER_SECOND: f64 = 40.0;
/// State messages a region may send at once.
pub const MESSAGE_BURST: f64 = 8.0;

/// Refusals of other regions' messages, by reason (`region.peer_refused`).
#[derive(Debug, Default, Serialize, schemars::JsonSchema)]
pub struct PeerRefusals {
    /// State messages beyond the sender's rate.
    pub too_fast: AtomicU64,
    /// Messages from or naming a region the road does not have.
    pub unknown_region: AtomicU64,
    /// State messages listing more than [`MAX_UAVS_PER_REGION`] UAVs.
    pub too_many_uavs: AtomicU64,
    /// Messages with an id that breaks the id rule, or the same id twice.
    pub bad_id: AtomicU64,
    /// State messages with a UAV far from the sender's segments.
    pub far_from_region: AtomicU64,
    /// Releases that answer no offer this region accepted from that sender.
    pub unrequested_release: AtomicU64,
    /// Offers or releases whose UAV would not be safe here (outside the road, within D_c of a UAV,
    /// over `--max-uavs`, an id another region flies).
    pub unsafe_uav: AtomicU64,
    /// Offers beyond the number one sender may have waiting.
    pub too_many_offers: AtomicU64,
}

impl PeerRefusals {
    /// Counts one refusal.
    pub fn count(counter: &AtomicU64) {
        counter.fetch_add(1, Relaxed);
    }
}

/// Why a state message was refused.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum Refusal {
    /// Faster than its rate.
    #[error("faster than {MESSAGES_PER_SECOND} messages per second")]
    TooFast,
    /// Not a region of the road.
    #[error("region `{0}` is not on the road")]
    UnknownRegion(String),
    /// Too many UAVs.
    #[error("{0} UAVs, more than {MAX_UAVS_PER_REGION}")]
    TooManyUavs(usize),
    /// An id breaks the rule or repeats.
    #[error("UAV id `{0}`: {1}")]
    BadId(String, String),
    /// A UAV far from the region.
    #[error("UAV `{0}` is more than {NEAR_M} m from region `{1}`'s segments")]
    Far(String, String),
}

/// Where a region's UAVs may be: on a road its segment range widened by one at each end, on a
/// network its cells and those a passage joins to them.
#[derive(Debug)]
enum Extent {
    Segments(usize, usize),
    Cells(HashSet<usize>),
}

/// The road or network as the screen needs it: each region's extent.
#[derive(Debug)]
struct Geography {
    space: Airspace,
    extents: HashMap<String, Extent>,
}

impl Geography {
    /// Each region's extent on `space`; O(cells + passages).
    fn new(space: &Airspace) -> Self {
        let extents = match space {
            Airspace::Road(road) => {
                let last = road.quads().len().saturating_sub(1);
                let regions = road.layout().regions.iter().flatten();
                regions
                    .map(|r| {
                        let extent = Extent::Segments(r.first().saturating_sub(1), (r.last() + 1).min(last));
                        (r.name.clone(), extent)
                    })
                    .collect()
            }
            Airspace::Network(net) => {
                let mut cells: HashMap<String, HashSet<usize>> = HashMap::new();
                for c in 0..net.cells().len() {
                    let Some(region) = net.region_of(c) else { continue };
                    let set = cells.entry(region.name.clone()).or_default();
                    set.insert(c);
                    set.extend(net.passages(c).iter().map(|p| p.other));
                }
                cells.into_iter().map(|(name, set)| (name, Extent::Cells(set))).collect()
            }
        };
        Self { space: space.clone(), extents }
    }
}

#[derive(Debug, Clone, Copy)]
struct Bucket {
    left: f64,
    at: Instant,
}

/// Screens the other regions' messages for one region server.
#[derive(Debug, Default)]
pub struct Screen {
    geography: Mutex<Option<Arc<Geography>>>,
    buckets: Mutex<HashMap<String, Bucket>>,
    /// The refusals so far.
    pub refused: PeerRefusals,
}

fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    // Plain data replaced whole: a panic elsewhere cannot leave it half-written.
    m.lock().unwrap_or_else(PoisonError::into_inner)
}

impl Screen {
    /// The road or network now served (called by the loop whenever it changes).
    pub fn set_road(&self, space: &Airspace) {
        *lock(&self.geography) = Some(Arc::new(Geography::new(space)));
    }

    fn geography(&self) -> Option<Arc<Geography>> {
        lock(&self.geography).clone()
    }

    /// True when `name` is a region of the served road.
    pub fn knows(&self, name: &str) -> bool {
        self.geography().is_some_and(|g| g.extents.contains_key(name))
    }

    /// Takes one message of `region` from its rate allowance at `now` (refused beyond it; counted).
    pub fn admit(&self, region: &str, now: Instant) -> Result<(), Refusal> {
        let mut buckets = lock(&self.buckets);
        if !buckets.contains_key(region) && !self.knows(region) {
            PeerRefusals::count(&self.refused.unknown_region);
            return Err(Refusal::UnknownRegion(region.into()));
        }
        let bucket = buckets.entry(region.to_string()).or_insert(Bucket { left: MESSAGE_BURST, at: now });
        let refill = now.saturating_duration_since(bucket.at).as_secs_f64() * MESSAGES_PER_SECOND;
        bucket.left = (bucket.left + refill).min(MESSAGE_BURST);
        bucket.at = now;
        if bucket.left < 1.0 {
            PeerRefusals::count(&self.refused.too_fast);
            return Err(Refusal::TooFast);
        }
        bucket.left -= 1.0;
        Ok(())
    }

    /// Checks region `region`'s list of UAVs `(id, position)`: their number, ids and positions
    /// (see the module documentation); a refusal is counted.
    pub fn check_states<'a>(
        &self,
        region: &str,
        uavs: impl ExactSizeIterator<Item = (&'a str, [f64; 2])>,
    ) -> Result<(), Refusal> {
        let refusal = |counter: &AtomicU64, r: Refusal| {
            PeerRefusals::count(counter);
            Err(r)
        };
        let Some(geography) = self.geography() else {
            return refusal(&self.refused.unknown_region, Refusal::UnknownRegion(region.into()));
        };
        let Some(extent) = geography.extents.get(region) else {
            return refusal(&self.refused.unknown_region, Refusal::UnknownRegion(region.into()));
        };
        if uavs.len() > MAX_UAVS_PER_REGION {
            return refusal(&self.refused.too_many_uavs, Refusal::TooManyUavs(uavs.len()));
        }
        let mut seen = HashSet::with_capacity(uavs.len());
        let mut hint = None;
        for (id, [x, y]) in uavs {
            if let Err(e) = uav::check_uav_id(id) {
                return refusal(&self.refused.bad_id, Refusal::BadId(id.into(), e));
            }
            if !seen.insert(id) {
                return refusal(&self.refused.bad_id, Refusal::BadId(id.into(), "listed twice".into()));
            }
            let p = uav::Vec2::new(x, y);
            let near = match (&geography.space, extent) {
                (Airspace::Road(road), &Extent::Segments(first, last)) => {
                    let s = road.locate(&p, hint);
                    hint = Some(s);
                    // Located in the range (a UAV off the road is located in the segment it is
                    // nearest), or outside it but near one of its two end segments (crossing
                    // into a neighbour's).
                    let quads = road.quads();
                    let near = |s: usize| quads[s].margin(&p) >= -NEAR_M;
                    ((first..=last).contains(&s) && near(s)) || near(first) || near(last)
                }
                (Airspace::Network(net), Extent::Cells(cells)) => {
                    net.cells_near(&p, NEAR_M).any(|c| cells.contains(&c))
                }
                _ => false,
            };
            if !near {
                return refusal(&self.refused.far_from_region, Refusal::Far(id.into(), region.into()));
            }
        }
        Ok(())
    }

    /// `region.peer_refused` of `GET /api/metrics`.
    pub fn report(&self) -> &PeerRefusals {
        &self.refused
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use roads::{Region, Road, RoadLayout};
    use std::time::Duration;

    fn screen() -> Screen {
        // Six 5 m segments along x from 0 to 30, 4 m wide; a = 0-1, b = 2-3, c = 4-5.
        let mut layout = RoadLayout::straight(0.0, 30.0, 4.0, 6);
        let region = |name: &str, first, last| Region { name: name.into(), segments: [first, last] };
        layout.regions = Some(vec![region("a", 0, 1), region("b", 2, 3), region("c", 4, 5)]);
        let screen = Screen::default();
        screen.set_road(&Road::new(layout).unwrap().into()); // a valid layout
        screen
    }

    fn check(s: &Screen, region: &str, uavs: &[(&str, [f64; 2])]) -> Result<(), Refusal> {
        s.check_states(region, uavs.iter().copied())
    }

    #[test]
    fn states_in_or_near_the_senders_segments_pass() {
        let s = screen();
        // b's own segments, the segment past each end, and a lost UAV drifting 5 m off the road.
        assert_eq!(check(&s, "b", &[("u1", [12.0, 0.0]), ("u2", [6.0, 1.0]), ("u3", [23.0, 0.0])]), Ok(()));
        assert_eq!(check(&s, "b", &[("lost", [14.0, 7.0])]), Ok(()));
        assert_eq!(check(&s, "b", &[]), Ok(()));
    }

    #[test]
    fn phantoms_far_away_bad_ids_and_unknown_regions_are_refused_by_name() {
        let s = screen();
        assert!(matches!(
            check(&s, "a", &[("u1", [2.0, 0.0]), ("x", [9000.0, 9000.0])]),
            Err(Refusal::Far(..))
        ));
        // Inside the road but in a's segments is not near c.
        assert!(matches!(check(&s, "c", &[("u1", [1.0, 0.0])]), Err(Refusal::Far(..))));
        for bad in ["has space", "a/b", &"x".repeat(330)] {
            assert!(matches!(check(&s, "a", &[(bad, [2.0, 0.0])]), Err(Refusal::BadId(..))), "{bad}");
        }
        let dup = check(&s, "a", &[("dup", [2.0, 0.0]), ("dup", [3.0, 0.0])]);
        assert!(matches!(dup, Err(Refusal::BadId(_, ref why)) if why == "listed twice"));
        assert_eq!(check(&s, "zz", &[]), Err(Refusal::UnknownRegion("zz".into())));
        let report = serde_json::to_value(s.report()).unwrap();
        assert_eq!(report["far_from_region"], 2);
        assert_eq!(report["bad_id"], 4);
        assert_eq!(report["unknown_region"], 1);
    }

    #[test]
    fn on_a_network_states_in_or_next_to_the_senders_cells_pass_and_others_are_refused() {
        let s = Screen::default();
        s.set_road(&crate::test_network::tee_in_three());
        // The stem's cells, the junction a passage joins to them, a UAV drifting 5 m off the stem.
        assert_eq!(
            check(&s, "stem", &[("u1", [0.0, -10.0]), ("u2", [0.0, 0.0]), ("u3", [7.0, -15.0])]),
            Ok(())
        );
        // The east road's far end is 16 m from the junction's box.
        assert!(matches!(check(&s, "stem", &[("u1", [18.0, 0.0])]), Err(Refusal::Far(..))));
        // West holds the junction: the stem's first cell is next to it, its last is not.
        assert_eq!(
            check(&s, "west", &[("u1", [0.0, -4.0]), ("u2", [-19.0, 0.0]), ("u3", [13.0, 0.0])]),
            Ok(())
        );
        assert!(matches!(check(&s, "west", &[("u1", [0.0, -19.0])]), Err(Refusal::Far(..))));
        assert!(s.knows("east") && !s.knows("a"));
    }

    #[test]
    fn too_many_uavs_are_refused_before_looking_at_them() {
        let s = screen();
        let ids: Vec<String> = (0..=MAX_UAVS_PER_REGION).map(|k| format!("u{k}")).collect();
        let uavs = ids.iter().map(|id| (id.as_str(), [2.0, 0.0]));
        assert_eq!(s.check_states("a", uavs), Err(Refusal::TooManyUavs(MAX_UAVS_PER_REGION + 1)));
    }

    #[test]
    fn a_sender_faster_than_its_rate_is_refused_and_regains_its_allowance() {
        let s = screen();
        let t0 = Instant::now();
        for _ in 0..MESSAGE_BURST as usize {
            assert_eq!(s.admit("a", t0), Ok(()));
        }
        assert_eq!(s.admit("a", t0), Err(Refusal::TooFast));
        assert_eq!(s.admit("b", t0), Ok(()), "another sender has its own allowance");
        assert_eq!(s.admit("a", t0 + Duration::from_millis(50)), Ok(()));
        assert_eq!(s.admit("nowhere", t0), Err(Refusal::UnknownRegion("nowhere".into())));
    }
}
