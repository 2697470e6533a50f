//! The typed request one region carries to another ([`ApiRequest`]): the route of `routes::ROUTES`
//! and its data, parsed once where the operator sent it and run where it is answered by the same
//! handlers, without routing a method and URI a second time.

use super::error::{self, ApiError, ApiJson, NoBody};
use super::handlers::{self, GoalBody, ListQuery, NewUav, PolicyBody};
use super::routes::{self, Route};
use super::state::AppState;
use axum::extract::{Path, Query, State};
use axum::response::{IntoResponse, Response};
use serde::{Deserialize, Serialize};

/// A REST request about one region's fleet, as it travels between regions.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "route", rename_all = "snake_case", deny_unknown_fields)]
pub enum ApiRequest {
    /// `GET /api/uavs/{id}`.
    GetUav {
        /// The UAV.
        id: String,
    },
    /// `DELETE /api/uavs/{id}`.
    RemoveUav {
        /// The UAV.
        id: String,
    },
    /// `PUT /api/uavs/{id}/goal`.
    SetGoal {
        /// The UAV.
        id: String,
        /// The body.
        body: GoalBody,
    },
    /// `DELETE /api/uavs/{id}/goal`.
    ClearGoal {
        /// The UAV.
        id: String,
    },
    /// `PUT /api/uavs/{id}/policy`.
    SetPolicy {
        /// The UAV.
        id: String,
        /// The body.
        body: PolicyBody,
    },
    /// `POST /api/uavs/{id}/land`.
    LandUav {
        /// The UAV.
        id: String,
    },
    /// `POST /api/uavs`.
    AddUav {
        /// The body.
        body: NewUav,
    },
    /// `POST /api/fleet/pause`.
    Pause,
    /// `POST /api/fleet/resume`.
    Resume,
    /// `POST /api/fleet/land`.
    LandFleet,
    /// `POST /api/fleet/stop`.
    StopFleet,
    /// `GET /api/state` of the region alone.
    GetState,
    /// `GET /api/uavs` of the region alone, every UAV (pages are cut from the merged list).
    ListUavs,
    /// `GET /api/road`.
    GetRoad,
}

impl ApiRequest {
    /// The request `route` with the `{id}` and body given makes, or the refusal of that body as the
    /// route's handler would answer it (so it is answered where it was sent). None: a route that
    /// does not travel between regions.
    pub fn of(route: &Route, id: Option<&str>, body: &[u8]) -> Option<Result<Self, ApiError>> {
        let id = || id.unwrap_or_default().to_string();
        let empty = |request: ApiRequest| Some(error::no_body(body).map(|NoBody| request));
        match route.doc.id {
            "getUav" => Some(Ok(Self::GetUav { id: id() })),
            "removeUav" => empty(Self::RemoveUav { id: id() }),
            "setGoal" => Some(error::parse(body).map(|body| Self::SetGoal { id: id(), body })),
            "clearGoal" => empty(Self::ClearGoal { id: id() }),
            "setPolicy" => Some(error::parse(body).map(|body| Self::SetPolicy { id: id(), body })),
            "landUav" => empty(Self::LandUav { id: id() }),
            "addUav" => Some(error::parse(body).map(|body| Self::AddUav { body })),
            "pause" => empty(Self::Pause),
            "resume" => empty(Self::Resume),
            "landFleet" => empty(Self::LandFleet),
            "stopFleet" => empty(Self::StopFleet),
            "getState" => Some(Ok(Self::GetState)),
            "listUavs" => Some(Ok(Self::ListUavs)),
            "getRoad" => Some(Ok(Self::GetRoad)),
            _ => None,
        }
    }

    /// Its route in `routes::ROUTES` and the UAV of its path.
    pub fn route(&self) -> (&'static Route, Option<&str>) {
        let (op, id) = match self {
            Self::GetUav { id } => ("getUav", Some(id)),
            Self::RemoveUav { id } => ("removeUav", Some(id)),
            Self::SetGoal { id, .. } => ("setGoal", Some(id)),
            Self::ClearGoal { id } => ("clearGoal", Some(id)),
            Self::SetPolicy { id, .. } => ("setPolicy", Some(id)),
            Self::LandUav { id } => ("landUav", Some(id)),
            Self::AddUav { .. } => ("addUav", None),
            Self::Pause => ("pause", None),
            Self::Resume => ("resume", None),
            Self::LandFleet => ("landFleet", None),
            Self::StopFleet => ("stopFleet", None),
            Self::GetState => ("getState", None),
            Self::ListUavs => ("listUavs", None),
            Self::GetRoad => ("getRoad", None),
        };
        // Every name above is an operation of the route table (a test walks them all).
        let route = routes::ROUTES.iter().find(|r| r.doc.id == op).expect("an operation of the route table");
        (route, id.map(String::as_str))
    }

