//! The Zenoh side of "one fleet to the operator" (docs/regions.md, One fleet): every
//! region answers REST requests from the other regions on its queryable `PREFIX/region/NAME/api/*`
//! (region ASKER asks on `PREFIX/region/NAME/api/ASKER`; the access control lets only ASKER's
//! certificate ask there)
//! (only the region's owner answers; a standby stays silent), and asks them with [`Federation`].
//! The HTTP side (what is forwarded, how reads are merged) is `serve::federate`.

use engine::fleet_loop::RoadView;
use roads::Airspace;
use serde::{Deserialize, Serialize};
use std::sync::{Arc, Mutex, PoisonError};
use std::time::Duration;

/// How long a request to another region may take before it counts as unanswered.
pub const ASK_TIMEOUT: Duration = Duration::from_secs(2);
/// A region that let a request wait out its timeout is taken as silent, without being asked, for
/// this long: a flood of requests about it costs no waiting.
pub const SILENCE_MEMORY: Duration = Duration::from_secs(1);
/// Largest request or answer carried (bytes): a request body is at most 4 MiB, a region's
/// `GET /api/state` at 10,000 UAVs about 6 MB.
pub const MAX_CARRIED_BYTES: usize = 64 << 20;

/// The key region `asker` asks region `region` on: `<prefix>/region/<region>/api/<asker>`.
pub fn api_key(prefix: &str, region: &str, asker: &str) -> String {
    format!("{prefix}/region/{region}/api/{asker}")
}

/// The region that asked on `key` (its last chunk), when `key` is an ask of region `own`.
pub fn asker_of<'k>(prefix: &str, own: &str, key: &'k str) -> Option<&'k str> {
    let asker =
        key.strip_prefix(prefix)?.strip_prefix("/region/")?.strip_prefix(own)?.strip_prefix("/api/")?;
    (!asker.is_empty() && !asker.contains('/')).then_some(asker)
}

/// A request carried to another region (JSON): the HTTP side's typed request `R` (its route and
/// data, run there without routing again), or a step of a deployment.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ApiQuery<R> {
    /// The request (None with `deploy`).
    #[serde(default = "none")]
    pub request: Option<R>,
    /// Answer only if this UAV is flown there (a change forwarded to its owner).
    #[serde(default)]
    pub uav: Option<String>,
    /// A step of a deployment-wide road or scenario (`serve::deploy`) instead of a request.
    #[serde(default)]
    pub deploy: Option<Step>,
    /// The operator's `Authorization` header, checked by the region that applies the request.
    #[serde(default)]
    pub authorization: Option<String>,
    /// The operator's address, for the applying region's audit log.
    #[serde(default)]
    pub client: Option<String>,
}

fn none<R>() -> Option<R> {
    None
}

impl<R> ApiQuery<R> {
    /// `request`, with nothing else.
    pub fn of(request: R) -> Self {
        Self { request: Some(request), uav: None, deploy: None, authorization: None, client: None }
    }
}

/// What is deployed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Kind {
    /// A road layout (`PUT /api/road`'s body).
    Road,
    /// A scenario (`POST /api/scenario`'s body).
    Scenario,
}

/// One step of a deployment, carried in [`ApiQuery::deploy`] (the HTTP side's `serve::deploy` runs them).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Step {
    /// `prepare` (check only) or `commit` (switch at `at_ms`).
    pub commit: bool,
    /// What is deployed.
    pub kind: Kind,
    /// The request's body as sent by the operator.
    pub body: String,
    /// The instant to switch at (ms since the Unix epoch; a commit only).
    #[serde(default)]
    pub at_ms: u64,
}

/// A region's answer: the HTTP status and body its API gave.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ApiReply {
    /// HTTP status.
    pub status: u16,
    /// The body (JSON).
    pub body: String,
}

/// What a region said to a request.
#[derive(Debug, Clone, PartialEq)]
pub enum Answer {
    /// It answered.
    Replied(ApiReply),
    /// Nobody answered within [`ASK_TIMEOUT`] (no owner, not flying that UAV, or unreachable).
    Silent,
}

/// A road with the version it was served at.
type VersionedRoad = (u64, Arc<Airspace>);

/// Asks the other regions over the region's Zenoh session.
#[derive(Clone)]
pub struct Federation {
    session: zenoh::Session,
    prefix: String,
    /// This server's region.
    pub own: String,
    /// The served road or network, built once per version (to find the region of a new UAV's
    /// position).
    road: Arc<Mutex<Option<VersionedRoad>>>,
    /// Regions that did not answer lately, until when they count as silent.
    silent_until: Arc<Mutex<std::collections::HashMap<String, std::time::Instant>>>,
}

impl std::fmt::Debug for Federation {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Federation").field("prefix", &self.prefix).field("own", &self.own).finish()
    }
}

impl Federation {
    /// Asks over `session` under `prefix`, as region `own`.
    pub fn new(session: zenoh::Session, prefix: &str, own: &str) -> Self {
        Self {
            session,
            prefix: prefix.into(),
            own: own.into(),
            road: Arc::default(),
            silent_until: Arc::default(),
        }
    }

    /// The road or network of `view` (built at its first use per version, a network with the
    /// passages it was validated for; None if it does not build).
    pub fn road(&self, view: &RoadView) -> Option<Arc<Airspace>> {
        let mut cached = self.road.lock().unwrap_or_else(PoisonError::into_inner);
        if let Some((version, road)) = cached.as_ref()
            && *version == view.version
        {
            return Some(road.clone());
        }
        let road = Arc::new(view.layout.clone().build(view.min_passage_m).ok()?);
        *cached = Some((view.version, road.clone()));
        Some(road)
    }

