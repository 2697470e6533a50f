//! Regions over Zenoh (`airroads serve --region NAME`, docs/regions.md): this server
//! flies the UAVs of one region of the road; every tick it publishes their states under
//! [`state_key`] and it subscribes to the regions next to its own, whose UAVs its fleet avoids as
//! foreign UAVs (`fleet/src/foreign.rs`).
//!
//! Nothing here can make the fleet loop wait: the loop replaces a `watch` value with each snapshot
//! (the publishing task sends the newest one it has, skipping any it was too slow for) and copies
//! the foreign UAVs out of a [`ForeignTable`] that the subscriber's callback fills.
//!
//! The crate plugs into the fleet loop only through the engine's hook ([`RegionLoop`]); the HTTP
//! side of the regions (forwarding, merged reads, deployments) is `airroads::serve::federate`.

pub mod ages;
pub mod certs;
mod config;
pub(crate) mod detach;
pub mod elsewhere;
pub mod failover;
pub mod federation;
pub mod handover;
mod loop_hook;
pub mod messages;
#[cfg(test)]
mod neighbours_tests;
pub mod ownership;
mod publish;
pub mod screen;
pub mod secure;
pub mod table;
mod takeover;
#[cfg(test)]
mod test_network;
pub mod tokens;
pub mod wire;

pub use config::{ZenohOptions, zenoh_config};
pub use failover::Failover;
pub use handover::Handover;
pub use loop_hook::RegionLoop;
pub use ownership::OwnershipLog;
pub use table::ForeignTable;

use engine::snapshot::Snapshot;
use roads::Airspace;
use std::sync::atomic::{AtomicU64, Ordering::Relaxed};
use std::sync::mpsc::SyncSender;
use std::sync::{Arc, Mutex, PoisonError};
use std::time::Instant;
use tokio::sync::watch;

/// Largest mirror read from the region's owner (bytes, JSON): far above 10,000 UAVs' worth.
pub const MAX_PAYLOAD_BYTES: usize = 16 << 20;
/// Largest state message read from a neighbour (bytes): [`screen::MAX_UAVS_PER_REGION`] UAVs with
/// ids of the longest length.
pub const MAX_STATE_BYTES: usize = wire::HEADER_BYTES
    + roads::MAX_REGION_NAME
    + screen::MAX_UAVS_PER_REGION * (2 + uav::MAX_UAV_ID_LEN + wire::RECORD_TAIL_BYTES);

/// The key a region's states are published under: `<prefix>/region/<name>/state`.
pub fn state_key(prefix: &str, region: &str) -> String {
    format!("{prefix}/region/{region}/state")
}

