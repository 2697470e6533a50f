//! The payload a region publishes every tick (docs/regions.md): little-endian, a header
//! then one record per UAV. A record is the binary stream's 40-byte record (`airroads::serve::binary`)
//! with its roster index replaced by the UAV's id (a region's receivers have no roster): `u16` id
//! length, the id (UTF-8), then `f32` p, v, u and target (x, y each), `u8` status (the stream's
//! codes), `u8` flags (1 arrived, 2 lost, 4 ghost), `u16` unheard: how long before the message's
//! tick the state was last heard (ms, saturating; 0 for a fresh state). A lost UAV's record has the
//! time since its link last spoke; a *ghost* is a UAV this region released (or is releasing) and
//! commands no more, listed until its new owner lists it, with the time since it left.
//!
//! Decoding never panics: truncated, oversized or garbage input, an unknown version or kind, ids or
//! a region name that are not valid, and positions or velocities that are not finite are errors.

use engine::snapshot::Snapshot;
use engine::snapshot::{UAV_ARRIVED, UAV_LOST, status_code};
use thiserror::Error;
use uav::UavState;

/// A record's flag: a ghost (released by the sender, not commanded by it).
pub const UAV_GHOST: u8 = 4;

/// The format's version, the first byte.
pub const WIRE_VERSION: u8 = 1;
/// The second byte: a region's states (the binary stream's kinds are 1 to 3).
pub const KIND_REGION_STATES: u8 = 4;
/// Bytes of the header before the region's name.
pub const HEADER_BYTES: usize = 28;
/// Bytes of a record after its id.
pub const RECORD_TAIL_BYTES: usize = 36;
/// Longest id or region name accepted (bytes).
pub const MAX_NAME_BYTES: usize = 256;

/// One UAV of a region's message.
#[derive(Debug, Clone, PartialEq)]
pub struct WireUav {
    /// Its id.
    pub id: String,
    /// Position (m), finite.
    pub p: [f32; 2],
    /// Velocity (m/s), finite.
    pub v: [f32; 2],
    /// Filtered input sent to it (m/s²).
    pub u: [f32; 2],
    /// Temporary target (m).
    pub target: [f32; 2],
    /// Status code (docs/streams.md, Binary stream).
    pub status: u8,
    /// 1 arrived, 2 lost, 4 ghost.
    pub flags: u8,
    /// How long before the message's tick its state was last heard (ms).
    pub unheard_ms: u16,
}

impl WireUav {
    /// A ghost: released by its sender, who no longer commands it.
    pub fn ghost(&self) -> bool {
        self.flags & UAV_GHOST != 0
    }
}

/// What a region adds to its snapshot's records: how long each silent UAV has not been heard from,
/// and its ghosts.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Unheard {
    /// (index in the snapshot, ms since its state was last heard), by increasing index.
    pub silent: Vec<(u32, u16)>,
    /// Released UAVs whose new owner does not list them yet: id, last state, ms since they left.
    pub ghosts: Vec<(String, UavState, u16)>,
}

/// Milliseconds in `seconds`, saturating at `u16::MAX` (a negative or NaN time is 0).
pub fn saturating_ms(seconds: f64) -> u16 {
    (seconds * 1000.0).clamp(0.0, f64::from(u16::MAX)) as u16
}

/// A region's states at one of its ticks.
#[derive(Debug, Clone, PartialEq)]
pub struct RegionStates {
    /// The region's name.
    pub region: String,
    /// Its tick.
    pub tick: u64,
    /// Its fleet time (s, its own clock).
    pub time: f64,
    /// How long before sending the states were read (s, measured on the sender's clock).
    pub age_at_send_s: f32,
    /// Its UAVs.
    pub uavs: Vec<WireUav>,
}