    /// The keys this region answers on (every asker's).
    pub fn own_key(&self) -> String {
        api_key(&self.prefix, &self.own, "*")
    }

    /// The region that asked on `key`, when it is one of this region's keys.
    pub fn asker<'k>(&self, key: &'k str) -> Option<&'k str> {
        asker_of(&self.prefix, &self.own, key)
    }

    /// Sends `query` to region `region` and returns its owner's answer (the first; there is one).
    pub async fn ask<R: Serialize + Sync>(&self, region: &str, query: &ApiQuery<R>) -> Answer {
        self.ask_within(region, query, ASK_TIMEOUT).await
    }

    /// True while `region` counts as silent (it did not answer within the last
    /// [`SILENCE_MEMORY`]).
    pub fn remembered_silent(&self, region: &str) -> bool {
        let silent = self.silent_until.lock().unwrap_or_else(PoisonError::into_inner);
        silent.get(region).is_some_and(|until| std::time::Instant::now() < *until)
    }

    fn heard(&self, region: &str, answered: bool) {
        let mut silent = self.silent_until.lock().unwrap_or_else(PoisonError::into_inner);
        if answered {
            silent.remove(region);
        } else {
            silent.insert(region.to_string(), std::time::Instant::now() + SILENCE_MEMORY);
        }
    }

    /// [`Federation::ask`], waiting at most `timeout`; a region remembered silent is not asked.
    pub async fn ask_within<R: Serialize + Sync>(
        &self,
        region: &str,
        query: &ApiQuery<R>,
        timeout: Duration,
    ) -> Answer {
        if self.remembered_silent(region) {
            return Answer::Silent;
        }
        let asked = std::time::Instant::now();
        let answer = self.ask_now(region, query, timeout).await;
        match answer {
            Answer::Replied(_) => self.heard(region, true),
            // Only a silence that cost the wait is remembered: an ask that nobody could take
            // (no queryable: the region is gone or not up yet) ends at once and costs nothing.
            Answer::Silent if asked.elapsed() >= timeout / 2 => self.heard(region, false),
            Answer::Silent => {}
        }
        answer
    }

    async fn ask_now<R: Serialize>(&self, region: &str, query: &ApiQuery<R>, timeout: Duration) -> Answer {
        let Ok(payload) = serde_json::to_vec(query) else { return Answer::Silent };
        let key = api_key(&self.prefix, region, &self.own);
        let asked = self
            .session
            .get(key.as_str())
            .payload(payload)
            .target(zenoh::query::QueryTarget::All)
            .consolidation(zenoh::query::ConsolidationMode::None)
            .timeout(timeout)
            .await;
        let replies = match asked {
            Ok(replies) => replies,
            Err(e) => {
                tracing::warn!("asking region {region}: {e}");
                return Answer::Silent;
            }
        };
        while let Ok(reply) = replies.recv_async().await {
            let Ok(sample) = reply.result() else { continue };
            let payload = sample.payload();
            if payload.len() > MAX_CARRIED_BYTES {
                continue;
            }
            if let Ok(answer) = serde_json::from_slice::<ApiReply>(&payload.to_bytes()) {
                return Answer::Replied(answer);
            }
        }
        Answer::Silent
    }

    /// Sends `query` to every region of `regions` at once; their answers in that order.
    pub async fn ask_all<R: Serialize + Sync>(
        &self,
        regions: &[String],
        query: &ApiQuery<R>,
    ) -> Vec<(String, Answer)> {
        let answers = futures_util::future::join_all(regions.iter().map(|r| self.ask(r, query))).await;
        regions.iter().cloned().zip(answers).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn queries_and_replies_are_plain_json_and_refuse_unknown_fields() {
        let q = ApiQuery {
            request: Some("a request".to_string()),
            uav: None,
            deploy: None,
            authorization: Some("Bearer t".into()),
            client: Some("127.0.0.1:5000".into()),
        };
        let text = serde_json::to_string(&q).unwrap();
        assert_eq!(serde_json::from_str::<ApiQuery<String>>(&text).unwrap(), q);
        let bare: ApiQuery<String> = serde_json::from_str(r#"{"request": "r"}"#).unwrap();
        assert_eq!((bare.request.as_deref(), bare.uav), (Some("r"), None));
        assert!(
            serde_json::from_str::<ApiQuery<String>>(r#"{"method": "GET", "uri": "/api/state"}"#).is_err()
        );
        assert!(serde_json::from_str::<ApiReply>(r#"{"status": 200, "body": "", "x": 1}"#).is_err());
        assert_eq!(api_key("airroads", "west", "east"), "airroads/region/west/api/east");
        assert_eq!(asker_of("airroads", "west", "airroads/region/west/api/east"), Some("east"));
        assert_eq!(asker_of("airroads", "west", "airroads/region/west/api/"), None);
        assert_eq!(asker_of("airroads", "west", "airroads/region/east/api/west"), None);
    }

    #[test]
    fn steps_round_trip_as_json_and_unknown_fields_are_refused() {
        let step = Step { commit: true, kind: Kind::Scenario, body: "{}".into(), at_ms: 17 };
        let text = serde_json::to_string(&step).unwrap();
        assert!(text.contains(r#""kind":"scenario""#), "{text}");
        assert_eq!(serde_json::from_str::<Step>(&text).unwrap(), step);
        assert!(serde_json::from_str::<Step>(&text.replacen('{', r#"{"x":1,"#, 1)).is_err());
    }
}
