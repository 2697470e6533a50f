//! Motion-capture ingestion (`--mocap ADDR`): UDP datagrams, each one JSON object
//! `{"id": "cf1", "t": 12.345, "p": [x, y, z]}` (id of the UAV, the capture time in seconds, the
//! position in metres in the road's frame). A bridge for Vicon, OptiTrack or NOKOV sends one
//! datagram per rigid body and frame. Each pose is forwarded to its Crazyflie as an external
//! position, which the onboard estimator fuses (as Crazyswarm does); the fleet then reads the fused
//! estimate from the Crazyflie's log block. Bad datagrams are counted and dropped.

use super::linking::MocapRoutes;
use serde::{Deserialize, Serialize};
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering::Relaxed};
use tokio::net::UdpSocket;

/// One motion-capture pose.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Pose {
    /// The UAV's id.
    pub id: String,
    /// Capture time (s), as the bridge's clock says.
    pub t: f64,
    /// Position [x, y, z] (m).
    pub p: [f64; 3],
}

/// What the ingestion has seen (`mocap` in `GET /api/metrics`).
#[derive(Debug, Default)]
pub struct MocapCounters {
    /// True once `--mocap` is listening.
    pub listening: std::sync::atomic::AtomicBool,
    /// Poses forwarded to a Crazyflie.
    pub forwarded: AtomicU64,
    /// Poses for an id without a Crazyflie link (or whose queue was full).
    pub unrouted: AtomicU64,
    /// Datagrams that were not a valid pose.
    pub invalid: AtomicU64,
    /// Datagrams from a sender that is not allowed (dropped unread).
    pub rejected_sender: AtomicU64,
}

impl MocapCounters {
    /// The counters as `GET /api/metrics` shows them.
    pub fn report(&self) -> MocapReport {
        MocapReport {
            listening: self.listening.load(Relaxed),
            forwarded: self.forwarded.load(Relaxed),
            unrouted: self.unrouted.load(Relaxed),
            invalid: self.invalid.load(Relaxed),
            rejected_sender: self.rejected_sender.load(Relaxed),
        }
    }
}

/// `mocap` of `GET /api/metrics`: [`MocapCounters`] read once.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, schemars::JsonSchema)]
pub struct MocapReport {
    /// A motion-capture socket is open (`--mocap`).
    pub listening: bool,
    /// Poses forwarded to a Crazyflie.
    pub forwarded: u64,
    /// Poses for no Crazyflie of the fleet.
    pub unrouted: u64,
    /// Datagrams that were not a valid pose.
    pub invalid: u64,
    /// Datagrams from a sender that is not allowed.
    pub rejected_sender: u64,
}

/// True when `sender` may send poses: a loopback address, or one of `allowed` (`--mocap-allow`).
pub fn sender_allowed(sender: std::net::IpAddr, allowed: &[std::net::IpAddr]) -> bool {
    sender.is_loopback() || allowed.contains(&sender)
}

/// Parses one datagram; positions must be finite and within roads' coordinate range.
pub fn parse(datagram: &[u8]) -> Result<Pose, String> {
    let pose: Pose = serde_json::from_slice(datagram).map_err(|e| e.to_string())?;
    let limit = roads::MAX_COORDINATE_M;
    if !pose.t.is_finite() || !pose.p.iter().all(|c| c.is_finite() && c.abs() <= limit) {
        return Err("t and p must be finite, p within ±1e6 m".into());
    }
    Ok(pose)
}

/// Receives poses on `socket` until it fails, forwarding each to its Crazyflie; datagrams from
/// senders other than loopback and `allowed` are dropped unread.
pub async fn ingest(
    socket: UdpSocket,
    routes: MocapRoutes,
    counters: Arc<MocapCounters>,
    allowed: Vec<std::net::IpAddr>,
) {
    let mut buf = vec![0u8; 2048];
    counters.listening.store(true, Relaxed);
    loop {
        let n = match socket.recv_from(&mut buf).await {
            Ok((_, from)) if !sender_allowed(from.ip(), &allowed) => {
                counters.rejected_sender.fetch_add(1, Relaxed);
                continue;
            }
            Ok((n, _)) => n,
            Err(e) => {
                tracing::error!("motion capture socket failed: {e}");
                counters.listening.store(false, Relaxed);
                return;
            }
        };
        match parse(&buf[..n]) {
            Ok(pose) => {
                let p = pose.p.map(|c| c as f32);
                let counter =
                    if routes.forward(&pose.id, p) { &counters.forwarded } else { &counters.unrouted };
                counter.fetch_add(1, Relaxed);
            }
            Err(_) => {
                counters.invalid.fetch_add(1, Relaxed);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn poses_parse_and_bad_ones_are_refused() {
        let pose = parse(br#"{"id": "cf1", "t": 1.5, "p": [1, 2, 1.0]}"#).unwrap();
        assert_eq!(pose, Pose { id: "cf1".into(), t: 1.5, p: [1.0, 2.0, 1.0] });
        for bad in [
            &b"not json"[..],
            br#"{"id": "cf1", "t": 1, "p": [1, 2]}"#,
            br#"{"id": "cf1", "t": 1, "p": [1, 2, 1e9]}"#,
            br#"{"id": "cf1", "t": 1, "p": [1, 2, 3], "q": 0}"#,
            br#"{"id": "cf1", "p": [1, 2, 3]}"#,
            b"",
        ] {
            assert!(parse(bad).is_err(), "{}", String::from_utf8_lossy(bad));
        }
    }

    #[test]
    fn only_loopback_and_listed_senders_may_send_poses() {
        let lab: std::net::IpAddr = "192.168.1.7".parse().unwrap();
        assert!(sender_allowed("127.0.0.1".parse().unwrap(), &[]));
        assert!(sender_allowed("::1".parse().unwrap(), &[]));
        assert!(!sender_allowed(lab, &[]));
        assert!(sender_allowed(lab, &[lab]));
        assert!(!sender_allowed("192.168.1.8".parse().unwrap(), &[lab]));
    }
}
