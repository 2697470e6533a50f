"""schemathesis hooks of scripts/api-fuzz (loaded by `hooks` in schemathesis.toml).

The check `documented_refusals` narrows the exceptions of schemathesis.toml: where a schema-valid
request may be answered 422 (positive_data_acceptance allows it for seven operations), the refusal
must be one of those the operation documents as beyond any schema (the state of the server, road
geometry, the order of a bbox, a whole number written as `2.0` where an integer is read), recognised by its error `code` and `field`.
Any other 422 for schema-valid data (a limit the server enforces but the schemas do not state)
fails, as it would anywhere else. Also serialises `ast.parse` (see below).
"""

import ast
import math
import re
import struct
import threading

import schemathesis

# The AST converter of CPython 3.11 (which the virtualenv runs on here) keeps its recursion depth in
# interpreter-wide state: two threads parsing at once can fail with "SystemError: AST constructor
# recursion depth mismatch" (python/cpython#106905 and related reports), which ended a run as a
# runtime error. Hypothesis parses lambda sources to describe strategies, and `--workers 2` runs two
# threads: one parse at a time.
_parse = ast.parse
_parse_lock = threading.Lock()


def _serial_parse(*args, **kwargs):
    with _parse_lock:
        return _parse(*args, **kwargs)


ast.parse = _serial_parse

try:  # request-shape probes of the coverage phase are not requests with schema-valid data
    from schemathesis.specs.openapi.checks import is_unexpected_http_status_case
except ImportError:  # pragma: no cover - another schemathesis version

    def is_unexpected_http_status_case(case):
        return False


# Road rules that no JSON schema states (the others, such as `empty` or `absurd_coordinate`, are in
# the schemas and must never refuse schema-valid data).
GEOMETRY_RULES = {
    "degenerate_edge",
    "not_convex",
    "seamless_join",
    "folds_back",
    "overlap",
    "duplicate_region_name",
    "reversed_region",
    "region_out_of_range",
    "region_overlap",
    "region_gap",
    # a network's
    "empty_region",
    "unknown_name",
    "duplicate_name",
    "shared_by_three",
    "partial_edge",
    "disconnected",
    "narrow_passage",
    "sharp_corner",
}
SEGMENTS_FIELD = re.compile(
    r"^(segments(\[\d+\])?|regions(\[\d+\](\.(name|segments|roads\[\d+\]|junctions\[\d+\]))?)?"
    r"|roads(\[\d+\]\.(name|segments(\[\d+\])?))?|junctions\[\d+\]\.(name|polygon))$"
)
# More than 20000 cells over all of a network's roads and junctions: no schema states a total.
NETWORK_CELLS = ("too_many_segments", "roads")
SCENARIO_UAV_FIELD = re.compile(r"^uavs\[\d+\]\.(start|goal|id|link)$")
UAV_ID = re.compile(r"[A-Za-z0-9_.-]{1,64}")  # the UavId schema


def _names_no_uav(message):
    """True for `no UAV `ID`` with an id a UAV could have (an id no UAV can have is the schema's)."""
    match = re.fullmatch(r"no UAV `(.*)`", message, re.S)
    return match is not None and UAV_ID.fullmatch(match.group(1)) is not None


def _f32(text):
    """The number as the server reads it (a 32-bit float), inf when it overflows."""
    value = float(text)
    try:
        return struct.unpack("f", struct.pack("f", value))[0]
    except OverflowError:
        return math.copysign(math.inf, value)


def _bbox_beyond_schema(bbox):
    """True when a schema-valid `bbox` is refused for what the schema cannot say (False when it is not
    four numbers at all: the schema states that)."""
    try:
        x0, y0, x1, y1 = (_f32(part.strip()) for part in bbox.split(","))
    except ValueError:
        return False
    return not all(map(math.isfinite, (x0, y0, x1, y1))) or x0 > x1 or y0 > y1


# JSON Schema cannot tell `2.0` from `2` (both are integers to it), but the server reads integer
# fields as integers and refuses a whole number written with a fraction or an exponent.
INTEGRAL_FLOAT = re.compile(r"^invalid type: floating point `[^`]*`, expected (usize|u\d+|i\d+)\b")


