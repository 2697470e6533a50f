//! Table of contents (TOC) v2, shared by the log and param ports (channel 0).
//!
//! Requests: `[CMD_GET_INFO_V2]` and `[CMD_GET_ITEM_V2, id_lo, id_hi]`. Answers, as in the
//! firmware's `logTOCProcess`/`paramTOCProcess`: info `[3, count(u16), crc(u32), extra..]`,
//! item `[2, id(u16), type, group\0, name\0]`, or `[2]` alone for an id out of range.

use crate::crtp::{self, Packet};

/// Get one TOC item (v2: 16-bit ids).
pub const CMD_GET_ITEM_V2: u8 = 2;
/// Get the TOC size and CRC (v2).
pub const CMD_GET_INFO_V2: u8 = 3;

/// One TOC entry.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TocEntry {
    /// Group name, e.g. `stateEstimate`.
    pub group: &'static str,
    /// Variable name, e.g. `x`.
    pub name: &'static str,
    /// Type byte as sent in the TOC (the log or param type code and flags).
    pub type_byte: u8,
}

/// A TOC with its CRC (the key clients use to cache it).
#[derive(Debug, Clone)]
pub struct Toc {
    entries: Vec<TocEntry>,
    crc: u32,
}

impl Toc {
    /// Build a TOC; ids are the positions in `entries`.
    pub fn new(entries: Vec<TocEntry>) -> Self {
        // Chained like the firmware: crc_i = crc32(crc_{i-1} ++ type ++ group ++ name).
        let mut crc = 0u32;
        for e in &entries {
            let mut buf = crc.to_le_bytes().to_vec();
            buf.push(e.type_byte);
            buf.extend_from_slice(e.group.as_bytes());
            buf.extend_from_slice(e.name.as_bytes());
            crc = crtp::crc32(&buf);
        }
        Self { entries, crc }
    }

    /// The entries, in id order.
    pub fn entries(&self) -> &[TocEntry] {
        &self.entries
    }

    /// The TOC CRC.
    pub fn crc(&self) -> u32 {
        self.crc
    }

    /// The id of `group.name`.
    pub fn find(&self, group: &str, name: &str) -> Option<usize> {
        self.entries.iter().position(|e| e.group == group && e.name == name)
    }

    /// Answer a channel-0 request on `port`; `info_extra` is appended to the info answer.
    /// Unknown commands (including the v1 ones) get no answer, like the current firmware.
    pub fn handle(&self, port: u8, data: &[u8], info_extra: &[u8]) -> Option<Packet> {
        match crtp::u8_at(data, 0)? {
            CMD_GET_INFO_V2 => {
                let count = u16::try_from(self.entries.len()).unwrap_or(u16::MAX);
                let mut out = vec![CMD_GET_INFO_V2];
                out.extend_from_slice(&count.to_le_bytes());
                out.extend_from_slice(&self.crc.to_le_bytes());
                out.extend_from_slice(info_extra);
                Some(Packet::new(port, 0, out))
            }
            CMD_GET_ITEM_V2 => {
                // A short request reads the missing id bytes as zero (the firmware reads stale
                // buffer bytes there).
                let lo = crtp::u8_at(data, 1).unwrap_or(0);
                let hi = crtp::u8_at(data, 2).unwrap_or(0);
                let id = u16::from_le_bytes([lo, hi]);
                let Some(e) = self.entries.get(usize::from(id)) else {
                    return Some(Packet::new(port, 0, vec![CMD_GET_ITEM_V2]));
                };
                let mut out = vec![CMD_GET_ITEM_V2, lo, hi, e.type_byte];
                out.extend_from_slice(e.group.as_bytes());
                out.push(0);
                out.extend_from_slice(e.name.as_bytes());
                out.push(0);
                Some(Packet::new(port, 0, out))
            }
            _ => None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn toc() -> Toc {
        Toc::new(vec![
            TocEntry { group: "a", name: "x", type_byte: 7 },
            TocEntry { group: "bb", name: "yy", type_byte: 1 },
        ])
    }

    #[test]
    fn info_and_items() {
        let t = toc();
        let info = t.handle(5, &[3], &[16, 128]).expect("info");
        assert_eq!(info.data[..3], [3, 2, 0]);
        assert_eq!(info.data[3..7], t.crc().to_le_bytes());
        assert_eq!(info.data[7..], [16, 128]);
        let item = t.handle(5, &[2, 1, 0], &[]).expect("item");
        assert_eq!(item.data, vec![2, 1, 0, 1, b'b', b'b', 0, b'y', b'y', 0]);
        assert_eq!(t.handle(5, &[2, 9, 0], &[]).expect("oob").data, vec![2]);
        assert_eq!(t.find("bb", "yy"), Some(1));
    }

    #[test]
    fn garbage_gets_no_answer_or_a_safe_one() {
        let t = toc();
        assert!(t.handle(5, &[], &[]).is_none());
        assert!(t.handle(5, &[0], &[]).is_none());
        assert!(t.handle(5, &[1, 2, 3], &[]).is_none());
        assert!(t.handle(5, &[2], &[]).is_some());
        assert_ne!(t.crc(), Toc::new(vec![]).crc());
    }
}
