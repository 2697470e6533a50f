//! Motion-capture ingestion (`--mocap ADDR`): UDP datagrams, each one JSON object
//! `{"id": "cf1", "t": 12.345, "p": [x, y, z]}` (id of the UAV, the capture time in seconds, the
//! position in metres in the road's frame). A bridge for Vicon, OptiTrack or NOKOV sends one
//! datagram per rigid body and frame. Each pose is forwarded to its Crazyflie as an external
//! position, which the onboard estimator fuses (as Crazyswarm does); the fleet then reads the fused
//! estimate from the Crazyflie's log block. Bad datagrams are counted and dropped.

use super::linking::MocapRoutes;
use serde::Deserialize;
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

/// What the ingestion has seen.
#[derive(Debug, Default)]
pub struct MocapCounters {
    /// Poses forwarded to a Crazyflie.
    pub forwarded: AtomicU64,
    /// Poses for an id without a Crazyflie link (or whose queue was full).
    pub unrouted: AtomicU64,
    /// Datagrams that were not a valid pose.
    pub invalid: AtomicU64,
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

/// Receives poses on `socket` until it fails, forwarding each to its Crazyflie.
pub async fn ingest(socket: UdpSocket, routes: MocapRoutes, counters: Arc<MocapCounters>) {
    let mut buf = vec![0u8; 2048];
    loop {
        let n = match socket.recv_from(&mut buf).await {
            Ok((n, _)) => n,
            Err(e) => {
                eprintln!("airroads: motion capture socket failed: {e}");
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
}
