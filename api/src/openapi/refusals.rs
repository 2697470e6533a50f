//! The refusals a route shares with others, from its access (the listener's, the guard's and the
//! token check's), its body (the JSON extractor's) and its reach among regions (the federation's).

use super::{Answer, Body, refusal};
use crate::routes::{Access, Reach, Route};

/// What the listener refuses before any route: every route's.
const LISTENER: [Answer; 3] = [
    refusal(414, "the request target is longer than 8 KiB"),
    refusal(421, "the `Host` header does not name this server (see --allow-host)"),
    refusal(431, "more than 100 header lines or 32 KiB of headers"),
];

/// What the token check refuses.
const TOKEN: [Answer; 2] = [
    refusal(401, "a token is configured and the request lacks `Authorization: Bearer <token>`"),
    refusal(429, "too many requests with a wrong token from this address"),
];

/// What the guard refuses of a change.
const GUARD: [Answer; 4] = [
    refusal(
        403,
        "the request comes from a page of another origin (`Origin` not the server's own nor --allow-origin)",
    ),
    refusal(408, "the body did not arrive within 10 s"),
    refusal(411, "a chunked body: send it with a Content-Length"),
    refusal(413, "the body is larger than 4 MiB"),
];

/// What the JSON extractor refuses of a body.
const JSON_BODY: [Answer; 3] = [
    refusal(400, "malformed JSON (also data after the JSON document)"),
    refusal(415, "not JSON: every change must say `Content-Type: application/json`"),
    refusal(422, "a field has an invalid value; `field` names it"),
];

/// What is refused of a change that takes no data.
const EMPTY_BODY: [Answer; 3] = [
    refusal(400, "malformed JSON (also data after the JSON document)"),
    refusal(415, "every change must say `Content-Type: application/json`, also without a body"),
    refusal(422, "a body other than nothing or `{}`"),
];

/// The refusals `route` shares with others of its kind (its [`super::Doc`] may replace them).
pub fn shared(route: &Route) -> Vec<Answer> {
    let mut answers = LISTENER.to_vec();
    let change = matches!(route.access, Access::Change | Access::Urgent);
    if change || route.access == Access::PrivateRead {
        answers.extend(TOKEN);
    }
    if change {
        answers.extend(GUARD);
        match route.doc.body {
            Body::Json(_) => answers.extend(JSON_BODY),
            Body::Empty | Body::None => answers.extend(EMPTY_BODY),
        }
    }
    if route.path.contains("{id}") {
        answers.push(refusal(404, "unknown UAV"));
    }
    answers.extend(regions(route, change));
    answers
}

/// The refusals of a deployment of regions (and the busy loop's, which a change shares with them).
fn regions(route: &Route, change: bool) -> Vec<Answer> {
    // (503 of a read, 503 of a change, 502)
    let (read, changed, failed) = match route.reach {
        Reach::Uav => (
            Some(
                "with `serve --region`: `region_unavailable`, a region that may fly this UAV did not answer (`region` names it)",
            ),
            "the fleet loop is not running or too busy; with `serve --region`: `region_unavailable`, a region that may fly this UAV did not answer (`region` names it)",
            None,
        ),
        Reach::Add => (
            None,
            "the fleet loop is not running or too busy; with `serve --region`: `region_unavailable`, the region of `position` did not answer",
            None,
        ),
        Reach::Deploy(_) => (
            None,
            "the fleet loop is not running or too busy; with `serve --region`: `region_unavailable`, a region did not answer the check; nothing changed",
            Some(
                "with `serve --region`: `deployment_failed`, a region failed at the switch (`regions` has each one's answer; a road is put back where it was applied)",
            ),
        ),
        Reach::Fleet => (
            None,
            "the fleet loop is not running or too busy",
            Some(
                "with `serve --region`: `regions_failed`, applied in this region but another refused it or did not answer (`regions` has each one's answer)",
            ),
        ),
        Reach::Here | Reach::State | Reach::List => (None, "the fleet loop is not running or too busy", None),
    };
    let unavailable = if change { Some(changed) } else { read };
    let failed = failed.filter(|_| change);
    unavailable
        .map(|text| refusal(503, text))
        .into_iter()
        .chain(failed.map(|text| refusal(502, text)))
        .collect()
}
