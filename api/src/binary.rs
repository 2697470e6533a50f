//! The binary stream `GET /ws?format=bin`, version 1 (docs/streams.md, Binary stream): per tick one
//! little-endian *tick frame* of fixed-size records, a *roster frame* (ids, policies, goals, links
//! as JSON) whenever those change and first to every new client, and a *reservations frame* (the
//! single-file sections, JSON) likewise. Encoded once per snapshot
//! by [`Encoder`], off the fleet loop, and shared by every client; a client with a viewport copies
//! the records inside it out of the shared frame ([`filter_bbox`]) without decoding anything else.

use axum::body::Bytes;
use engine::snapshot::Snapshot;
use std::collections::HashMap;
use std::sync::Arc;

/// The format's version, the first byte of every message.
pub const VERSION: u8 = 1;
/// Second byte of a tick frame.
pub const KIND_TICK: u8 = 1;
/// Second byte of a roster frame.
pub const KIND_ROSTER: u8 = 2;
/// Second byte of a reservations frame.
pub const KIND_RESERVATIONS: u8 = 3;
/// Bytes of a tick frame's header.
pub const TICK_HEADER_BYTES: usize = 52;
/// Bytes of one UAV's record in a tick frame.
pub const RECORD_BYTES: usize = 40;
/// Bytes before a roster frame's JSON.
pub const ROSTER_HEADER_BYTES: usize = 8;
/// Tick-frame flag: the fleet holds.
pub const FLAG_PAUSED: u16 = 1;
/// Tick-frame flag: only the UAVs inside the client's viewport are in the frame.
pub const FLAG_FILTERED: u16 = 2;
pub use engine::snapshot::{UAV_ARRIVED, UAV_LOST, status_code};

/// One snapshot in the binary format.
#[derive(Debug, Clone, Default)]
pub struct BinaryFrame {
    /// The roster the records' indices refer to.
    pub roster_version: u32,
    /// The roster frame of that version.
    pub roster: Bytes,
    /// Each id of that roster with its index (`GET /api/uavs/{id}` without a scan of the fleet).
    pub index: Arc<HashMap<Arc<str>, usize>>,
    /// The tick frame with every UAV.
    pub body: Bytes,
    /// Changes whenever the reservations frame does.
    pub reservations_version: u32,
    /// The reservations frame: `{"reservations": [...]}` as in the JSON snapshot.
    pub reservations: Bytes,
}

/// Encodes snapshots, remembering the roster to tell when it changed.
#[derive(Debug, Default)]
pub struct Encoder {
    roster_version: u32,
    roster: Bytes,
    index: Arc<HashMap<Arc<str>, usize>>,
    /// (id, policy, goal, link) of the roster, in snapshot order.
    last: Vec<RosterEntry>,
    reservations_version: u32,
    reservations: Bytes,
}

/// What the roster frame says of one UAV: id, policy, goal, link.
type RosterEntry = (Arc<str>, Arc<str>, Option<[f64; 2]>, Arc<str>);

/// The same text: the same shared string, or equal strings.
fn same_text(a: &Arc<str>, b: &Arc<str>) -> bool {
    Arc::ptr_eq(a, b) || a == b
}

fn f32_of(x: Option<f64>) -> f32 {
    x.map_or(f32::NAN, |x| x as f32)
}

