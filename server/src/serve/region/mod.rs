//! Regions over Zenoh (`airroads serve --region NAME`, README "Regions over Zenoh"): this server
//! flies the UAVs of one region of the road; every tick it publishes their states under
//! [`state_key`] and it subscribes to the regions next to its own, whose UAVs its fleet avoids as
//! foreign UAVs (`fleet/src/foreign.rs`).
//!
//! Nothing here can make the fleet loop wait: the loop replaces a `watch` value with each snapshot
//! (the publishing task sends the newest one it has, skipping any it was too slow for) and copies
//! the foreign UAVs out of a [`ForeignTable`] that the subscriber's callback fills.

mod engine_side;
pub mod handover;
pub mod messages;
pub mod ownership;
pub mod table;
pub mod wire;

pub use handover::Handover;
pub use ownership::OwnershipLog;
pub use table::ForeignTable;

use super::snapshot::Snapshot;
use anyhow::Context as _;
use roads::Road;
use std::path::PathBuf;
use std::sync::atomic::{AtomicU64, Ordering::Relaxed};
use std::sync::mpsc::SyncSender;
use std::sync::{Arc, Mutex, PoisonError};
use std::time::Instant;
use tokio::sync::watch;

/// Largest payload read from a neighbour (bytes): far above 10,000 UAVs' worth.
pub const MAX_PAYLOAD_BYTES: usize = 16 << 20;

/// How `serve --region` joins Zenoh.
#[derive(Debug, Clone, Default)]
pub struct ZenohOptions {
    /// Endpoints to listen on (`tcp/HOST:PORT`).
    pub listen: Vec<String>,
    /// Endpoints to connect to.
    pub connect: Vec<String>,
    /// A Zenoh configuration file (JSON5, Zenoh's own format), applied first.
    pub config_file: Option<PathBuf>,
    /// The first chunks of every key (`--zenoh-prefix`).
    pub prefix: String,
}

/// The key a region's states are published under: `<prefix>/region/<name>/state`.
pub fn state_key(prefix: &str, region: &str) -> String {
    format!("{prefix}/region/{region}/state")
}

/// The key a region's handover messages go to: `<prefix>/region/<name>/handover`.
pub fn handover_key(prefix: &str, region: &str) -> String {
    format!("{prefix}/region/{region}/handover")
}

/// Handover messages waiting in either direction at most (the loop drops beyond; see `handover`).
pub const HANDOVER_QUEUE: usize = 1024;

/// Checks a key prefix: one or more chunks of `A-Z a-z 0-9 _ -` separated by `/` (no wildcards).
pub fn check_prefix(prefix: &str) -> Result<(), String> {
    let chunk_ok =
        |c: &str| !c.is_empty() && c.chars().all(|ch| ch.is_ascii_alphanumeric() || ch == '_' || ch == '-');
    if prefix.split('/').all(chunk_ok) {
        Ok(())
    } else {
        Err(format!("`{prefix}`: expected chunks of A-Z a-z 0-9 _ - separated by /"))
    }
}

/// The regions next to `name` on `road` (whose segment range touches its own), by segment order;
/// the error names the region and the known ones.
pub fn neighbours_of(road: &Road, name: &str) -> Result<Vec<String>, String> {
    let regions = road.layout().regions.as_deref().unwrap_or_default();
    let known = || regions.iter().map(|r| r.name.as_str()).collect::<Vec<_>>().join(", ");
    let Some(own) = regions.iter().find(|r| r.name == name) else {
        return Err(if regions.is_empty() {
            format!("`{name}`: the road has no regions")
        } else {
            format!("`{name}`: the road has no such region (known: {})", known())
        });
    };
    let mut next: Vec<&roads::Region> = regions
        .iter()
        .filter(|r| r.name != name && (r.last() + 1 == own.first() || own.last() + 1 == r.first()))
        .collect();
    next.sort_by_key(|r| r.first());
    Ok(next.into_iter().map(|r| r.name.clone()).collect())
}

/// The Zenoh configuration: the file's if given, then the endpoints. With endpoints given, multicast
/// scouting is off (only the endpoints named are used, so separate deployments, and tests run side
/// by side, never find each other).
pub fn zenoh_config(options: &ZenohOptions) -> anyhow::Result<zenoh::Config> {
    let mut config = match &options.config_file {
        Some(file) => zenoh::Config::from_file(file)
            .map_err(|e| anyhow::anyhow!("{e}"))
            .with_context(|| format!("--zenoh-config {}", file.display()))?,
        None => zenoh::Config::default(),
    };
    let set = |config: &mut zenoh::Config, key: &str, value: String| {
        config.insert_json5(key, &value).map_err(|e| anyhow::anyhow!("{key}: {e}"))
    };
    for (key, endpoints, flag) in [
        ("listen/endpoints", &options.listen, "--zenoh-listen"),
        ("connect/endpoints", &options.connect, "--zenoh-connect"),
    ] {
        if !endpoints.is_empty() {
            let list = serde_json::to_string(endpoints)?;
            set(&mut config, key, list).with_context(|| format!("{flag} {}", endpoints.join(" ")))?;
        }
    }
    if !(options.listen.is_empty() && options.connect.is_empty()) {
        set(&mut config, "scouting/multicast/enabled", "false".into())?;
    }
    Ok(config)
}