def _is_udp(link):
    return isinstance(link, str) and link.startswith("udp://")


def _list_uavs(case, code, field, message):
    query = case.query or {}
    if code != "invalid_value":
        return False
    if field == "after":
        return _names_no_uav(message)
    return field == "bbox" and "bbox" in query and _bbox_beyond_schema(query["bbox"])


def _add_uav(case, code, field, message):
    body = case.body if isinstance(case.body, dict) else {}
    return (
        (code == "unsafe" and field in ("position", "goal"))
        or (code == "unknown_policy" and field == "policy")
        or (code == "invalid_value" and field == "link" and _is_udp(body.get("link")))
        or (code == "fleet_full" and field == "uavs")
    )


def _set_goal(case, code, field, message):
    return code == "unsafe" and field == "goal"


def _set_policy(case, code, field, message):
    return code == "unknown_policy" and field == "policy"


def _put_road(case, code, field, message, rule=None):
    if code == "invalid_road" and (rule, field) == NETWORK_CELLS:
        return True
    return code == "invalid_road" and rule in GEOMETRY_RULES and bool(SEGMENTS_FIELD.match(field))


def _load_scenario(case, code, field, message):
    if code == "fleet_full":
        return field == "uavs"
    if code != "invalid_value":
        return False
    if field == "regions" and message.startswith("regions of "):
        return True  # a chain's regions on a network or a network's on a chain (the schema has both)
    if SEGMENTS_FIELD.match(field):
        rule = re.search(r"\((\w+)\)$", message)
        return rule is not None and (rule.group(1) in GEOMETRY_RULES or (rule.group(1), field) == NETWORK_CELLS)
    match = SCENARIO_UAV_FIELD.match(field)
    if not match:
        return False
    if match.group(1) == "id":
        return message.startswith("duplicate id")
    if match.group(1) == "link":
        index = int(field[5 : field.index("]")])
        uavs = case.body.get("uavs", []) if isinstance(case.body, dict) else []
        return index < len(uavs) and _is_udp(uavs[index].get("link"))
    return True  # a start or goal outside this road, too near a wall, or starts closer than D_c


def _rerun_selection(case, code, field, message):
    return code == "invalid_value" and field == "ids" and _names_no_uav(message)


ALLOWED = {
    ("GET", "/api/uavs"): _list_uavs,
    ("POST", "/api/uavs"): _add_uav,
    ("PUT", "/api/uavs/{id}/goal"): _set_goal,
    ("PUT", "/api/uavs/{id}/policy"): _set_policy,
    ("PUT", "/api/road"): _put_road,
    ("POST", "/api/scenario"): _load_scenario,
    ("PUT", "/api/rerun/selection"): _rerun_selection,
}


@schemathesis.check
def documented_refusals(ctx, response, case):
    """A 422 for schema-valid data is only accepted for a refusal the operation documents as beyond the schema."""
    meta = case.meta
    if response.status_code != 422 or meta is None or not meta.generation.mode.is_positive:
        return None
    if is_unexpected_http_status_case(case):
        return None
    allowed = ALLOWED.get((case.operation.method.upper(), case.operation.path))
    if allowed is None:
        return None  # positive_data_acceptance itself refuses 422 there
    try:
        error = response.json()["error"]
        code, field, message = error["code"], error.get("field") or "", error.get("message") or ""
    except Exception as exc:
        raise AssertionError(f"a 422 without the documented error body: {exc}") from None
    extra = {"rule": error.get("rule")} if allowed is _put_road else {}
    integral_float = code == "invalid_body" and INTEGRAL_FLOAT.match(message)
    try:
        documented = integral_float or allowed(case, code, field, message, **extra)
    except (AttributeError, IndexError, KeyError, TypeError, ValueError):
        documented = False  # a request of another shape than the documented refusal's
    if not documented:
        raise AssertionError(
            f"Schema-valid data refused with 422 `{code}` (field `{field}`: {message}), which is not "
            f"one of the refusals {case.operation.method.upper()} {case.operation.path} documents as "
            "beyond the schema: state the limit in the schema (api/src/openapi/, the types' schemars attributes), or stop enforcing it"
        )
    return None
