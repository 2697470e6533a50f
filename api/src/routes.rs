//! Every REST route, written once ([`ROUTES`]): the router is built from it, the regions'
//! forwarding asks it where a request is answered ([`Reach`]), the token check which routes are an
//! operator's stop and land ([`Access::Urgent`]) and which reads need the token, the request guard
//! which changes exist, and a test holds the OpenAPI document's paths to it.

use super::openapi::{Doc, docs};
use super::state::AppState;
use super::{handlers, road};
use axum::Router;
use axum::http::Method;
use axum::routing::{MethodFilter, MethodRouter, on};
use regions::federation::Kind;

/// An HTTP method the API takes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Verb {
    /// GET: a read.
    Get,
    /// PUT: a change.
    Put,
    /// POST: a change.
    Post,
    /// DELETE: a change.
    Delete,
}

impl Verb {
    /// The verb of `method` (None: a method no route takes).
    pub fn of(method: &Method) -> Option<Verb> {
        match *method {
            Method::GET => Some(Verb::Get),
            Method::PUT => Some(Verb::Put),
            Method::POST => Some(Verb::Post),
            Method::DELETE => Some(Verb::Delete),
            _ => None,
        }
    }

    /// Its HTTP method.
    pub fn method(self) -> Method {
        match self {
            Verb::Get => Method::GET,
            Verb::Put => Method::PUT,
            Verb::Post => Method::POST,
            Verb::Delete => Method::DELETE,
        }
    }

    /// Its name in an OpenAPI document (`get`, `put`, ...).
    pub fn name(self) -> &'static str {
        match self {
            Verb::Get => "get",
            Verb::Put => "put",
            Verb::Post => "post",
            Verb::Delete => "delete",
        }
    }

    fn filter(self) -> MethodFilter {
        match self {
            Verb::Get => MethodFilter::GET,
            Verb::Put => MethodFilter::PUT,
            Verb::Post => MethodFilter::POST,
            Verb::Delete => MethodFilter::DELETE,
        }
    }
}

/// Who may call a route.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Access {
    /// Anyone (a read of the fleet's public state).
    Read,
    /// With the token when one is set (the audit log).
    PrivateRead,
    /// With the token: a change, applied and saved by the fleet loop.
    Change,
    /// With the token, checked even for a rate-limited network once a second: land and stop.
    Urgent,
}

/// Where a request is answered when the road is split into regions (`serve::federate`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Reach {
    /// Here only.
    Here,
    /// About the UAV of the path's `{id}`: here if flown here, else at its owner.
    Uav,
    /// `GET /api/state`: every region's, merged.
    State,
    /// `GET /api/uavs`: every region's, merged.
    List,
    /// `POST /api/uavs`: at the region of the position.
    Add,
    /// A fleet-wide command: here, then everywhere.
    Fleet,
    /// A road or a scenario: every region at once, or none (`serve::deploy`).
    Deploy(Kind),
}

/// One route of the API.
pub struct Route {
    /// Its method.
    pub verb: Verb,
    /// Its path template (`{id}` is one non-empty segment).
    pub path: &'static str,
    /// Who may call it.
    pub access: Access,
    /// Where it is answered in a deployment of regions.
    pub reach: Reach,
    /// What the OpenAPI document says of it beyond the above.
    pub doc: &'static Doc,
    /// Its handler, for the method filter given.
    handler: fn(MethodFilter) -> MethodRouter<AppState>,
}

const fn route(
    verb: Verb,
    path: &'static str,
    access: Access,
    reach: Reach,
    doc: &'static Doc,
    handler: fn(MethodFilter) -> MethodRouter<AppState>,
) -> Route {
    Route { verb, path, access, reach, doc, handler }
}

use Access::{Change, PrivateRead, Read, Urgent};
use Reach::{Add, Deploy, Fleet, Here, List, State, Uav};
use Verb::{Delete, Get, Post, Put};

