//! The param port (2): TOC (channel 0), read (1), write (2) and misc (3), v2 (16-bit ids), after
//! the firmware's `param_logic.c`.

use crate::crtp::{self, PORT_PARAM, Packet};
use crate::toc::{Toc, TocEntry};

/// Param type bytes: size in bits 0-1, float in bit 2, unsigned in bit 3.
const UINT8: u8 = 0x08;
const UINT32: u8 = 0x0a;
const FLOAT: u8 = 0x06;
/// Flags in the TOC type byte.
const CORE: u8 = 0x20;
const RONLY: u8 = 0x40;

const MISC_GET_EXTENDED_TYPE_V2: u8 = 7;
const MISC_GET_DEFAULT_VALUE_V2: u8 = 8;
const ENOENT: u8 = 2;

/// The params: (group, name, type byte with flags, default value). Ids are the positions.
const PARAMS: &[(&str, &str, u8, f64)] = &[
    ("commander", "enHighLevel", UINT8, 1.0),
    ("stabilizer", "estimator", UINT8 | CORE, 2.0),
    ("stabilizer", "controller", UINT8 | CORE, 1.0),
    ("kalman", "resetEstimation", UINT8 | CORE, 0.0),
    ("locSrv", "extPosStdDev", FLOAT | CORE, 0.01),
    ("locSrv", "extQuatStdDev", FLOAT | CORE, 4.5e-3),
    ("firmware", "revision0", UINT32 | CORE | RONLY, 0.0),
];

fn size_of(type_byte: u8) -> usize {
    1 << (type_byte & 0x03)
}

/// Encode `v` as the param type.
fn encode(v: f64, type_byte: u8) -> Vec<u8> {
    let n = size_of(type_byte);
    if type_byte & 0x04 != 0 {
        match n {
            8 => v.to_le_bytes().to_vec(),
            _ => (v as f32).to_le_bytes().to_vec(),
        }
    } else {
        (v as i64).to_le_bytes()[..n].to_vec()
    }
}

/// Decode a param value of the given type from `bytes` (which must hold enough bytes).
fn decode(bytes: &[u8], type_byte: u8) -> Option<f64> {
    let n = size_of(type_byte);
    let b = bytes.get(..n)?;
    let unsigned = type_byte & 0x08 != 0;
    Some(if type_byte & 0x04 != 0 {
        match n {
            4 => f64::from(f32::from_le_bytes(b.try_into().ok()?)),
            8 => f64::from_le_bytes(b.try_into().ok()?),
            // Half floats are stored but not interpreted.
            _ => f64::from(u16::from_le_bytes(b.try_into().ok()?)),
        }
    } else {
        let mut buf = [0u8; 8];
        buf[..n].copy_from_slice(b);
        if !unsigned && b[n - 1] & 0x80 != 0 {
            buf[n..].fill(0xff);
        }
        i64::from_le_bytes(buf) as f64
    })
}

/// The param subsystem: TOC and current values.
#[derive(Debug, Clone)]
pub struct Params {
    toc: Toc,
    values: Vec<f64>,
}

impl Default for Params {
    fn default() -> Self {
        Self::new()
    }
}

impl Params {
    /// All params at their defaults.
    pub fn new() -> Self {
        let entries =
            PARAMS.iter().map(|&(group, name, type_byte, _)| TocEntry { group, name, type_byte }).collect();
        Self { toc: Toc::new(entries), values: PARAMS.iter().map(|p| p.3).collect() }
    }

    /// The TOC.
    pub fn toc(&self) -> &Toc {
        &self.toc
    }

    /// The value of `group.name` (as f64), if it exists.
    pub fn get(&self, group: &str, name: &str) -> Option<f64> {
        self.toc.find(group, name).and_then(|i| self.values.get(i).copied())
    }

    /// Set `group.name` from inside the firmware (no notification is sent).
    pub fn set(&mut self, group: &str, name: &str, value: f64) {
        if let Some(v) = self.toc.find(group, name).and_then(|i| self.values.get_mut(i)) {
            *v = value;
        }
    }

    /// Handle a packet on the param port. Returns the answer, if any, and the id written by a
    /// successful write (so the firmware can run the param's callback).
    pub fn handle(&mut self, pk: &Packet) -> (Option<Packet>, Option<usize>) {
        match pk.channel {
            0 => (self.toc.handle(PORT_PARAM, &pk.data, &[]), None),
            1 => (self.read(&pk.data), None),
            2 => self.write(&pk.data),
            _ => (self.misc(&pk.data), None),
        }
    }