impl Encoder {
    /// The binary frame of `snapshot` (a new roster frame only when ids, policies, goals or links
    /// changed since the previous snapshot).
    pub fn encode(&mut self, snapshot: &Snapshot) -> BinaryFrame {
        let uavs = &snapshot.uavs;
        let same = self.roster_version > 0
            && self.last.len() == uavs.len()
            && self.last.iter().zip(uavs).all(|((id, policy, goal, link), u)| {
                // The snapshot shares unchanged names with the previous one: mostly a pointer test.
                same_text(id, &u.id)
                    && same_text(policy, &u.policy)
                    && *goal == u.goal
                    && same_text(link, &u.link)
            });
        if !same {
            // The index depends on the ids alone (a new goal or policy keeps it).
            let ids_changed = self.last.len() != uavs.len()
                || self.last.iter().zip(uavs).any(|(l, u)| !same_text(&l.0, &u.id));
            if ids_changed {
                self.index = Arc::new(uavs.iter().enumerate().map(|(k, u)| (u.id.clone(), k)).collect());
            }
            self.roster_version = self.roster_version.wrapping_add(1).max(1);
            self.last.clear();
            self.last.extend(uavs.iter().map(|u| (u.id.clone(), u.policy.clone(), u.goal, u.link.clone())));
            let list = uavs
                .iter()
                .map(|u| RosterUav { id: &u.id, policy: &u.policy, goal: u.goal, link: &u.link })
                .collect();
            let mut roster = Vec::with_capacity(ROSTER_HEADER_BYTES + 64 * uavs.len());
            roster.extend_from_slice(&[VERSION, KIND_ROSTER, 0, 0]);
            roster.extend_from_slice(&self.roster_version.to_le_bytes());
            // Serialising strings and numbers into a Vec cannot fail (a NaN goal is written null).
            serde_json::to_writer(&mut roster, &Roster { uavs: list }).unwrap_or_default();
            self.roster = Bytes::from(roster);
        }
        let mut body = Vec::with_capacity(TICK_HEADER_BYTES + RECORD_BYTES * uavs.len());
        let flags = if snapshot.paused { FLAG_PAUSED } else { 0 };
        let count = u32::try_from(uavs.len()).unwrap_or(u32::MAX);
        body.extend_from_slice(&[VERSION, KIND_TICK]);
        body.extend_from_slice(&flags.to_le_bytes());
        body.extend_from_slice(&self.roster_version.to_le_bytes());
        body.extend_from_slice(&snapshot.tick.to_le_bytes());
        body.extend_from_slice(&snapshot.time.to_le_bytes());
        body.extend_from_slice(&count.to_le_bytes());
        body.extend_from_slice(&count.to_le_bytes());
        body.extend_from_slice(&(snapshot.road_version as u32).to_le_bytes());
        for x in [
            f32_of(snapshot.min_collision_margin_m),
            f32_of(snapshot.min_road_margin_m),
            snapshot.d_c as f32,
            snapshot.d_s as f32,
        ] {
            body.extend_from_slice(&x.to_le_bytes());
        }
        for (index, u) in (0u32..).zip(uavs) {
            body.extend_from_slice(&index.to_le_bytes());
            for x in [u.p, u.v, u.u, u.target].iter().flatten() {
                body.extend_from_slice(&(*x as f32).to_le_bytes());
            }
            let flags = if u.arrived { UAV_ARRIVED } else { 0 } | if u.lost { UAV_LOST } else { 0 };
            body.extend_from_slice(&[status_code(u.status), flags, 0, 0]);
        }
        let mut reservations = Vec::with_capacity(ROSTER_HEADER_BYTES + 256);
        reservations.extend_from_slice(&[VERSION, KIND_RESERVATIONS, 0, 0, 0, 0, 0, 0]);
        reservations.extend_from_slice(br#"{"reservations":"#);
        // Plain data (strings, counts, finite points): serialising cannot fail.
        serde_json::to_writer(&mut reservations, &snapshot.reservations).unwrap_or_default();
        reservations.push(b'}');
        if self.reservations_version == 0 || reservations[8..] != self.reservations[8..] {
            self.reservations_version = self.reservations_version.wrapping_add(1).max(1);
            reservations[4..8].copy_from_slice(&self.reservations_version.to_le_bytes());
            self.reservations = Bytes::from(reservations);
        }
        BinaryFrame {
            roster_version: self.roster_version,
            roster: self.roster.clone(),
            index: self.index.clone(),
            body: Bytes::from(body),
            reservations_version: self.reservations_version,
            reservations: self.reservations.clone(),
        }
    }
}

/// The JSON of a roster frame: the UAVs in index order.
#[derive(serde::Serialize)]
struct Roster<'s> {
    uavs: Vec<RosterUav<'s>>,
}

/// One UAV of a roster frame.
#[derive(serde::Serialize)]
struct RosterUav<'s> {
    id: &'s str,
    policy: &'s str,
    goal: Option<[f64; 2]>,
    link: &'s str,
}

/// A viewport `[x0, y0, x1, y1]` (m), x0 ≤ x1 and y0 ≤ y1.
pub type Bbox = [f32; 4];

/// The pattern of a `bbox` ([`parse_bbox`]): four decimal numbers, commas between, spaces
/// around. Their order (x0 ≤ x1, y0 ≤ y1) and finiteness as f32 are beyond a pattern.
pub fn bbox_pattern() -> String {
    let space = r"[\t\n\v\f\r ]*";
    let number = format!("{space}[+-]?([0-9]+[.]?[0-9]*|[.][0-9]+)([eE][+-]?[0-9]+)?{space}");
    format!("^{}$", [number.as_str(); 4].join(","))
}

/// Parses `bbox=x0,y0,x1,y1`: four finite numbers with x0 ≤ x1 and y0 ≤ y1.
pub fn parse_bbox(text: &str) -> Result<Bbox, String> {
    let parts: Vec<&str> = text.split(',').collect();
    let values: Vec<f32> = parts.iter().filter_map(|p| p.trim().parse::<f32>().ok()).collect();
    match values[..] {
        [x0, y0, x1, y1]
            if parts.len() == 4 && values.iter().all(|v| v.is_finite()) && x0 <= x1 && y0 <= y1 =>
        {
            Ok([x0, y0, x1, y1])
        }
        _ => Err("must be x0,y0,x1,y1: four finite numbers with x0 ≤ x1 and y0 ≤ y1".into()),
    }
}

