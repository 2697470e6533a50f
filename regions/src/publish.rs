//! The region's publishing tasks: its states after every tick (and its mirror while a standby
//! listens), and the handover messages its loop queues.

use super::{Failover, Published, failover, handover, handover_key, wire};
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering::Relaxed};
use tokio::sync::watch;

/// What the publishing task puts.
pub(super) struct Publishers {
    pub(super) states: zenoh::pubsub::Publisher<'static>,
    pub(super) mirror: zenoh::pubsub::Publisher<'static>,
    pub(super) failover: Arc<Failover>,
    pub(super) bytes: Arc<AtomicU64>,
}

/// Sends the newest snapshot after each change (skipping any it was too slow for) until the loop
/// ends, and the mirror when a standby listens; nothing while this server is a standby. Zenoh's
/// default congestion control for a put drops rather than blocks.
pub(super) async fn publish(
    publishers: Publishers,
    region: String,
    mut snapshots: watch::Receiver<Option<Published>>,
) {
    while snapshots.changed().await.is_ok() {
        let Some(published) = snapshots.borrow_and_update().clone() else { continue };
        // Both: the loop flew the region in this tick, and no other owner has come since.
        if !(published.owned && publishers.failover.is_owner()) {
            continue;
        }
        let age = published.read_at.elapsed().as_secs_f32();
        let payload = wire::encode(&region, &published.snapshot, age, &published.unheard);
        publishers.bytes.fetch_add(payload.len() as u64, Relaxed);
        if let Err(e) = publishers.states.put(payload).await {
            tracing::warn!("region {region}: publishing: {e}");
        }
        let standby_listens = publishers.mirror.matching_status().await.is_ok_and(|m| m.matching());
        if standby_listens {
            let mirror = failover::Mirror::of(
                &region,
                publishers.failover.epoch(),
                &published.snapshot,
                &published.leaving,
            );
            if let Ok(payload) = serde_json::to_vec(&mirror)
                && let Err(e) = publishers.mirror.put(payload).await
            {
                tracing::warn!("region {region}: mirror: {e}");
            }
        }
    }
}

/// Puts each handover message the loop queues on its region's key from this one, waiting (congestion control:
/// block) rather than dropping: a release must arrive.
pub(super) async fn send_handover(
    session: zenoh::Session,
    prefix: String,
    own: String,
    mut outbox: tokio::sync::mpsc::Receiver<handover::Message>,
) {
    while let Some(message) = outbox.recv().await {
        let key = handover_key(&prefix, message.to(), &own);
        let Ok(payload) = serde_json::to_vec(&message) else { continue };
        let put = session.put(key.as_str(), payload).congestion_control(zenoh::qos::CongestionControl::Block);
        if let Err(e) = put.await {
            tracing::warn!("handover to {key}: {e}");
        }
    }
}
