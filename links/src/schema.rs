//! The JSON schema of a link URI ([`crate::parse_link`]), for the OpenAPI document (`schemars`).

use crate::uri::MAX_LINK_LEN;
use schemars::{JsonSchema, Schema, SchemaGenerator, json_schema};
use std::borrow::Cow;

/// The schema of a link as a request writes it: `sim` or a Crazyflie URI (schema name `Link`).
pub struct LinkText;

/// A number 0 to 255 without leading zeros.
const BYTE: &str = "(25[0-5]|2[0-4][0-9]|1[0-9]{2}|[1-9]?[0-9])";

/// The pattern of every URI [`crate::parse_link`] takes, but for the UDP host rules a pattern cannot
/// state (unicast, loopback unless allowed, a bracketed host an IPv6 address).
pub fn link_pattern() -> String {
    let channel = "(12[0-5]|1[01][0-9]|[1-9]?[0-9])";
    let timeout = "timeout=(60000|[1-5][0-9]{4}|[1-9][0-9]{0,3})";
    let flags = ["safelink=[01]", "ackfilter=[01]", timeout];
    // Each flag at most once, in any order: every ordering of every non-empty subset.
    let mut orders: Vec<Vec<usize>> = (0..3).map(|i| vec![i]).collect();
    for (i, j) in [(0, 1), (0, 2), (1, 2)] {
        orders.extend([vec![i, j], vec![j, i]]);
    }
    let triples = [[0, 1, 2], [0, 2, 1], [1, 0, 2], [1, 2, 0], [2, 0, 1], [2, 1, 0]];
    orders.extend(triples.iter().map(|t| t.to_vec()));
    let queries: Vec<String> =
        orders.iter().map(|o| o.iter().map(|&k| flags[k]).collect::<Vec<_>>().join("&")).collect();
    let radio =
        format!("radio://{BYTE}/{channel}/(250K|1M|2M)/[0-9A-Fa-f]{{10}}(\\?({}))?", queries.join("|"));
    let port = "(6553[0-5]|655[0-2][0-9]|65[0-4][0-9]{2}|6[0-4][0-9]{3}|[1-5][0-9]{4}|[1-9][0-9]{0,3})";
    let udp = format!("udp://(localhost|{BYTE}(\\.{BYTE}){{3}}|\\[[0-9A-Fa-f:.]{{2,45}}\\]):{port}");
    format!("^(sim|{radio}|usb://[A-Za-z0-9]{{1,64}}|{udp})$")
}

impl JsonSchema for LinkText {
    fn schema_name() -> Cow<'static, str> {
        "Link".into()
    }

    fn json_schema(_: &mut SchemaGenerator) -> Schema {
        json_schema!({
            "type": "string",
            "maxLength": MAX_LINK_LEN,
            "pattern": link_pattern(),
            "description": "`sim` (in-process simulator, the default) or a Crazyflie URI: `radio://DEV/CHANNEL/RATE/ADDRESS[?FLAGS]` (DEV 0–255, CHANNEL 0–125, RATE `250K`, `1M` or `2M`, ADDRESS 10 hex digits, FLAGS `safelink=0|1`, `ackfilter=0|1`, `timeout=MS` (1–60000) each at most once, joined by `&`; e.g. `radio://0/80/2M/E7E7E7E7E7`), `usb://SERIAL` (1–64 letters and digits), `udp://HOST:PORT` (CrazySim, cfsim; HOST an IPv4 literal, a bracketed IPv6 literal or `localhost`, PORT 1–65535, numbers without leading zeros). Beyond the pattern, a UDP host must be a unicast address, and a loopback one (127.0.0.0/8, ::1, `localhost`) unless the server was started with `--allow-link-host` for it (a setting of the server, so not in the schema); a bracketed host that is not an IPv6 address is refused too"
        })
    }
}

#[cfg(test)]
mod tests {
    use crate::{LinkRules, parse_link};

    #[test]
    fn the_pattern_takes_what_the_parser_takes() {
        let pattern = regex::Regex::new(&super::link_pattern()).expect("a valid pattern");
        let rules = LinkRules::default();
        let uris = [
            "sim",
            "simx",
            "radio://0/80/2M/E7E7E7E7E7",
            "radio://0/80/2M/E7E7E7E7E7?safelink=1&timeout=500",
            "radio://0/80/2M/E7E7E7E7E7?timeout=500&ackfilter=0&safelink=1",
            "radio://0/126/2M/E7E7E7E7E7",
            "radio://256/80/2M/E7E7E7E7E7",
            "radio://0/80/3M/E7E7E7E7E7",
            "radio://0/80/2M/E7E7E7E7",
            "radio://0/80/2M/E7E7E7E7E7?safelink=1&safelink=0",
            "radio://0/80/2M/E7E7E7E7E7?timeout=60001",
            "radio://0/80/2M/E7E7E7E7E7?timeout=0",
            "radio://00/80/2M/E7E7E7E7E7",
            "usb://ABC123",
            "usb://",
            "udp://127.0.0.1:19850",
            "udp://localhost:1",
            "udp://[::1]:65535",
            "udp://127.0.0.1:65536",
            "udp://127.0.0.1:0",
            "udp://127.0.0.01:5",
            "udp://127.0.0.1",
            "RADIO://0/80/2M/E7E7E7E7E7",
        ];
        for uri in uris {
            assert_eq!(pattern.is_match(uri), parse_link(uri, &rules).is_ok(), "{uri}");
        }
    }
}