    /// Its path, as the operator wrote it (the audit log's route).
    pub fn path(&self) -> String {
        let (route, id) = self.route();
        id.map_or_else(|| route.path.to_string(), |id| route.path.replace("{id}", id))
    }

    /// Runs it through its handler here.
    pub async fn run(self, app: AppState) -> Response {
        let app = State(app);
        match self {
            Self::GetUav { id } => handlers::get_uav(app, Path(id)).await.into_response(),
            Self::RemoveUav { id } => handlers::remove_uav(app, Path(id), NoBody).await.into_response(),
            Self::SetGoal { id, body } => {
                handlers::set_goal(app, Path(id), ApiJson(body)).await.into_response()
            }
            Self::ClearGoal { id } => handlers::clear_goal(app, Path(id), NoBody).await.into_response(),
            Self::SetPolicy { id, body } => {
                handlers::set_policy(app, Path(id), ApiJson(body)).await.into_response()
            }
            Self::LandUav { id } => handlers::land_uav(app, Path(id), NoBody).await.into_response(),
            Self::AddUav { body } => handlers::add_uav(app, ApiJson(body)).await.into_response(),
            Self::Pause => handlers::pause(app, NoBody).await.into_response(),
            Self::Resume => handlers::resume(app, NoBody).await.into_response(),
            Self::LandFleet => handlers::land_fleet(app, NoBody).await.into_response(),
            Self::StopFleet => handlers::stop_fleet(app, NoBody).await.into_response(),
            Self::GetState => handlers::get_state(app).await,
            Self::ListUavs => handlers::list_uavs(app, Ok(Query(ListQuery::default()))).await.into_response(),
            Self::GetRoad => super::road::get_road(app).await.into_response(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::routes::{ROUTES, Reach};

    #[test]
    fn every_route_that_travels_is_a_request_and_back() {
        for route in ROUTES {
            let body: &[u8] = match route.doc.id {
                "setGoal" => br#"{"goal": [1, 2]}"#,
                "setPolicy" => br#"{"policy": "pd"}"#,
                "addUav" => br#"{"id": "u1", "position": [0, 0]}"#,
                _ => b"",
            };
            let travels = !matches!(route.reach, Reach::Here | Reach::Deploy(_)) || route.doc.id == "getRoad";
            let Some(request) = ApiRequest::of(route, Some("u1"), body) else {
                assert!(!travels, "{} {} does not travel", route.verb.name(), route.path);
                continue;
            };
            let request = request.unwrap_or_else(|e| panic!("{}: {}", route.path, e.message));
            assert!(travels, "{} {} travels", route.verb.name(), route.path);
            assert!(std::ptr::eq(request.route().0, route), "{}", route.path);
            let text = serde_json::to_string(&request).unwrap();
            assert_eq!(serde_json::from_str::<ApiRequest>(&text).unwrap(), request, "{text}");
        }
    }

    #[test]
    fn a_body_the_route_refuses_is_refused_where_it_was_sent() {
        let (goal, _) = routes::find(&axum::http::Method::PUT, "/api/uavs/u1/goal").unwrap();
        let refused = ApiRequest::of(goal, Some("u1"), br#"{"goal": [1]}"#).unwrap().unwrap_err();
        assert_eq!((refused.status.as_u16(), refused.field.as_deref()), (422, Some("goal")));
        let (stop, _) = routes::find(&axum::http::Method::POST, "/api/fleet/stop").unwrap();
        assert_eq!(ApiRequest::of(stop, None, b"{}").unwrap(), Ok(ApiRequest::StopFleet));
        assert_eq!(ApiRequest::of(stop, None, br#"{"a": 1}"#).unwrap().unwrap_err().status.as_u16(), 422);
        let set = ApiRequest::SetGoal {
            id: "u 1".into(),
            body: serde_json::from_str(r#"{"goal": [1, 2]}"#).unwrap(),
        };
        assert_eq!(set.path(), "/api/uavs/u 1/goal");
    }
}