/// A snapshot on its way to the publishing task, with when its states were read.
#[derive(Debug, Clone)]
pub struct Published {
    /// The fleet after a tick.
    pub snapshot: Arc<Snapshot>,
    /// When that tick started (its states were read just after).
    pub read_at: Instant,
}

/// What the fleet loop and `GET /api/metrics` share with the region's Zenoh side.
#[derive(Debug, Clone)]
pub struct RegionShared {
    /// This server's region.
    pub name: String,
    /// The neighbours' UAVs, for the loop to copy before each tick.
    pub foreign: Arc<ForeignTable>,
    /// Where the loop puts each tick's snapshot for the publishing task.
    pub published: Arc<watch::Sender<Option<Published>>>,
    /// Who owned which UAV when (`GET /api/region/ownership`).
    pub ownership: Arc<OwnershipLog>,
    /// The handover counters, as the loop last wrote them.
    pub handover_counts: Arc<Mutex<handover::HandoverCounts>>,
    /// Handover messages received, for the loop.
    inbox: SyncSender<handover::Message>,
    /// Handover messages received that the loop's queue had no room for.
    inbox_dropped: Arc<AtomicU64>,
    /// The loop's side of the handover (taken once by the loop).
    handover: Arc<Mutex<Option<Handover>>>,
    /// Handover messages the loop sends (taken once by the Zenoh side).
    outbox: Arc<Mutex<Option<tokio::sync::mpsc::Receiver<handover::Message>>>>,
}

impl RegionShared {
    /// A new, empty side for region `name`.
    pub fn new(name: &str) -> Self {
        let ownership = Arc::new(OwnershipLog::default());
        let (inbox, inbox_rx) = std::sync::mpsc::sync_channel(HANDOVER_QUEUE);
        let (outbox_tx, outbox) = tokio::sync::mpsc::channel(HANDOVER_QUEUE);
        let handover = Handover::new(name, inbox_rx, outbox_tx, ownership.clone());
        Self {
            name: name.into(),
            foreign: Arc::new(ForeignTable::new(name)),
            published: Arc::new(watch::channel(None).0),
            ownership,
            handover_counts: Arc::default(),
            inbox,
            inbox_dropped: Arc::default(),
            handover: Arc::new(Mutex::new(Some(handover))),
            outbox: Arc::new(Mutex::new(Some(outbox))),
        }
    }

    /// The loop's side of the handover protocol (Some once).
    pub fn take_handover(&self) -> Option<Handover> {
        self.handover.lock().unwrap_or_else(PoisonError::into_inner).take()
    }

    /// `GET /api/metrics` `region`: the neighbours' table and the handover counters.
    pub fn report(&self, now: Instant) -> serde_json::Value {
        let mut doc = self.foreign.report(now);
        let counts = *self.handover_counts.lock().unwrap_or_else(PoisonError::into_inner);
        let mut handover = serde_json::to_value(counts).unwrap_or_default();
        handover["dropped"] = (counts.dropped + self.inbox_dropped.load(Relaxed)).into();
        doc["handover"] = handover;
        doc
    }
}

/// The running Zenoh side: the session (closed when dropped) and its subscribers.
pub struct RegionLink {
    /// The Zenoh session.
    pub session: zenoh::Session,
    _subscribers: Vec<zenoh::pubsub::Subscriber<()>>,
}

/// Opens the Zenoh session, subscribes to `neighbours` and starts publishing `shared`'s snapshots.
pub async fn start(
    options: &ZenohOptions,
    shared: &RegionShared,
    neighbours: &[String],
) -> anyhow::Result<RegionLink> {
    let config = zenoh_config(options)?;
    let session = zenoh::open(config).await.map_err(|e| anyhow::anyhow!("opening the Zenoh session: {e}"))?;
    let mut subscribers = Vec::new();
    for name in neighbours {
        let key = state_key(&options.prefix, name);
        let (table, expected) = (shared.foreign.clone(), name.clone());
        let subscriber = session
            .declare_subscriber(key.as_str())
            .callback(move |sample| receive(&table, &expected, sample.payload()))
            .await
            .map_err(|e| anyhow::anyhow!("subscribing to {key}: {e}"))?;
        subscribers.push(subscriber);
    }
    let key = handover_key(&options.prefix, &shared.name);
    let (inbox, dropped) = (shared.inbox.clone(), shared.inbox_dropped.clone());
    let subscriber = session
        .declare_subscriber(key.as_str())
        .callback(move |sample| {
            let payload = sample.payload();
            let message = (payload.len() <= handover::MAX_MESSAGE_BYTES)
                .then(|| serde_json::from_slice::<handover::Message>(&payload.to_bytes()).ok())
                .flatten();
            // A malformed message, or one the loop has no room for, is dropped: the protocol
            // makes every message but a release again, and sends a release only with room.
            if message.is_none_or(|m| inbox.try_send(m).is_err()) {
                dropped.fetch_add(1, Relaxed);
            }
        })
        .await
        .map_err(|e| anyhow::anyhow!("subscribing to {key}: {e}"))?;
    subscribers.push(subscriber);
    let outbox = shared.outbox.lock().unwrap_or_else(PoisonError::into_inner).take();
    if let Some(outbox) = outbox {
        tokio::spawn(send_handover(session.clone(), options.prefix.clone(), outbox));
    }
    let key = state_key(&options.prefix, &shared.name);
    let publisher = session
        .declare_publisher(key.clone())
        .await
        .map_err(|e| anyhow::anyhow!("declaring the publisher {key}: {e}"))?;
    tokio::spawn(publish(publisher, shared.name.clone(), shared.published.subscribe()));
    Ok(RegionLink { session, _subscribers: subscribers })
}

