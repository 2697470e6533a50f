//! The Zenoh side of a region's ownership (`failover`): claiming the region at start, watching its
//! liveliness tokens, and following the owner's mirror as a standby.

use super::failover::{self, CLAIM_SETTLE, Decision, Failover, Mirror, OwnerToken, Tokens};
use super::{MAX_PAYLOAD_BYTES, handover, handover_key};
use std::sync::Arc;
use std::time::Instant;
use zenoh::liveliness::LivelinessToken;
use zenoh::sample::{Sample, SampleKind};

/// The keys of one region's ownership: `<prefix>/region/<name>/` then `mirror`, `owner/...`,
/// `standby/...`.
#[derive(Debug, Clone)]
pub struct RegionKeys {
    /// `--zenoh-prefix`.
    pub prefix: String,
    /// The region.
    pub name: String,
}

impl RegionKeys {
    /// The keys of region `name` under `options`' prefix.
    pub fn new(options: &super::ZenohOptions, name: &str) -> Self {
        Self { prefix: options.prefix.clone(), name: name.to_string() }
    }

    fn base(&self) -> String {
        format!("{}/region/{}/", self.prefix, self.name)
    }

    /// The mirror's key (JSON [`Mirror`] after each of the owner's ticks).
    pub fn mirror(&self) -> String {
        format!("{}mirror", self.base())
    }

    /// Every liveliness token of the region.
    fn tokens(&self) -> String {
        format!("{}**", self.base())
    }

    fn owner(&self, token: &OwnerToken) -> String {
        format!("{}owner/{}/{}", self.base(), token.epoch, token.incarnation)
    }

    fn standby(&self, incarnation: &str) -> String {
        format!("{}standby/{incarnation}", self.base())
    }

    /// Applies a liveliness sample to `tokens` (false: not one of this region's tokens).
    fn apply(&self, tokens: &mut Tokens, sample: &Sample) -> bool {
        let key = sample.key_expr().as_str();
        let base = self.base();
        key.strip_prefix(base.as_str())
            .is_some_and(|suffix| tokens.apply(suffix, sample.kind() == SampleKind::Put))
    }
}

/// The ownership task's state: the region's tokens and this server's own.
pub struct Claim {
    tokens: Tokens,
    owner_token: Option<(OwnerToken, LivelinessToken)>,
    standby_token: Option<LivelinessToken>,
    subscriber: zenoh::pubsub::Subscriber<zenoh::handlers::FifoChannelHandler<Sample>>,
}

fn zerr(what: &str) -> impl FnOnce(zenoh::Error) -> anyhow::Error + '_ {
    move |e| anyhow::anyhow!("{what}: {e}")
}

async fn declare(session: &zenoh::Session, key: String) -> anyhow::Result<LivelinessToken> {
    session.liveliness().declare_token(key.as_str()).await.map_err(zerr(&key))
}

/// Starts following the region's tokens. `standby`: join as a standby (`--standby-for`);
/// otherwise (`--region`) listen [`CLAIM_SETTLE`] for a live owner and become its standby if there
/// is one, else the owner. `failover` is told the outcome before this returns.
pub async fn claim(
    session: &zenoh::Session,
    keys: &RegionKeys,
    failover: &Failover,
    standby: bool,
) -> anyhow::Result<Claim> {
    let what = keys.tokens();
    let subscriber =
        session.liveliness().declare_subscriber(what.as_str()).history(true).await.map_err(zerr(&what))?;
    let mut tokens = Tokens::default();
    let until = tokio::time::Instant::now() + CLAIM_SETTLE;
    while let Ok(Ok(sample)) = tokio::time::timeout_at(until, subscriber.recv_async()).await {
        keys.apply(&mut tokens, &sample);
    }
    let mut claim = Claim { tokens, owner_token: None, standby_token: None, subscriber };
    if standby || !claim.tokens.owners.is_empty() {
        claim.standby_token = Some(declare(session, keys.standby(&failover.incarnation)).await?);
    } else {
        let token =
            OwnerToken { epoch: claim.tokens.max_epoch + 1, incarnation: failover.incarnation.clone() };
        let handle = declare(session, keys.owner(&token)).await?;
        failover.became_owner(token.epoch, false);
        claim.owner_token = Some((token, handle));
    }
    Ok(claim)
}