/// The REST API (docs/api.md, `GET /api/openapi.json`).
pub static ROUTES: &[Route] = &[
    route(Get, "/healthz", Read, Here, &docs::HEALTHZ, |m| on(m, handlers::healthz)),
    route(Get, "/api/openapi.json", Read, Here, &docs::OPENAPI, |m| on(m, handlers::openapi)),
    route(Get, "/api/road", Read, Here, &docs::GET_ROAD, |m| on(m, road::get_road)),
    route(Put, "/api/road", Change, Deploy(Kind::Road), &docs::PUT_ROAD, |m| on(m, road::put_road)),
    route(Get, "/api/road/geometry", Read, Here, &docs::GET_ROAD_GEOMETRY, |m| {
        on(m, road::get_road_geometry)
    }),
    route(Get, "/api/uavs", Read, List, &docs::LIST_UAVS, |m| on(m, handlers::list_uavs)),
    route(Post, "/api/uavs", Change, Add, &docs::ADD_UAV, |m| on(m, handlers::add_uav)),
    route(Get, "/api/uavs/{id}", Read, Uav, &docs::GET_UAV, |m| on(m, handlers::get_uav)),
    route(Delete, "/api/uavs/{id}", Change, Uav, &docs::REMOVE_UAV, |m| on(m, handlers::remove_uav)),
    route(Put, "/api/uavs/{id}/goal", Change, Uav, &docs::SET_GOAL, |m| on(m, handlers::set_goal)),
    route(Delete, "/api/uavs/{id}/goal", Change, Uav, &docs::CLEAR_GOAL, |m| on(m, handlers::clear_goal)),
    route(Put, "/api/uavs/{id}/policy", Change, Uav, &docs::SET_POLICY, |m| on(m, handlers::set_policy)),
    route(Post, "/api/uavs/{id}/land", Urgent, Uav, &docs::LAND_UAV, |m| on(m, handlers::land_uav)),
    route(Get, "/api/policies", Read, Here, &docs::LIST_POLICIES, |m| on(m, handlers::list_policies)),
    route(Post, "/api/scenario", Change, Deploy(Kind::Scenario), &docs::LOAD_SCENARIO, |m| {
        on(m, handlers::load_scenario)
    }),
    route(Post, "/api/fleet/pause", Change, Fleet, &docs::PAUSE, |m| on(m, handlers::pause)),
    route(Post, "/api/fleet/resume", Change, Fleet, &docs::RESUME, |m| on(m, handlers::resume)),
    route(Post, "/api/fleet/land", Urgent, Fleet, &docs::LAND_FLEET, |m| on(m, handlers::land_fleet)),
    route(Post, "/api/fleet/stop", Urgent, Fleet, &docs::STOP_FLEET, |m| on(m, handlers::stop_fleet)),
    route(Get, "/api/state", Read, State, &docs::GET_STATE, |m| on(m, handlers::get_state)),
    route(Get, "/api/metrics", Read, Here, &docs::GET_METRICS, |m| on(m, handlers::get_metrics)),
    route(Get, "/api/audit", PrivateRead, Here, &docs::AUDIT, |m| on(m, super::audit::list)),
    route(Get, "/api/region/ownership", Read, Here, &docs::GET_OWNERSHIP, |m| on(m, handlers::get_ownership)),
    route(Get, "/api/rerun/selection", Read, Here, &docs::GET_RERUN_SELECTION, |m| {
        on(m, handlers::get_rerun_selection)
    }),
    route(Put, "/api/rerun/selection", Change, Here, &docs::PUT_RERUN_SELECTION, |m| {
        on(m, handlers::put_rerun_selection)
    }),
];

/// The router of every route in [`ROUTES`].
pub fn router() -> Router<AppState> {
    ROUTES.iter().fold(Router::new(), |router, r| router.route(r.path, (r.handler)(r.verb.filter())))
}

/// The route `method` on `path` takes, with the segment its `{id}` matched (None: no route
/// takes it; the router answers 404 or 405).
pub fn find<'p>(method: &Method, path: &'p str) -> Option<(&'static Route, Option<&'p str>)> {
    let verb = Verb::of(method)?;
    ROUTES.iter().filter(|r| r.verb == verb).find_map(|r| matches(r.path, path).map(|id| (r, id)))
}

/// `Some(id)` when `path` matches `template` (`id`: what `{id}` matched, if it has one).
fn matches<'p>(template: &str, path: &'p str) -> Option<Option<&'p str>> {
    let (mut t, mut p) = (template.split('/'), path.split('/'));
    let mut id = None;
    loop {
        match (t.next(), p.next()) {
            (None, None) => return Some(id),
            (Some(want), Some(got)) if want.starts_with('{') && !got.is_empty() => id = Some(got),
            (Some(want), Some(got)) if want == got => {}
            _ => return None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_route_is_found_by_its_method_and_path_with_its_id() {
        let (stop, _) = find(&Method::POST, "/api/fleet/stop").unwrap();
        assert_eq!((stop.access, stop.reach), (Urgent, Fleet));
        let (goal, id) = find(&Method::PUT, "/api/uavs/uav-1/goal").unwrap();
        assert_eq!((goal.path, id), ("/api/uavs/{id}/goal", Some("uav-1")));
        assert_eq!(
            find(&Method::DELETE, "/api/uavs/x").map(|(r, id)| (r.path, id)),
            Some(("/api/uavs/{id}", Some("x")))
        );
        assert!(find(&Method::PUT, "/api/metrics").is_none());
        assert!(find(&Method::POST, "/api/uavs//land").is_none());
        assert!(find(&Method::POST, "/api/uavs/a/b/land").is_none());
        assert!(find(&Method::PATCH, "/api/road").is_none());
        assert!(find(&Method::POST, "/nowhere").is_none());
    }

    #[test]
    fn every_route_is_written_once() {
        for (k, a) in ROUTES.iter().enumerate() {
            let twice = ROUTES[k + 1..].iter().any(|b| a.verb == b.verb && a.path == b.path);
            assert!(!twice, "{:?} {} twice", a.verb, a.path);
        }
    }
}