/// Decodes a neighbour's payload into the table (on Zenoh's thread); what cannot be used is counted.
fn receive(table: &ForeignTable, expected: &str, payload: &zenoh::bytes::ZBytes) {
    let at = Instant::now();
    if payload.len() > MAX_PAYLOAD_BYTES {
        table.refuse();
        return;
    }
    match wire::decode(&payload.to_bytes()) {
        Ok(states) => {
            table.accept(expected, states, at);
        }
        Err(e) => {
            tracing::debug!("region {expected}: payload refused: {e}");
            table.refuse();
        }
    }
}

/// Sends the newest snapshot after each change (skipping any it was too slow for) until the loop
/// ends. Zenoh's default congestion control for a put drops rather than blocks.
async fn publish(
    publisher: zenoh::pubsub::Publisher<'static>,
    region: String,
    mut snapshots: watch::Receiver<Option<Published>>,
) {
    while snapshots.changed().await.is_ok() {
        let Some(published) = snapshots.borrow_and_update().clone() else { continue };
        let age = published.read_at.elapsed().as_secs_f32();
        let payload = wire::encode(&region, &published.snapshot, age);
        if let Err(e) = publisher.put(payload).await {
            tracing::warn!("region {region}: publishing: {e}");
        }
    }
}

/// Puts each handover message the loop queues on its region's key, waiting (congestion control:
/// block) rather than dropping: a release must arrive.
async fn send_handover(
    session: zenoh::Session,
    prefix: String,
    mut outbox: tokio::sync::mpsc::Receiver<handover::Message>,
) {
    while let Some(message) = outbox.recv().await {
        let key = handover_key(&prefix, message.to());
        let Ok(payload) = serde_json::to_vec(&message) else { continue };
        let put = session.put(key.as_str(), payload).congestion_control(zenoh::qos::CongestionControl::Block);
        if let Err(e) = put.await {
            tracing::warn!("handover to {key}: {e}");
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use roads::{Region, RoadLayout};

    fn road_of_three() -> Road {
        let mut layout = RoadLayout::straight(0.0, 30.0, 4.0, 6);
        let region = |name: &str, first, last| Region { name: name.into(), segments: [first, last] };
        layout.regions = Some(vec![region("c", 4, 5), region("a", 0, 1), region("b", 2, 3)]);
        Road::new(layout).unwrap() // a valid layout: three regions covering six segments
    }

    #[test]
    fn neighbours_are_the_regions_whose_ranges_touch() {
        let road = road_of_three();
        assert_eq!(neighbours_of(&road, "a").unwrap(), ["b"]);
        assert_eq!(neighbours_of(&road, "b").unwrap(), ["a", "c"]);
        assert_eq!(neighbours_of(&road, "c").unwrap(), ["b"]);
        let e = neighbours_of(&road, "d").unwrap_err();
        assert!(e.contains("`d`") && e.contains("known: c, a, b"), "{e}");
        let plain = Road::new(RoadLayout::straight(0.0, 30.0, 4.0, 6)).unwrap(); // valid
        assert!(neighbours_of(&plain, "a").unwrap_err().contains("no regions"));
    }

    #[test]
    fn prefixes_are_plain_key_chunks() {
        assert!(check_prefix("airroads").is_ok() && check_prefix("site-1/fleet_2").is_ok());
        for bad in ["", "a//b", "a/*", "a/**", "a b", "a/$x", "/a"] {
            assert!(check_prefix(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn endpoints_turn_multicast_scouting_off() {
        let options = ZenohOptions {
            listen: vec!["tcp/127.0.0.1:7447".into()],
            prefix: "airroads".into(),
            ..Default::default()
        };
        let config = zenoh_config(&options).unwrap();
        assert_eq!(config.get_json("scouting/multicast/enabled").unwrap(), "false");
        assert!(config.get_json("listen/endpoints").unwrap().contains("tcp/127.0.0.1:7447"));
        let bad = ZenohOptions { connect: vec!["nonsense".into()], ..options };
        assert!(zenoh_config(&bad).is_err());
    }
}
