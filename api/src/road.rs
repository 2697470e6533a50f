//! The road routes: `GET /api/road` (the layout as put), `GET /api/road/geometry` (walls, centre
//! line, a network's cells) and `PUT /api/road`, which takes a chain layout (`{"segments", ...}`)
//! or a network layout (`{"roads", "junctions"?}`), validates it off the async workers and has the
//! loop put it in place.

use super::answers::RoadReplaced;
use super::error::{ApiError, parse, read_json};
use super::state::AppState;
use axum::Json;
use axum::extract::{FromRequest, Request, State};
use axum::http::StatusCode;
use axum::response::{IntoResponse, Response};
use engine::command::{Command, NewRoad, Outcome};
use roads::network::NetworkLayout;
use roads::{Airspace, AirspaceLayout, RoadError, RoadLayout};
use serde::de::IgnoredAny;
use serde_json::json;
use std::collections::BTreeMap;

/// Parses a road body: a network layout when it is an object with `roads`, else a chain layout
/// (whose errors are those of a chain layout alone, as before networks existed). Every error
/// names the field.
pub fn parse_layout(bytes: &[u8]) -> Result<AirspaceLayout, ApiError> {
    // Only the keys are read here (the values are skipped); an object's keys are few.
    let keys = parse::<BTreeMap<String, IgnoredAny>>(bytes).unwrap_or_default();
    if !keys.contains_key("roads") {
        return parse::<RoadLayout>(bytes).map(AirspaceLayout::Road);
    }
    parse::<NetworkLayout>(bytes).map(AirspaceLayout::Network)
}

/// The body of `PUT /api/road`: a chain layout or a network layout.
pub struct RoadBody(pub AirspaceLayout);

impl<S: Send + Sync> FromRequest<S> for RoadBody {
    type Rejection = ApiError;

    async fn from_request(req: Request, state: &S) -> Result<Self, ApiError> {
        read_json(req, state, parse_layout).await.map(RoadBody)
    }
}

pub(crate) async fn get_road(State(app): State<AppState>) -> Json<AirspaceLayout> {
    Json(app.engine.road.borrow().layout.clone())
}

pub(crate) async fn get_road_geometry(State(app): State<AppState>) -> Response {
    Json(app.engine.road.borrow().clone()).into_response()
}

pub(crate) async fn put_road(
    State(app): State<AppState>,
    RoadBody(layout): RoadBody,
) -> Result<Response, ApiError> {
    let checked_passage_m = app.engine.road.borrow().min_passage_m;
    let road = app.validate(move || airspace_of(layout, checked_passage_m)).await?;
    let network = road.network().is_some();
    match app.apply(Command::SetRoad(Box::new(NewRoad { road, checked_passage_m }))).await {
        Ok(Outcome::RoadReplaced { cleared_goals }) => {
            let version = app.engine.road.borrow().version;
            Ok(Json(RoadReplaced { version, cleared_goals }).into_response())
        }
        Ok(_) => Ok(StatusCode::OK.into_response()),
        // A UAV that would be outside or too close to a wall is a 409 (EditError::RoadConflict),
        // naming the network's `roads` rather than a chain's `segments`.
        Err(mut e) if network && e.field.as_deref() == Some("segments") => {
            e.field = Some("roads".into());
            Err(e)
        }
        Err(e) => Err(e),
    }
}

/// The 422 of a layout that breaks a rule: `field` (`segments[i]`, `regions[i].segments`,
/// `roads[k].segments[i]`, `junctions[j].polygon`, ...), `segment` and `rule`.
fn refused(e: RoadError) -> ApiError {
    let mut err = ApiError::new(StatusCode::UNPROCESSABLE_ENTITY, "invalid_road", e.message.clone())
        .field(e.field.clone());
    let mut extra = serde_json::Map::new();
    extra.insert("segment".into(), json!(e.segment));
    extra.insert("rule".into(), json!(e.rule.name()));
    err.extra = Some(extra);
    err
}

/// A validated road or network (passages at least `min_passage_m` wide), or the 422 naming the
/// field and the rule.
pub(crate) fn airspace_of(layout: AirspaceLayout, min_passage_m: f64) -> Result<Airspace, ApiError> {
    layout.build(min_passage_m).map_err(refused)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_body_is_read_as_the_form_it_has_and_errors_name_the_field() {
        let chain = serde_json::to_vec(&RoadLayout::straight(0.0, 10.0, 4.0, 2)).unwrap();
        assert!(matches!(parse_layout(&chain), Ok(AirspaceLayout::Road(_))));
        let network = NetworkLayout::from(&RoadLayout::straight(0.0, 10.0, 4.0, 2));
        let text = serde_json::to_vec(&network).unwrap();
        assert_eq!(parse_layout(&text).unwrap(), AirspaceLayout::Network(network));
        // A chain's errors are a chain layout's, with their paths.
        let e = parse_layout(br#"{"segments": [[[0, 0], [1, 0], [1, "x"], [0, 1]]]}"#).unwrap_err();
        assert_eq!(
            (e.status, e.field.as_deref()),
            (StatusCode::UNPROCESSABLE_ENTITY, Some("segments[0][2][1]"))
        );
        for body in [&b"[1]"[..], b"[[1]]", b"3", b"{\"segments\": {}}"] {
            assert_eq!(parse_layout(body).unwrap_err(), parse::<RoadLayout>(body).unwrap_err());
        }
        // A network's, with theirs.
        let e = parse_layout(br#"{"roads": [{"name": "a", "segments": 3}]}"#).unwrap_err();
        assert_eq!(e.field.as_deref(), Some("roads[0].segments"));
        // A network's regions are sets of cells: a chain's segment range is not one.
        let e =
            parse_layout(br#"{"roads": [], "regions": [{"name": "a", "segments": [0, 1]}]}"#).unwrap_err();
        assert!(e.field.as_deref().is_some_and(|f| f.starts_with("regions[0]")), "{e:?}");
        assert!(e.message.contains("unknown field `segments`"), "{}", e.message);
        let e = parse_layout(br#"{"roads": [], "segments": []}"#).unwrap_err();
        assert!(e.message.contains("unknown field `segments`"), "{}", e.message);
    }

    #[test]
    fn a_broken_network_names_its_cell_and_rule() {
        let mut network = NetworkLayout::from(&RoadLayout::straight(0.0, 10.0, 4.0, 2));
        network.roads[0].segments[1][0] = [3.0, 9.0];
        let e = airspace_of(network.into(), 1.0).unwrap_err();
        assert_eq!(e.status, StatusCode::UNPROCESSABLE_ENTITY);
        assert!(e.field.as_deref().is_some_and(|f| f.starts_with("roads[0].segments[")), "{e:?}");
        assert!(e.extra.unwrap()["rule"].is_string());
        // Too narrow for the fleet's parameters.
        let narrow = NetworkLayout::from(&RoadLayout::straight(0.0, 10.0, 0.5, 2));
        let e = airspace_of(narrow.into(), 1.0).unwrap_err();
        assert_eq!(e.extra.unwrap()["rule"], "narrow_passage");
    }
}
