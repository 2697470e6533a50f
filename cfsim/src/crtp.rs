//! CRTP packets: the header byte (`pppp xx cc`) and little-endian payload readers.
//!
//! Every reader returns `None` on a short payload, so a malformed packet can never panic.

/// Console port (text printed by the firmware).
pub const PORT_CONSOLE: u8 = 0;
/// Parameter port.
pub const PORT_PARAM: u8 = 2;
/// Legacy commander port (roll/pitch/yawrate/thrust).
pub const PORT_COMMANDER: u8 = 3;
/// Memory port.
pub const PORT_MEMORY: u8 = 4;
/// Log port.
pub const PORT_LOG: u8 = 5;
/// Localization port (external position, emergency stop).
pub const PORT_LOCALIZATION: u8 = 6;
/// Generic setpoint port.
pub const PORT_SETPOINT_GENERIC: u8 = 7;
/// High-level commander port.
pub const PORT_HL_COMMANDER: u8 = 8;
/// Supervisor port.
pub const PORT_SUPERVISOR: u8 = 9;
/// Platform port (versions, app channel).
pub const PORT_PLATFORM: u8 = 13;
/// Link port (echo, source, sink, null packets).
pub const PORT_LINK: u8 = 15;

/// Largest CRTP payload (bytes after the header).
pub const MAX_PAYLOAD: usize = 30;

/// A CRTP packet: port, channel and payload (the header's two link-layer bits are dropped).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Packet {
    /// Port (0..=15).
    pub port: u8,
    /// Channel (0..=3).
    pub channel: u8,
    /// Payload, at most [`MAX_PAYLOAD`] bytes when built by the simulator.
    pub data: Vec<u8>,
}

impl Packet {
    /// A packet for `port`/`channel` with `data` as payload.
    pub fn new(port: u8, channel: u8, data: Vec<u8>) -> Self {
        Self { port: port & 0x0f, channel: channel & 0x03, data }
    }

    /// Decode one datagram; `None` if it is empty.
    pub fn parse(datagram: &[u8]) -> Option<Self> {
        let (&header, data) = datagram.split_first()?;
        Some(Self { port: header >> 4, channel: header & 0x03, data: data.to_vec() })
    }

    /// The header byte as the firmware sends it (link-layer bits clear).
    pub fn header(&self) -> u8 {
        (self.port << 4) | self.channel
    }

    /// Encode as one datagram: header then payload.
    pub fn to_datagram(&self) -> Vec<u8> {
        let mut out = Vec::with_capacity(1 + self.data.len());
        out.push(self.header());
        out.extend_from_slice(&self.data);
        out
    }

    /// True for a link-port null packet (port 15, channel 3), as sent for keep-alive.
    pub fn is_null(&self) -> bool {
        self.port == PORT_LINK && self.channel == 3
    }
}

/// The byte at `i`.
pub fn u8_at(data: &[u8], i: usize) -> Option<u8> {
    data.get(i).copied()
}

/// The little-endian `u16` at `i`.
pub fn u16_at(data: &[u8], i: usize) -> Option<u16> {
    Some(u16::from_le_bytes(data.get(i..i + 2)?.try_into().ok()?))
}

/// The little-endian `i16` at `i`.
pub fn i16_at(data: &[u8], i: usize) -> Option<i16> {
    Some(i16::from_le_bytes(data.get(i..i + 2)?.try_into().ok()?))
}

/// The little-endian `u32` at `i`.
pub fn u32_at(data: &[u8], i: usize) -> Option<u32> {
    Some(u32::from_le_bytes(data.get(i..i + 4)?.try_into().ok()?))
}

/// The little-endian `f32` at `i`.
pub fn f32_at(data: &[u8], i: usize) -> Option<f32> {
    Some(f32::from_le_bytes(data.get(i..i + 4)?.try_into().ok()?))
}

/// `n` consecutive little-endian `f32`s starting at `i`.
pub fn f32s_at<const N: usize>(data: &[u8], i: usize) -> Option<[f32; N]> {
    let mut out = [0.0; N];
    for (k, v) in out.iter_mut().enumerate() {
        *v = f32_at(data, i + 4 * k)?;
    }
    Some(out)
}

/// CRC-32 (IEEE 802.3, the polynomial of the firmware's `crc32CalculateBuffer`).
pub fn crc32(bytes: &[u8]) -> u32 {
    let mut crc = 0xffff_ffffu32;
    for &b in bytes {
        crc ^= u32::from(b);
        for _ in 0..8 {
            let mask = (crc & 1).wrapping_neg();
            crc = (crc >> 1) ^ (0xedb8_8320 & mask);
        }
    }
    !crc
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn header_round_trip_and_link_bits_ignored() {
        let p = Packet::parse(&[0x5d, 1, 2]).expect("non-empty");
        assert_eq!((p.port, p.channel, p.data.as_slice()), (5, 1, &[1u8, 2][..]));
        assert_eq!(p.header(), 0x51);
        assert_eq!(p.to_datagram(), vec![0x51, 1, 2]);
        assert!(Packet::parse(&[]).is_none());
        assert!(Packet::parse(&[0xff]).expect("one byte").is_null());
    }

    #[test]
    fn readers_refuse_short_input() {
        assert_eq!(u16_at(&[1], 0), None);
        assert_eq!(f32_at(&[0, 0, 0], 0), None);
        assert_eq!(u32_at(&[1, 0, 0, 0], 0), Some(1));
        assert_eq!(f32s_at::<2>(&1.5f32.to_le_bytes(), 0), None);
        assert_eq!(i16_at(&[0xff, 0xff], 0), Some(-1));
        assert_eq!(u8_at(&[], 3), None);
    }

    #[test]
    fn crc32_matches_reference() {
        assert_eq!(crc32(b"123456789"), 0xcbf4_3926);
    }
}
