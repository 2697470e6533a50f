//! A standby follows its owner's road (`serve --standby-for`): the owner's mirror carries its road
//! version; when it changes, the standby asks its region's owner for the road (`GET /api/road` over
//! the region's queryable) and takes it (`Command::FollowRoad`, the one change a standby accepts).
//! So a takeover flies on with the road the owner last flew, whatever was changed since the start.

use super::request::ApiRequest;
use super::state::AppState;
use engine::command::Command;
use regions::federation::{Answer, ApiQuery};
use std::time::Duration;

/// How often a standby compares its owner's road version with the one it took.
pub const FOLLOW_EVERY: Duration = Duration::from_millis(250);

/// Runs while the server runs (nothing while it owns its region).
pub async fn follow(app: AppState) {
    let Some(region) = app.region.clone() else { return };
    let mut taken: Option<u64> = None;
    loop {
        tokio::time::sleep(FOLLOW_EVERY).await;
        let Some(federation) = region.federation.get() else { continue };
        if region.failover.is_owner() {
            taken = None;
            continue;
        }
        let Some((mirror, _)) = region.failover.mirror() else { continue };
        if taken == Some(mirror.road_version) {
            continue;
        }
        let query = ApiQuery::of(ApiRequest::GetRoad);
        let Answer::Replied(reply) = federation.ask(&region.name, &query).await else { continue };
        let layout =
            (reply.status == 200).then(|| serde_json::from_str::<roads::RoadLayout>(&reply.body).ok());
        let Some(road) = layout.flatten().and_then(|l| roads::Road::new(l).ok()) else {
            tracing::warn!("standby of {}: the owner's road could not be read", region.name);
            continue;
        };
        match app.apply(Command::FollowRoad(Box::new(road))).await {
            Ok(_) => taken = Some(mirror.road_version),
            Err(e) => tracing::warn!("standby of {}: the owner's road not taken: {}", region.name, e.message),
        }
    }
}