/// Watches the region's tokens until the session closes, taking over or giving way by
/// [`failover::decide`].
pub async fn watch(session: zenoh::Session, keys: RegionKeys, failover: Arc<Failover>, mut claim: Claim) {
    loop {
        let decision = failover::decide(
            &claim.tokens,
            &failover.incarnation,
            claim.owner_token.as_ref().map(|(t, _)| t),
        );
        match decision {
            Decision::Stay => {}
            Decision::TakeOver(epoch) => {
                let token = OwnerToken { epoch, incarnation: failover.incarnation.clone() };
                match declare(&session, keys.owner(&token)).await {
                    Ok(handle) => {
                        // The token is out before the loop commands anything.
                        failover.became_owner(epoch, true);
                        tracing::warn!(
                            "region {}: took over as owner (epoch {epoch}); no owner token left (the last \
                             seen: epoch {})",
                            keys.name,
                            claim.tokens.max_epoch
                        );
                        claim.owner_token = Some((token, handle));
                        claim.standby_token = None;
                    }
                    Err(e) if !session.is_closed() => {
                        // No sample may come to decide again: try again shortly.
                        tracing::warn!("region {}: taking over: {e:#}; trying again", keys.name);
                        tokio::time::sleep(std::time::Duration::from_millis(100)).await;
                        continue;
                    }
                    Err(_) => return,
                }
            }
            Decision::GiveWay => {
                failover.became_standby();
                // Who caused it: only a server holding this region's certificate can declare an
                // owner token under its keys (the access control), named by its incarnation.
                let ahead: Vec<String> = claim
                    .tokens
                    .owners
                    .iter()
                    .map(|t| format!("epoch {} by {}", t.epoch, t.incarnation))
                    .collect();
                tracing::warn!(
                    "region {}: another owner is ahead ({}); this server is now its standby",
                    keys.name,
                    ahead.join(", ")
                );
                claim.owner_token = None;
                match declare(&session, keys.standby(&failover.incarnation)).await {
                    Ok(handle) => claim.standby_token = Some(handle),
                    Err(e) => tracing::warn!("region {}: standby token: {e:#}", keys.name),
                }
            }
        }
        let Ok(sample) = claim.subscriber.recv_async().await else { return };
        keys.apply(&mut claim.tokens, &sample);
        // Take in everything that already arrived before deciding again.
        while let Ok(Some(sample)) = claim.subscriber.try_recv() {
            keys.apply(&mut claim.tokens, &sample);
        }
    }
}

/// Subscribes (as long as the returned subscribers live) to the region's mirror and to the
/// neighbours' handover keys, whose releases from this region keep released UAVs out of a takeover.
pub async fn follow(
    session: &zenoh::Session,
    keys: &RegionKeys,
    neighbours: &[String],
    failover: &Arc<Failover>,
) -> anyhow::Result<Vec<zenoh::pubsub::Subscriber<()>>> {
    let mut subscribers = Vec::new();
    let key = keys.mirror();
    let kept = failover.clone();
    let subscriber = session
        .declare_subscriber(key.as_str())
        .callback(move |sample| {
            let payload = sample.payload();
            if payload.len() <= MAX_PAYLOAD_BYTES
                && let Ok(mirror) = serde_json::from_slice::<Mirror>(&payload.to_bytes())
            {
                kept.keep_mirror(mirror, Instant::now());
            }
        })
        .await
        .map_err(zerr(&key))?;
    subscribers.push(subscriber);
    for neighbour in neighbours {
        let key = handover_key(&keys.prefix, neighbour, &keys.name);
        let (seen, own) = (failover.clone(), keys.name.clone());
        let subscriber = session
            .declare_subscriber(key.as_str())
            .callback(move |sample| {
                let payload = sample.payload();
                if payload.len() <= handover::MAX_MESSAGE_BYTES
                    && let Ok(message) = serde_json::from_slice::<handover::Message>(&payload.to_bytes())
                {
                    seen.saw_handover(&own, &message, Instant::now());
                }
            })
            .await
            .map_err(zerr(&key))?;
        subscribers.push(subscriber);
    }
    Ok(subscribers)
}
