//! The ports that only answer: platform versions (port 13, channel 1), memory (port 4) and link
//! (port 15).

use crate::crtp::{self, PORT_LINK, PORT_MEMORY, PORT_PLATFORM, Packet};

/// CRTP protocol version reported on the platform port (crazyflie-lib 0.8 accepts 12..=13; cflib
/// uses the supervisor port from 12 on).
pub const PROTOCOL_VERSION: u8 = 12;
/// Device type name reported on the platform port.
pub const DEVICE_TYPE: &str = "Crazyflie 2.1";

/// Platform port, version channel (1): protocol version (0), firmware version (1), device type (2).
pub fn version(pk: &Packet, firmware_version: &str) -> Option<Packet> {
    let cmd = crtp::u8_at(&pk.data, 0)?;
    let mut d = vec![cmd];
    match cmd {
        0 => d.push(PROTOCOL_VERSION),
        1 => d.extend_from_slice(firmware_version.as_bytes()),
        2 => d.extend_from_slice(DEVICE_TYPE.as_bytes()),
        _ => return None,
    }
    d.truncate(crtp::MAX_PAYLOAD);
    Some(Packet::new(PORT_PLATFORM, 1, d))
}

/// Memory port: the simulator has no memories.
pub fn memory(pk: &Packet) -> Option<Packet> {
    match (pk.channel, crtp::u8_at(&pk.data, 0)?) {
        // CMD_INFO_VER, CMD_INFO_NBR.
        (0, 0) => Some(Packet::new(PORT_MEMORY, 0, vec![0, 1])),
        (0, 1) => Some(Packet::new(PORT_MEMORY, 0, vec![1, 0])),
        _ => None,
    }
}

/// Link port: echo (0), source (1), sink (2). Null packets (3) go unanswered, as on the real
/// firmware (over the radio the Crazyradio's acknowledgement answers them; over UDP nothing does),
/// unless `answer_null`: then an empty channel-3 packet (`0xF3`), the stand-in for that
/// acknowledgement (cflib's UDP scan relies on one).
pub fn link(pk: &Packet, answer_null: bool) -> Option<Packet> {
    match pk.channel {
        0 => Some(Packet::new(PORT_LINK, 0, pk.data.clone())),
        1 => {
            let mut d = b"Bitcraze Crazyflie".to_vec();
            d.resize(crtp::MAX_PAYLOAD, 0);
            Some(Packet::new(PORT_LINK, 1, d))
        }
        3 if answer_null => Some(Packet::new(PORT_LINK, 3, Vec::new())),
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pk(port: u8, ch: u8, d: &[u8]) -> Packet {
        Packet::new(port, ch, d.to_vec())
    }

    #[test]
    fn versions_memory_and_link() {
        assert_eq!(version(&pk(13, 1, &[0]), "v").map(|p| p.data), Some(vec![0, PROTOCOL_VERSION]));
        assert_eq!(version(&pk(13, 1, &[1]), "v").map(|p| p.data), Some(b"\x01v".to_vec()));
        assert_eq!(version(&pk(13, 1, &[2]), "v").map(|p| p.data), Some(b"\x02Crazyflie 2.1".to_vec()));
        assert!(version(&pk(13, 1, &[]), "v").is_none() && version(&pk(13, 1, &[3]), "v").is_none());
        let long = "x".repeat(40);
        assert_eq!(version(&pk(13, 1, &[1]), &long).map(|p| p.data.len()), Some(crtp::MAX_PAYLOAD));
        assert_eq!(memory(&pk(4, 0, &[1])).map(|p| p.data), Some(vec![1, 0]));
        assert!(memory(&pk(4, 1, &[0])).is_none());
        assert_eq!(link(&pk(15, 0, &[1, 2]), false).map(|p| p.data), Some(vec![1, 2]));
        let source = link(&pk(15, 1, &[0]), false).expect("source");
        assert!(source.data.starts_with(b"Bitcraze Crazyflie") && source.data.len() == crtp::MAX_PAYLOAD);
        assert!(link(&pk(15, 2, &[1, 2]), false).is_none());
        assert!(link(&pk(15, 3, &[]), false).is_none(), "the firmware ignores null packets");
        assert_eq!(link(&pk(15, 3, &[]), true).map(|p| p.to_datagram()), Some(vec![0xf3]));
    }
}