    fn read(&self, data: &[u8]) -> Option<Packet> {
        let id = crtp::u16_at(data, 0)?;
        let mut out = id.to_le_bytes().to_vec();
        match PARAMS.get(usize::from(id)).zip(self.values.get(usize::from(id))) {
            Some((def, v)) => {
                out.push(0);
                out.extend_from_slice(&encode(*v, def.2));
            }
            None => out.push(ENOENT),
        }
        Some(Packet::new(PORT_PARAM, 1, out))
    }

    fn write(&mut self, data: &[u8]) -> (Option<Packet>, Option<usize>) {
        let Some(id) = crtp::u16_at(data, 0) else { return (None, None) };
        let i = usize::from(id);
        let Some(&(_, _, type_byte, _)) = PARAMS.get(i) else {
            let mut out = id.to_le_bytes().to_vec();
            out.push(ENOENT);
            return (Some(Packet::new(PORT_PARAM, 2, out)), None);
        };
        // Read-only params are silently ignored, as in the firmware.
        if type_byte & RONLY != 0 {
            return (None, None);
        }
        let Some(value) = data.get(2..).and_then(|b| decode(b, type_byte)) else {
            return (None, None);
        };
        if let Some(slot) = self.values.get_mut(i) {
            *slot = value;
        }
        // The firmware echoes the request as the acknowledgement.
        (Some(Packet::new(PORT_PARAM, 2, data.to_vec())), Some(i))
    }

    fn misc(&self, data: &[u8]) -> Option<Packet> {
        let cmd = crtp::u8_at(data, 0)?;
        let id = crtp::u16_at(data, 1)?;
        let mut out = vec![cmd];
        out.extend_from_slice(&id.to_le_bytes());
        let def = PARAMS.get(usize::from(id));
        match cmd {
            // No param has extended type information.
            MISC_GET_EXTENDED_TYPE_V2 => out.push(ENOENT),
            MISC_GET_DEFAULT_VALUE_V2 => match def {
                Some(&(_, _, t, default)) if t & RONLY == 0 => {
                    out.push(0);
                    out.extend_from_slice(&encode(default, t));
                }
                _ => out.push(ENOENT),
            },
            _ => return None,
        }
        Some(Packet::new(PORT_PARAM, 3, out))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ask(p: &mut Params, channel: u8, data: &[u8]) -> Option<Vec<u8>> {
        p.handle(&Packet::new(PORT_PARAM, channel, data.to_vec())).0.map(|pk| pk.data)
    }

    #[test]
    fn read_write_echo_and_errors() {
        let mut p = Params::new();
        let ext = p.toc().find("locSrv", "extPosStdDev").expect("exists") as u16;
        let mut req = ext.to_le_bytes().to_vec();
        assert_eq!(
            ask(&mut p, 1, &req).expect("read")[2..],
            [[0u8].as_slice(), &0.01f32.to_le_bytes()].concat()
        );
        req.extend_from_slice(&0.5f32.to_le_bytes());
        assert_eq!(ask(&mut p, 2, &req), Some(req.clone()));
        assert_eq!(p.get("locSrv", "extPosStdDev"), Some(0.5));
        assert_eq!(ask(&mut p, 1, &[99, 0]), Some(vec![99, 0, ENOENT]));
        assert_eq!(ask(&mut p, 2, &[99, 0, 1]), Some(vec![99, 0, ENOENT]));
        let ro = p.toc().find("firmware", "revision0").expect("exists") as u16;
        let mut w = ro.to_le_bytes().to_vec();
        w.extend_from_slice(&[1, 2, 3, 4]);
        assert_eq!(ask(&mut p, 2, &w), None);
        assert_eq!(ask(&mut p, 2, &[0, 0]), None, "no value bytes");
        assert_eq!(ask(&mut p, 1, &[0]), None);
        assert_eq!(ask(&mut p, 3, &[8, 0, 0]), Some(vec![8, 0, 0, 0, 1]));
        assert_eq!(ask(&mut p, 3, &[7, 0, 0]), Some(vec![7, 0, 0, ENOENT]));
        assert_eq!(ask(&mut p, 3, &[]), None);
    }

    #[test]
    fn value_codecs() {
        assert_eq!(decode(&[0xff], 0x00), Some(-1.0));
        assert_eq!(decode(&[0xff], UINT8), Some(255.0));
        assert_eq!(decode(&[0xfe, 0xff, 0xff, 0xff], 0x02), Some(-2.0));
        assert_eq!(decode(&[1, 2], UINT32), None);
        assert_eq!(encode(300.0, UINT8), vec![44]);
        assert_eq!(decode(&encode(0.25, FLOAT), FLOAT), Some(0.25));
    }
}
