//! A standby follows its owner's road (`serve --standby-for`): the owner's mirror carries its road
//! version; when it changes, the standby asks its region's owner for the road (`GET /api/road` over
//! the region's queryable) and takes it (`Command::FollowRoad`, the one change a standby accepts).
//! So a takeover flies on with the road the owner last flew, whatever was changed since the start.

use super::request::ApiRequest;
use super::state::AppState;
use engine::command::{Command, NewRoad};
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
        // A network is built with the passages this server's fleet needs (its parameters are the
        // owner's: the same scenario).
        let checked_passage_m = app.engine.road.borrow().min_passage_m;
        let layout = (reply.status == 200).then(|| super::road::parse_layout(reply.body.as_bytes()).ok());
        let Some(road) = layout.flatten().and_then(|l| l.build(checked_passage_m).ok()) else {
            tracing::warn!("standby of {}: the owner's road could not be read", region.name);
            continue;
        };
        match app.apply(Command::FollowRoad(Box::new(NewRoad { road, checked_passage_m }))).await {
            Ok(_) => taken = Some(mirror.road_version),
            Err(e) => tracing::warn!("standby of {}: the owner's road not taken: {}", region.name, e.message),
        }
    }
}