fn f32_at(bytes: &[u8], at: usize) -> f32 {
    bytes.get(at..at + 4).and_then(|b| b.try_into().ok()).map_or(f32::NAN, f32::from_le_bytes)
}

/// The tick frame `body` with only the records whose position lies in `bbox` (header copied, the
/// count and [`FLAG_FILTERED`] set).
pub fn filter_bbox(body: &[u8], bbox: Bbox) -> Vec<u8> {
    let Some((header, records)) = body.split_at_checked(TICK_HEADER_BYTES) else { return body.to_vec() };
    let mut out = Vec::with_capacity(body.len().min(TICK_HEADER_BYTES + 64 * RECORD_BYTES));
    out.extend_from_slice(header);
    let mut count = 0u32;
    for record in records.chunks_exact(RECORD_BYTES) {
        let (x, y) = (f32_at(record, 4), f32_at(record, 8));
        if x >= bbox[0] && x <= bbox[2] && y >= bbox[1] && y <= bbox[3] {
            out.extend_from_slice(record);
            count += 1;
        }
    }
    let flags = u16::from_le_bytes([out[2], out[3]]) | FLAG_FILTERED;
    out[2..4].copy_from_slice(&flags.to_le_bytes());
    out[28..32].copy_from_slice(&count.to_le_bytes());
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use engine::snapshot::UavStatus;

    /// The quoted names of the list that follows `start` in `text`, up to its closing bracket.
    fn quoted_list(text: &str, start: &str) -> Vec<String> {
        let from = text.find(start).unwrap_or_else(|| panic!("`{start}` not found")) + start.len();
        let list = &text[from..from + text[from..].find(']').expect("a closing bracket")];
        list.split('"').skip(1).step_by(2).map(str::to_string).collect()
    }

    #[test]
    fn every_reader_of_the_status_byte_uses_the_servers_numbers() {
        let ours: Vec<String> = UavStatus::ALL
            .iter()
            .enumerate()
            .map(|(code, status)| {
                assert_eq!(status_code(*status) as usize, code, "{status:?}");
                serde_json::to_value(status).unwrap().as_str().unwrap().to_string()
            })
            .collect();
        let repo = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
        let read = |path: &str| std::fs::read_to_string(repo.join(path)).unwrap();
        assert_eq!(quoted_list(&read("web/binary.js"), "export const STATUSES = ["), ours, "web/binary.js");
        assert_eq!(
            quoted_list(&read("scripts/airroads_stream.py"), "STATUSES = ["),
            ours,
            "airroads_stream.py"
        );
        // docs/streams.md: "Status codes: 0 flying, 1 arrived, … 12 waiting."
        let docs = read("docs/streams.md");
        let from = docs.find("Status codes: ").expect("the status table") + "Status codes: ".len();
        let table = &docs[from..from + docs[from..].find('.').unwrap()];
        let documented: Vec<String> = table
            .split(',')
            .enumerate()
            .map(|(code, entry)| {
                let (number, name) = entry.trim().split_once(' ').expect("`N name`");
                assert_eq!(number, code.to_string(), "docs/streams.md: {entry}");
                name.to_string()
            })
            .collect();
        assert_eq!(documented, ours, "docs/streams.md");
    }

    #[test]
    fn a_viewport_is_four_finite_ordered_numbers() {
        assert_eq!(parse_bbox("-1,-2.5,3,4"), Ok([-1.0, -2.5, 3.0, 4.0]));
        assert_eq!(parse_bbox(" 0, 0 ,0,0"), Ok([0.0; 4]));
        for bad in
            ["", "1,2,3", "1,2,3,4,5", "a,b,c,d", "1,2,0,4", "1,5,2,4", "0,0,NaN,1", "0,0,1e40,1", "0,,1,1"]
        {
            assert!(parse_bbox(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn filtering_keeps_the_header_and_the_records_inside() {
        let mut body = vec![0u8; TICK_HEADER_BYTES];
        body[..2].copy_from_slice(&[VERSION, KIND_TICK]);
        for (index, (x, y)) in [(0u32, (0.0f32, 0.0f32)), (1, (5.0, 5.0)), (2, (f32::NAN, 0.0))] {
            let mut record = vec![0u8; RECORD_BYTES];
            record[..4].copy_from_slice(&index.to_le_bytes());
            record[4..8].copy_from_slice(&x.to_le_bytes());
            record[8..12].copy_from_slice(&y.to_le_bytes());
            body.extend_from_slice(&record);
        }
        let out = filter_bbox(&body, [-1.0, -1.0, 1.0, 1.0]);
        assert_eq!(out.len(), TICK_HEADER_BYTES + RECORD_BYTES);
        assert_eq!(u32::from_le_bytes(out[28..32].try_into().unwrap()), 1);
        assert_eq!(u16::from_le_bytes([out[2], out[3]]), FLAG_FILTERED);
        assert_eq!(&out[TICK_HEADER_BYTES..TICK_HEADER_BYTES + 4], &0u32.to_le_bytes());
    }
}