/// Why a payload was refused.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum WireError {
    /// Fewer bytes than the header or a record needs.
    #[error("truncated: {0}")]
    Truncated(&'static str),
    /// A first byte other than [`WIRE_VERSION`].
    #[error("format version {0}, expected {WIRE_VERSION}")]
    Version(u8),
    /// A second byte other than [`KIND_REGION_STATES`].
    #[error("kind {0}, expected {KIND_REGION_STATES}")]
    Kind(u8),
    /// An empty, too long or non-UTF-8 id or region name.
    #[error("invalid {0}")]
    Name(&'static str),
    /// A record whose position or velocity is not finite.
    #[error("UAV `{0}`: position or velocity not finite")]
    NotFinite(String),
    /// A sending age that is negative or not finite.
    #[error("invalid age at sending")]
    Age,
    /// Bytes after the last record.
    #[error("{0} bytes after the last record")]
    Trailing(usize),
}

/// The payload of `snapshot` from `region`, its states read `age_at_send_s` before now, with the
/// silent UAVs' ages and the ghosts of `unheard`.
pub fn encode(region: &str, snapshot: &Snapshot, age_at_send_s: f32, unheard: &Unheard) -> Vec<u8> {
    let uavs = &snapshot.uavs;
    let count = uavs.len() + unheard.ghosts.len();
    let mut out = Vec::with_capacity(HEADER_BYTES + region.len() + count * (RECORD_TAIL_BYTES + 16));
    let name = &region.as_bytes()[..region.len().min(MAX_NAME_BYTES)];
    out.extend_from_slice(&[WIRE_VERSION, KIND_REGION_STATES]);
    out.extend_from_slice(&(name.len() as u16).to_le_bytes());
    out.extend_from_slice(&(u32::try_from(count).unwrap_or(u32::MAX)).to_le_bytes());
    out.extend_from_slice(&snapshot.tick.to_le_bytes());
    out.extend_from_slice(&snapshot.time.to_le_bytes());
    out.extend_from_slice(&age_at_send_s.to_le_bytes());
    out.extend_from_slice(name);
    let mut silent = unheard.silent.iter().peekable();
    for (k, u) in uavs.iter().enumerate() {
        let unheard_ms = silent.next_if(|(i, _)| *i as usize == k).map_or(0, |(_, ms)| *ms);
        let flags = if u.arrived { UAV_ARRIVED } else { 0 } | if u.lost { UAV_LOST } else { 0 };
        let tail = [status_code(u.status), flags];
        put_record(&mut out, &u.id, [u.p, u.v, u.u, u.target], tail, unheard_ms);
    }
    for (id, state, unheard_ms) in &unheard.ghosts {
        let (p, v) = ([state.p.x, state.p.y], [state.v.x, state.v.y]);
        put_record(&mut out, id, [p, v, [0.0; 2], p], [0, UAV_GHOST | UAV_LOST], *unheard_ms);
    }
    out
}

/// Appends one record: id, the four vectors, status and flags, unheard time.
fn put_record(out: &mut Vec<u8>, id: &str, vectors: [[f64; 2]; 4], status_flags: [u8; 2], unheard_ms: u16) {
    let id = &id.as_bytes()[..id.len().min(MAX_NAME_BYTES)];
    out.extend_from_slice(&(id.len() as u16).to_le_bytes());
    out.extend_from_slice(id);
    for x in vectors.iter().flatten() {
        out.extend_from_slice(&(*x as f32).to_le_bytes());
    }
    out.extend_from_slice(&status_flags);
    out.extend_from_slice(&unheard_ms.to_le_bytes());
}

/// Reads little-endian fields from the front of a byte slice.
struct Reader<'a>(&'a [u8]);

impl<'a> Reader<'a> {
    fn take(&mut self, n: usize, what: &'static str) -> Result<&'a [u8], WireError> {
        let (head, rest) = self.0.split_at_checked(n).ok_or(WireError::Truncated(what))?;
        self.0 = rest;
        Ok(head)
    }

    fn array<const N: usize>(&mut self, what: &'static str) -> Result<[u8; N], WireError> {
        let bytes = self.take(N, what)?;
        let mut out = [0; N];
        out.copy_from_slice(bytes);
        Ok(out)
    }

    fn f32_pair(&mut self, what: &'static str) -> Result<[f32; 2], WireError> {
        let b = self.array::<8>(what)?;
        let x = f32::from_le_bytes([b[0], b[1], b[2], b[3]]);
        Ok([x, f32::from_le_bytes([b[4], b[5], b[6], b[7]])])
    }

    fn name(&mut self, len: usize, what: &'static str) -> Result<String, WireError> {
        if len == 0 || len > MAX_NAME_BYTES {
            return Err(WireError::Name(what));
        }
        let bytes = self.take(len, what)?;
        std::str::from_utf8(bytes).map(str::to_owned).map_err(|_| WireError::Name(what))
    }
}

/// Decodes a payload (see the module doc for what is refused).
pub fn decode(bytes: &[u8]) -> Result<RegionStates, WireError> {
    let mut r = Reader(bytes);
    let [version, kind] = r.array::<2>("header")?;
    if version != WIRE_VERSION {
        return Err(WireError::Version(version));
    }
    if kind != KIND_REGION_STATES {
        return Err(WireError::Kind(kind));
    }
    let name_len = usize::from(u16::from_le_bytes(r.array::<2>("header")?));
    let count = u32::from_le_bytes(r.array::<4>("header")?) as usize;
    let tick = u64::from_le_bytes(r.array::<8>("header")?);
    let time = f64::from_le_bytes(r.array::<8>("header")?);
    let age_at_send_s = f32::from_le_bytes(r.array::<4>("header")?);
    if !(age_at_send_s.is_finite() && age_at_send_s >= 0.0) {
        return Err(WireError::Age);
    }
    let region = r.name(name_len, "region name")?;
    // Each record takes at least 2 + 1 + 36 bytes: a count beyond what is left is a truncation,
    // refused before allocating for it.
    if count > r.0.len() / (3 + RECORD_TAIL_BYTES) {
        return Err(WireError::Truncated("records"));
    }
    let mut uavs = Vec::with_capacity(count);
    for _ in 0..count {
        let id_len = usize::from(u16::from_le_bytes(r.array::<2>("record")?));
        let id = r.name(id_len, "UAV id")?;
        let (p, v) = (r.f32_pair("record")?, r.f32_pair("record")?);
        let (u, target) = (r.f32_pair("record")?, r.f32_pair("record")?);
        let [status, flags, ms0, ms1] = r.array::<4>("record")?;
        if !p.iter().chain(&v).all(|x| x.is_finite()) {
            return Err(WireError::NotFinite(id));
        }
        let unheard_ms = u16::from_le_bytes([ms0, ms1]);
        uavs.push(WireUav { id, p, v, u, target, status, flags, unheard_ms });
    }
    if !r.0.is_empty() {
        return Err(WireError::Trailing(r.0.len()));
    }
    Ok(RegionStates { region, tick, time, age_at_send_s, uavs })
}

#[cfg(test)]
#[path = "wire_tests.rs"]
mod tests;