/// The key `from`'s handover messages to `region` go to: `<prefix>/region/<region>/handover/<from>`
/// (the access control lets only `from`'s certificate put there).
pub fn handover_key(prefix: &str, region: &str, from: &str) -> String {
    format!("{prefix}/region/{region}/handover/{from}")
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

/// The regions next to `name` on `space`: on a road those whose segment range touches its own, by
/// segment order; on a network those a passage joins to one of its cells, in the layout's order.
/// The error names the region and the known ones.
pub fn neighbours_of(space: &Airspace, name: &str) -> Result<Vec<String>, String> {
    if let Some(next) = space.neighbour_regions(name) {
        return Ok(next.into_iter().map(String::from).collect());
    }
    let what = if space.network().is_some() { "network" } else { "road" };
    let known = space.region_names();
    Err(if known.is_empty() {
        format!("`{name}`: the {what} has no regions")
    } else {
        format!("`{name}`: the {what} has no such region (known: {})", known.join(", "))
    })
}

/// A snapshot on its way to the publishing task, with when its states were read.
#[derive(Debug, Clone)]
pub struct Published {
    /// The fleet after a tick.
    pub snapshot: Arc<Snapshot>,
    /// When that tick started (its states were read just after).
    pub read_at: Instant,
    /// The loop flew the region in that tick (a standby's empty fleet is never published).
    pub owned: bool,
    /// The silent UAVs' unheard times and the ghosts, sent with the states.
    pub unheard: wire::Unheard,
    /// The UAVs released whose links are still closing, for the mirror.
    pub leaving: Vec<failover::MirrorUav>,
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
    /// Ages of the foreign states the loop used (`foreign_age_ms`).
    pub foreign_ages: Arc<ages::AgeHistogram>,
    /// Bytes of state messages published so far.
    pub published_bytes: Arc<AtomicU64>,
    /// Who owns the region: this server or another (`failover`).
    pub failover: Arc<Failover>,
    /// The handover counters, as the loop last wrote them.
    pub handover_counts: Arc<Mutex<handover::HandoverCounts>>,
    /// The other regions' newest state messages, for the dashboard's stream.
    pub elsewhere: Arc<elsewhere::Elsewhere>,
    /// How this region asks the others (set once the Zenoh side started; `serve::federate`).
    pub federation: Arc<std::sync::OnceLock<federation::Federation>>,
    /// The checks of the other regions' messages, and their refusals.
    pub screen: Arc<screen::Screen>,
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
        let screen = Arc::new(screen::Screen::default());
        let handover = Handover::new(name, inbox_rx, outbox_tx, ownership.clone(), screen.clone());
        Self {
            name: name.into(),
            foreign: Arc::new(ForeignTable::new(name)),
            published: Arc::new(watch::channel(None).0),
            ownership,
            foreign_ages: Arc::default(),
            published_bytes: Arc::default(),
            failover: Arc::new(Failover::new()),
            handover_counts: Arc::default(),
            federation: Arc::default(),
            screen,
            elsewhere: Arc::default(),
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
    pub fn report(&self, now: Instant) -> RegionReport {
        let mut handover = *self.handover_counts.lock().unwrap_or_else(PoisonError::into_inner);
        handover.dropped += self.inbox_dropped.load(Relaxed);
        RegionReport {
            table: self.foreign.report(now),
            handover,
            failover: self.failover.report(now),
            foreign_age_ms: self.foreign_ages.report(),
            published_bytes: self.published_bytes.load(Relaxed),
            peer_refused: self.screen.clone(),
        }
    }
}

/// `region` of `GET /api/metrics`.
#[derive(Debug, serde::Serialize, schemars::JsonSchema)]
pub struct RegionReport {
    /// The neighbours' table: this region's name, the foreign UAVs, the messages heard.
    #[serde(flatten)]
    pub table: table::TableReport,
    /// The handover counters (`dropped` counts the inbox's drops too).
    pub handover: handover::HandoverCounts,
    /// Who owns the region.
    pub failover: failover::FailoverReport,
    /// Ages of the foreign states the loop used (ms).
    pub foreign_age_ms: ages::AgeReport,
    /// Bytes of state messages published.
    pub published_bytes: u64,
    /// Refusals of other regions' messages, by reason.
    #[serde(serialize_with = "peer_refusals")]
    #[schemars(with = "screen::PeerRefusals")]
    pub peer_refused: Arc<screen::Screen>,
}

fn peer_refusals<S: serde::Serializer>(screen: &Arc<screen::Screen>, to: S) -> Result<S::Ok, S::Error> {
    serde::Serialize::serialize(screen.report(), to)
}

/// The running Zenoh side: the session (closed when dropped) and its subscribers.
pub struct RegionLink {
    /// The Zenoh session.
    pub session: zenoh::Session,
    _subscribers: Vec<zenoh::pubsub::Subscriber<()>>,
}

/// Opens the Zenoh session.
pub async fn open(options: &ZenohOptions) -> anyhow::Result<zenoh::Session> {
    let config = zenoh_config(options)?;
    zenoh::open(config).await.map_err(|e| anyhow::anyhow!("opening the Zenoh session: {e}"))
}

/// Subscribes to `neighbours`, starts publishing `shared`'s snapshots (while this server owns the
/// region) and its mirror, and watches the region's ownership from `claim` on.
pub async fn start(
    session: zenoh::Session,
    options: &ZenohOptions,
    shared: &RegionShared,
    neighbours: &[String],
    claim: tokens::Claim,
) -> anyhow::Result<RegionLink> {
    let keys = tokens::RegionKeys::new(options, &shared.name);
    let mirror_key = keys.mirror();
    let mut subscribers = tokens::follow(&session, &keys, neighbours, &shared.failover).await?;
    tokio::spawn(tokens::watch(session.clone(), keys, shared.failover.clone(), claim));
    for name in neighbours {
        let key = state_key(&options.prefix, name);
        let (table, screen, expected) = (shared.foreign.clone(), shared.screen.clone(), name.clone());
        let subscriber = session
            .declare_subscriber(key.as_str())
            .callback(move |sample| receive(&table, &screen, &expected, sample.payload()))
            .await
            .map_err(|e| anyhow::anyhow!("subscribing to {key}: {e}"))?;
        subscribers.push(subscriber);
    }
    // Every other region's states, kept as received for the dashboard (`elsewhere`).
    let key = format!("{}/region/*/state", options.prefix);
    let (elsewhere, prefix, own) = (shared.elsewhere.clone(), options.prefix.clone(), shared.name.clone());
    let screen = shared.screen.clone();
    let subscriber = session
        .declare_subscriber(key.as_str())
        .callback(move |sample| {
            let name = elsewhere::region_of_key(&prefix, sample.key_expr().as_str());
            let payload = sample.payload();
            let plain = payload.len() <= MAX_STATE_BYTES && payload.len() >= wire::HEADER_BYTES;
            let mut head = [0u8; 2];
            let states = std::io::Read::read_exact(&mut payload.reader(), &mut head).is_ok()
                && head == [wire::WIRE_VERSION, wire::KIND_REGION_STATES];
            // Only the deployment's regions: memory for their messages stays bounded.
            if let Some(name) = name.filter(|n| *n != own && plain && states && screen.knows(n)) {
                // Kept as Zenoh's buffers (a reference, no copy) until a stream client needs it.
                elsewhere.put(name, payload.clone(), Instant::now());
            }
        })
        .await
        .map_err(|e| anyhow::anyhow!("subscribing to {key}: {e}"))?;
    subscribers.push(subscriber);
    // Messages to this region, one key per sender (`.../handover/SENDER`): the access control lets
    // only the sender's certificate put there, and a message must name the sender of its key.
    let key = format!("{}/region/{}/handover/*", options.prefix, shared.name);
    let (inbox, dropped, prefix) =
        (shared.inbox.clone(), shared.inbox_dropped.clone(), options.prefix.clone());
    let own = shared.name.clone();
    let subscriber = session
        .declare_subscriber(key.as_str())
        .callback(move |sample| {
            let sender = sample.key_expr().as_str().rsplit('/').next().unwrap_or_default();
            let payload = sample.payload();
            let message = (payload.len() <= handover::MAX_MESSAGE_BYTES)
                .then(|| serde_json::from_slice::<handover::Message>(&payload.to_bytes()).ok())
                .flatten()
                .filter(|m| {
                    m.from() == sender
                        && m.to() == own
                        && sample.key_expr().as_str() == handover_key(&prefix, &own, sender)
                });
            // A malformed message, one whose sender is not its key's, or one the loop has no room
            // for, is dropped: the protocol makes every message but a release again, and sends a
            // release only with room.
            if message.is_none_or(|m| inbox.try_send(m).is_err()) {
                dropped.fetch_add(1, Relaxed);
            }
        })
        .await
        .map_err(|e| anyhow::anyhow!("subscribing to {key}: {e}"))?;
    subscribers.push(subscriber);
    let outbox = shared.outbox.lock().unwrap_or_else(PoisonError::into_inner).take();
    if let Some(outbox) = outbox {
        tokio::spawn(publish::send_handover(
            session.clone(),
            options.prefix.clone(),
            shared.name.clone(),
            outbox,
        ));
    }
    let key = state_key(&options.prefix, &shared.name);
    let publisher = session
        .declare_publisher(key.clone())
        .await
        .map_err(|e| anyhow::anyhow!("declaring the publisher {key}: {e}"))?;
    let key = mirror_key;
    // Only remote subscribers count: every server of the region subscribes to its mirror.
    let mirror = session
        .declare_publisher(key.clone())
        .allowed_destination(zenoh::sample::Locality::Remote)
        .await
        .map_err(|e| anyhow::anyhow!("declaring the publisher {key}: {e}"))?;
    let publishers = publish::Publishers {
        states: publisher,
        mirror,
        failover: shared.failover.clone(),
        bytes: shared.published_bytes.clone(),
    };
    tokio::spawn(publish::publish(publishers, shared.name.clone(), shared.published.subscribe()));
    Ok(RegionLink { session, _subscribers: subscribers })
}

/// Screens and decodes a neighbour's payload into the table (on Zenoh's thread); what cannot be used
/// is counted (`refused`, and by reason in `peer_refused`).
fn receive(table: &ForeignTable, screen: &screen::Screen, expected: &str, payload: &zenoh::bytes::ZBytes) {
    let at = Instant::now();
    if payload.len() > MAX_STATE_BYTES || screen.admit(expected, at).is_err() {
        table.refuse();
        return;
    }
    let states = wire::decode(&payload.to_bytes()).map_err(|e| e.to_string()).and_then(|states| {
        let listed = states.uavs.iter().map(|u| (u.id.as_str(), u.p.map(f64::from)));
        screen.check_states(expected, listed).map_err(|e| e.to_string())?;
        Ok(states)
    });
    match states {
        Ok(states) => {
            table.accept(expected, states, at);
        }
        Err(e) => {
            tracing::debug!("region {expected}: payload refused: {e}");
            table.refuse();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

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
