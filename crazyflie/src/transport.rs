//! Opening a CRTP connection from a URI: `radio://…` and `usb://…` through crazyflie-link's
//! [`crazyflie_link::LinkContext`] (a Crazyradio or USB cable), `udp://HOST:PORT` through
//! [`crate::udp::UdpConnection`] (CrazySim, cflib's UDP driver, `cfsim`).

use crate::udp::UdpConnection;
use crazyflie_link::Connection;
use std::time::Duration;

/// A UDP peer that does not answer the connect datagram within this time is not there (a simulator
/// answers in microseconds; waiting longer only delays the next attempt).
pub const UDP_ANSWER_TIMEOUT: Duration = Duration::from_millis(500);

/// A URI that cannot be opened.
#[derive(Debug, thiserror::Error)]
pub enum TransportError {
    /// Not a `radio://`, `usb://` or `udp://` URI.
    #[error("unsupported link URI `{0}` (expected radio://…, usb://… or udp://HOST:PORT)")]
    Unsupported(String),
    /// The Crazyradio/USB link failed.
    #[error("{uri}: {source}")]
    Radio {
        /// The URI.
        uri: String,
        /// What crazyflie-link said.
        source: crazyflie_link::Error,
    },
    /// The UDP link failed.
    #[error("{uri}: {reason}")]
    Udp {
        /// The URI.
        uri: String,
        /// What went wrong.
        reason: String,
    },
}

/// Checks that `uri` names a transport this relay can open (without opening it).
pub fn check_uri(uri: &str) -> Result<(), TransportError> {
    if ["radio://", "usb://", "udp://"].iter().any(|s| uri.starts_with(s)) {
        Ok(())
    } else {
        Err(TransportError::Unsupported(uri.into()))
    }
}

/// Opens a CRTP connection to `uri`.
pub async fn open(uri: &str) -> Result<Connection, TransportError> {
    check_uri(uri)?;
    if uri.starts_with("udp://") {
        let udp = UdpConnection::open(uri)
            .await
            .map_err(|e| TransportError::Udp { uri: uri.into(), reason: e.to_string() })?;
        if !udp.wait_connected(UDP_ANSWER_TIMEOUT).await {
            let reason = format!("no answer within {} ms", UDP_ANSWER_TIMEOUT.as_millis());
            return Err(TransportError::Udp { uri: uri.into(), reason });
        }
        return Ok(Connection::new(Box::new(udp)));
    }
    // The Crazyradio context lives only for this attempt; its USB scan runs inside this task.
    let context = crazyflie_link::LinkContext::new();
    context.open_link(uri).await.map_err(|source| TransportError::Radio { uri: uri.into(), source })
}
