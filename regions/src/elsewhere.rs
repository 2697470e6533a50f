//! The newest state message of every other region, kept as received for the dashboard: the binary
//! stream (`/ws?format=bin`) passes each one on to its clients as a kind 4 frame (the regions'
//! own format, docs/regions.md), so a dashboard connected to any region draws the whole
//! fleet. Nothing here is decoded or used by the fleet loop, and a message is copied out of Zenoh's
//! buffers only when a stream client is sent it (once, whatever the number of clients).

use bytes::Bytes;
use std::collections::HashMap;
use std::sync::{Mutex, MutexGuard, OnceLock, PoisonError};
use std::time::{Duration, Instant};

/// A region's message older than this is no longer sent (the region stopped publishing).
pub const SHOWN_FOR: Duration = Duration::from_secs(2);

/// One region's newest message.
#[derive(Debug)]
struct Latest {
    seq: u64,
    at: Instant,
    payload: zenoh::bytes::ZBytes,
    /// `payload` in one piece, made for the first client sent it.
    contiguous: OnceLock<Bytes>,
}

/// The newest message per other region.
#[derive(Debug, Default)]
pub struct Elsewhere {
    regions: Mutex<HashMap<String, Latest>>,
}

impl Elsewhere {
    fn lock(&self) -> MutexGuard<'_, HashMap<String, Latest>> {
        // Plain data replaced whole: a panic elsewhere cannot leave it half-written.
        self.regions.lock().unwrap_or_else(PoisonError::into_inner)
    }

    /// Keeps `payload` as region `region`'s newest message (received at `at`).
    pub fn put(&self, region: &str, payload: zenoh::bytes::ZBytes, at: Instant) {
        let mut regions = self.lock();
        let seq = regions.get(region).map_or(1, |l| l.seq + 1);
        regions.insert(region.to_string(), Latest { seq, at, payload, contiguous: OnceLock::new() });
    }

    /// The messages a client has not `seen` (region → the number it has), no older than
    /// [`SHOWN_FOR`] at `now`; updates `seen`.
    pub fn unseen(&self, seen: &mut HashMap<String, u64>, now: Instant) -> Vec<Bytes> {
        let regions = self.lock();
        let mut out = Vec::new();
        for (name, latest) in regions.iter() {
            let fresh = now.saturating_duration_since(latest.at) < SHOWN_FOR;
            if fresh && seen.get(name).is_none_or(|s| *s < latest.seq) {
                seen.insert(name.clone(), latest.seq);
                let bytes =
                    latest.contiguous.get_or_init(|| Bytes::from(latest.payload.to_bytes().into_owned()));
                out.push(bytes.clone());
            }
        }
        out
    }
}

/// The region named by a state key `<prefix>/region/<name>/state` (None for any other key).
pub fn region_of_key<'k>(prefix: &str, key: &'k str) -> Option<&'k str> {
    let name = key.strip_prefix(prefix)?.strip_prefix("/region/")?.strip_suffix("/state")?;
    (!name.is_empty() && !name.contains('/')).then_some(name)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_message_is_sent_once_per_client_and_not_when_stale() {
        let elsewhere = Elsewhere::default();
        let t0 = Instant::now();
        elsewhere.put("east", b"e1".to_vec().into(), t0);
        elsewhere.put("north", b"n1".to_vec().into(), t0);
        let mut seen = HashMap::new();
        let mut first = elsewhere.unseen(&mut seen, t0);
        first.sort();
        assert_eq!(first, [Bytes::from_static(b"e1"), Bytes::from_static(b"n1")]);
        assert!(elsewhere.unseen(&mut seen, t0).is_empty(), "nothing new");
        elsewhere.put("east", b"e2".to_vec().into(), t0 + Duration::from_secs(1));
        let later = t0 + Duration::from_millis(2500);
        // The new east message is 1.5 s old and sent; north's is 2.5 s old and not.
        assert_eq!(elsewhere.unseen(&mut HashMap::new(), later), [Bytes::from_static(b"e2")]);
    }

    #[test]
    fn the_region_is_read_from_its_state_key_only() {
        assert_eq!(region_of_key("airroads", "airroads/region/west/state"), Some("west"));
        assert_eq!(region_of_key("a/b", "a/b/region/x-1/state"), Some("x-1"));
        for key in ["airroads/region/west/mirror", "airroads/region//state", "other/region/w/state"] {
            assert_eq!(region_of_key("airroads", key), None, "{key}");
        }
    }
}
