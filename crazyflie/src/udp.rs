//! CRTP over UDP: one raw CRTP packet (header byte, then payload) per datagram, the convention
//! of CrazySim and cflib's UDP driver (`udp://HOST:PORT`, simulators on ports 19850 and up).
//!
//! [`UdpConnection`] implements [`crazyflie_link::ConnectionTrait`], so
//! `crazyflie_lib::Crazyflie::connect_from_link` runs over it unchanged:
//!
//! ```no_run
//! # async fn demo() -> Result<(), Box<dyn std::error::Error>> {
//! let link = crazyflie::udp::connect("udp://127.0.0.1:19850").await?;
//! let cf = crazyflie_lib::Crazyflie::connect_from_link(link, crazyflie_lib::NoTocCache).await?;
//! # let _ = cf; Ok(()) }
//! ```
//!
//! On open it sends the connect datagram `0xF3` and on close `0xF4` (CrazySim's cflib fork).
//! Like the radio, it sends a null packet (`0xFF`, port 15 channel 3) every keep-alive interval.
//! The real firmware does not answer null packets (over the radio the Crazyradio's acknowledgement
//! does; over UDP nothing does), so the link asks for an answer the firmware does give: a link echo
//! request (port 15, channel 0, [`ECHO_PROBE`] as payload) on open and whenever nothing has been
//! received for two keep-alive intervals. Silence therefore means the link is gone: when nothing
//! at all has been received for the link timeout the connection is declared disconnected, for good
//! (open a new one to reconnect). Null packets and the echoes of the probe are not passed to the
//! client.

use std::net::SocketAddr;
use std::sync::{Arc, Mutex, PoisonError};
use std::time::Duration;

use async_trait::async_trait;
use crazyflie_link::{ConnectionStatus, ConnectionTrait, Packet, RadioLinkStatistics};
use tokio::net::UdpSocket;
use tokio::sync::{mpsc, watch};
use tokio::time::Instant;

/// First datagram of a connection (CrazySim convention).
pub const CONNECT_DATAGRAM: u8 = 0xf3;
/// Last datagram of a connection (CrazySim convention).
pub const CLOSE_DATAGRAM: u8 = 0xf4;
/// The null packet sent as keep-alive (port 15, channel 3, link-layer bits set).
pub const NULL_PACKET: u8 = 0xff;
/// The header of a link echo request (port 15, channel 0): the firmware sends the packet back.
pub const ECHO_HEADER: u8 = 0xf0;
/// The payload of the link's own echo requests, told apart from a client's echoes by it.
pub const ECHO_PROBE: &[u8] = b"airroads-link-probe";

/// The echo request the link sends to get an answer from a firmware that ignores null packets.
fn probe_datagram() -> Vec<u8> {
    let mut datagram = vec![ECHO_HEADER];
    datagram.extend_from_slice(ECHO_PROBE);
    datagram
}

/// True for the echo of [`probe_datagram`] (any link-layer bits).
fn is_probe_echo(datagram: &[u8]) -> bool {
    datagram.first().is_some_and(|h| h & 0xf3 == ECHO_HEADER) && &datagram[1..] == ECHO_PROBE
}

/// Errors opening a UDP link.
#[derive(Debug, thiserror::Error)]
pub enum UdpError {
    /// The URI is not `udp://HOST:PORT`.
    #[error("invalid UDP URI {uri:?}: {reason}")]
    BadUri {
        /// The URI given.
        uri: String,
        /// What is wrong with it.
        reason: &'static str,
    },
    /// The host name did not resolve to any address.
    #[error("cannot resolve {0:?}")]
    Unresolved(String),
    /// A socket error.
    #[error("UDP socket error: {0}")]
    Io(#[from] std::io::Error),
}

/// Link timing.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct UdpConfig {
    /// Declare the link disconnected when nothing has been received for this long.
    pub link_timeout: Duration,
    /// Interval between keep-alive null packets.
    pub keepalive: Duration,
}

impl Default for UdpConfig {
    fn default() -> Self {
        Self { link_timeout: Duration::from_secs(1), keepalive: Duration::from_millis(100) }
    }
}

/// Parse `udp://HOST:PORT` into host and port.
pub fn parse_uri(uri: &str) -> Result<(String, u16), UdpError> {
    let bad = |reason| UdpError::BadUri { uri: uri.to_owned(), reason };
    let rest = uri.strip_prefix("udp://").ok_or_else(|| bad("scheme must be udp://"))?;
    let rest = rest.strip_suffix('/').unwrap_or(rest);
    let (host, port) = rest.rsplit_once(':').ok_or_else(|| bad("missing :PORT"))?;
    let host = host.strip_prefix('[').and_then(|h| h.strip_suffix(']')).unwrap_or(host);
    if host.is_empty() || host.contains(['/', '?', '#', '@']) {
        return Err(bad("bad host"));
    }
    let port: u16 = port.parse().map_err(|_| bad("bad port"))?;
    if port == 0 {
        return Err(bad("port 0"));
    }
    Ok((host.to_owned(), port))
}

/// Open a UDP link with the default timing, wrapped as a [`crazyflie_link::Connection`].
pub async fn connect(uri: &str) -> Result<crazyflie_link::Connection, UdpError> {
    let conn = UdpConnection::open(uri).await?;
    Ok(crazyflie_link::Connection::new(Box::new(conn)))
}

/// A CRTP link to a Crazyflie (simulated or bridged) over UDP.
pub struct UdpConnection {
    peer: SocketAddr,
    socket: Arc<UdpSocket>,
    status: Arc<Mutex<ConnectionStatus>>,
    downlink: tokio::sync::Mutex<mpsc::UnboundedReceiver<Packet>>,
    close: watch::Sender<bool>,
    done: watch::Receiver<bool>,
}

impl std::fmt::Debug for UdpConnection {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("UdpConnection").field("peer", &self.peer).finish_non_exhaustive()
    }
}

impl UdpConnection {
    /// Open `udp://HOST:PORT` with the default timing.
    pub async fn open(uri: &str) -> Result<Self, UdpError> {
        Self::open_with(uri, UdpConfig::default()).await
    }

    /// Open `udp://HOST:PORT` with the given timing. Returns once the socket is set up and the
    /// connect datagram sent; the status is `Connecting` until the first datagram arrives.
    pub async fn open_with(uri: &str, config: UdpConfig) -> Result<Self, UdpError> {
        let (host, port) = parse_uri(uri)?;
        let peer = tokio::net::lookup_host((host.as_str(), port))
            .await?
            .next()
            .ok_or_else(|| UdpError::Unresolved(host.clone()))?;
        let local: SocketAddr = if peer.is_ipv4() { ([0, 0, 0, 0], 0).into() } else { ([0u16; 8], 0).into() };
        let socket = Arc::new(UdpSocket::bind(local).await?);
        // Connected: only datagrams from the peer are received.
        socket.connect(peer).await?;
        socket.send(&[CONNECT_DATAGRAM]).await?;
        // Lossy like every later datagram: a refused one (ICMP from a port nobody listens on) is
        // silence, which the link timeout decides on.
        let _ = socket.send(&probe_datagram()).await;
        let status = Arc::new(Mutex::new(ConnectionStatus::Connecting));
        let (down_tx, down_rx) = mpsc::unbounded_channel();
        let (close_tx, close_rx) = watch::channel(false);
        let (done_tx, done_rx) = watch::channel(false);
        tokio::spawn(run(socket.clone(), config, status.clone(), down_tx, close_rx, done_tx));
        Ok(Self {
            peer,
            socket,
            status,
            downlink: tokio::sync::Mutex::new(down_rx),
            close: close_tx,
            done: done_rx,
        })
    }

    /// The peer address.
    pub fn peer(&self) -> SocketAddr {
        self.peer
    }

    /// The current status, without waiting.
    pub fn status_now(&self) -> ConnectionStatus {
        self.status.lock().unwrap_or_else(PoisonError::into_inner).clone()
    }

    /// Wait until the link is connected (first datagram received); `false` if it was
    /// disconnected or `timeout` passed first.
    pub async fn wait_connected(&self, timeout: Duration) -> bool {
        let deadline = Instant::now() + timeout;
        loop {
            match self.status_now() {
                ConnectionStatus::Connected => return true,
                ConnectionStatus::Disconnected(_) => return false,
                ConnectionStatus::Connecting => {}
            }
            if Instant::now() >= deadline {
                return false;
            }
            tokio::time::sleep(Duration::from_millis(5)).await;
        }
    }

    fn is_done(&self) -> bool {
        *self.done.borrow()
    }

    async fn wait_done(&self) {
        flag_set(&mut self.done.clone()).await;
    }
}

/// Resolves once the flag is set (or its sender is gone), without holding the borrow.
async fn flag_set(flag: &mut watch::Receiver<bool>) {
    let _ = flag.wait_for(|f| *f).await;
}

fn set_status(status: &Mutex<ConnectionStatus>, new: ConnectionStatus) {
    *status.lock().unwrap_or_else(PoisonError::into_inner) = new;
}

/// The connection task: receives datagrams, sends keep-alives, watches the link timeout.
async fn run(
    socket: Arc<UdpSocket>,
    config: UdpConfig,
    status: Arc<Mutex<ConnectionStatus>>,
    downlink: mpsc::UnboundedSender<Packet>,
    mut close: watch::Receiver<bool>,
    done: watch::Sender<bool>,
) {
    let mut buf = vec![0u8; 2048];
    let mut last_rx = Instant::now();
    let mut keepalive = tokio::time::interval(config.keepalive.max(Duration::from_millis(1)));
    keepalive.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    let reason = loop {
        tokio::select! {
            _ = flag_set(&mut close) => {
                let _ = socket.send(&[CLOSE_DATAGRAM]).await;
                break "Connection closed".to_owned();
            }
            r = socket.recv(&mut buf) => {
                // Errors (e.g. ICMP port unreachable while the peer is down) are transient;
                // the link timeout decides.
                let Ok(n) = r else { continue };
                if n == 0 {
                    continue;
                }
                last_rx = Instant::now();
                {
                    let mut s = status.lock().unwrap_or_else(PoisonError::into_inner);
                    if matches!(*s, ConnectionStatus::Connecting) {
                        *s = ConnectionStatus::Connected;
                    }
                }
                let header = buf[0];
                // Null packets (port 15, channel 3) carry no data: keep-alive answers. The probe's
                // echo is the link's own.
                if (header & 0xf3 == 0xf3 && n == 1) || is_probe_echo(&buf[..n]) {
                    continue;
                }
                // A receiver gone means the connection object was dropped.
                if downlink.send(Packet::from(buf[..n].to_vec())).is_err() {
                    break "Connection dropped".to_owned();
                }
            }
            _ = keepalive.tick() => {
                if last_rx.elapsed() > config.link_timeout {
                    break format!(
                        "Connection timeout: nothing received for {} ms",
                        config.link_timeout.as_millis()
                    );
                }
                let _ = socket.send(&[NULL_PACKET]).await;
                if last_rx.elapsed() >= 2 * config.keepalive {
                    let _ = socket.send(&probe_datagram()).await;
                }
            }
        }
    };
    set_status(&status, ConnectionStatus::Disconnected(reason));
    // Dropping the sender ends recv_packet; then tell the waiters.
    drop(downlink);
    done.send_replace(true);
}

#[async_trait]
impl ConnectionTrait for UdpConnection {
    async fn wait_close(&self) -> String {
        self.wait_done().await;
        match self.status_now() {
            ConnectionStatus::Disconnected(reason) => reason,
            _ => "Still connected!".to_owned(),
        }
    }

    async fn close(&self) {
        self.close.send_replace(true);
        self.wait_done().await;
    }

    async fn status(&self) -> ConnectionStatus {
        self.status_now()
    }

    async fn wait_disconnect(&self) {
        self.wait_done().await;
    }

    async fn send_packet(&self, packet: Packet) -> crazyflie_link::error::Result<()> {
        if self.is_done() {
            // The link is gone for good (crazyflie-link has no "closed" variant to report).
            return Err(crazyflie_link::Error::Timeout);
        }
        let datagram: Vec<u8> = packet.into();
        // UDP is lossy like the radio: a failed send is a lost packet, not a dead link.
        let _ = self.socket.send(&datagram).await;
        Ok(())
    }

    async fn recv_packet(&self) -> crazyflie_link::error::Result<Packet> {
        // Cancel-safe: crazyflie-lib polls this under a timeout.
        let mut rx = self.downlink.lock().await;
        rx.recv().await.ok_or(crazyflie_link::Error::Timeout)
    }

    async fn link_statistics(&self) -> Option<RadioLinkStatistics> {
        None
    }
}

impl Drop for UdpConnection {
    fn drop(&mut self) {
        self.close.send_replace(true);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn uri_parsing() {
        assert_eq!(parse_uri("udp://127.0.0.1:19850").ok(), Some(("127.0.0.1".into(), 19850)));
        assert_eq!(parse_uri("udp://localhost:19851/").ok(), Some(("localhost".into(), 19851)));
        assert_eq!(parse_uri("udp://[::1]:19850").ok(), Some(("::1".into(), 19850)));
        for bad in
            ["radio://0/80/2M", "udp://", "udp://host", "udp://:1", "udp://h:x", "udp://h:0", "udp://h:70000"]
        {
            assert!(matches!(parse_uri(bad), Err(UdpError::BadUri { .. })), "{bad}");
        }
    }

    #[tokio::test]
    async fn times_out_without_a_peer_and_ignores_garbage() {
        // A bound socket that never answers except with garbage.
        let peer = UdpSocket::bind("127.0.0.1:0").await.expect("bind");
        let uri = format!("udp://{}", peer.local_addr().expect("addr"));
        let config =
            UdpConfig { link_timeout: Duration::from_millis(200), keepalive: Duration::from_millis(20) };
        let conn = UdpConnection::open_with(&uri, config).await.expect("open");
        let mut buf = [0u8; 64];
        let (n, from) = peer.recv_from(&mut buf).await.expect("connect datagram");
        assert_eq!(&buf[..n], &[CONNECT_DATAGRAM]);
        peer.send_to(&[], from).await.expect("send");
        peer.send_to(&[0x51, 1, 2], from).await.expect("send");
        assert!(conn.wait_connected(Duration::from_secs(1)).await);
        let pk = conn.recv_packet().await.expect("packet");
        assert_eq!((pk.get_port(), pk.get_channel(), pk.get_data().as_slice()), (5, 1, &[1u8, 2][..]));
        let reason = tokio::time::timeout(Duration::from_secs(2), conn.wait_close()).await.expect("closes");
        assert!(reason.contains("timeout"), "{reason}");
        assert!(conn.recv_packet().await.is_err());
        assert!(conn.send_packet(Packet::new(0, 0, vec![])).await.is_err());
    }

    /// A peer that answers only echo requests and ignores null packets, as the real firmware
    /// does over UDP: the link connects and stays up on the echoes, which the client never sees.
    #[tokio::test]
    async fn stays_up_on_a_peer_that_answers_only_echoes() {
        let peer = UdpSocket::bind("127.0.0.1:0").await.expect("bind");
        let uri = format!("udp://{}", peer.local_addr().expect("addr"));
        let config =
            UdpConfig { link_timeout: Duration::from_millis(200), keepalive: Duration::from_millis(20) };
        let firmware = tokio::spawn(async move {
            let mut buf = [0u8; 64];
            let mut nulls = 0;
            loop {
                let (n, from) = peer.recv_from(&mut buf).await.expect("recv");
                match buf[0] {
                    NULL_PACKET if n == 1 => nulls += 1,
                    ECHO_HEADER => {
                        peer.send_to(&buf[..n], from).await.expect("echo");
                    }
                    // The client's own packet: answer it once, then stop.
                    0x51 => {
                        peer.send_to(&[0x51, 7], from).await.expect("send");
                        return nulls;
                    }
                    _ => {}
                }
            }
        });
        let conn = UdpConnection::open_with(&uri, config).await.expect("open");
        assert!(conn.wait_connected(Duration::from_millis(500)).await, "the echo of the probe connects");
        // Five link timeouts with nothing but echoes coming back.
        tokio::time::sleep(Duration::from_millis(1000)).await;
        assert!(matches!(conn.status_now(), ConnectionStatus::Connected));
        conn.send_packet(Packet::new(5, 1, vec![1])).await.expect("send");
        let pk = tokio::time::timeout(Duration::from_secs(1), conn.recv_packet())
            .await
            .expect("a packet")
            .expect("ok");
        assert_eq!((pk.get_port(), pk.get_data().as_slice()), (5, &[7u8][..]), "no echo reaches the client");
        assert!(firmware.await.expect("peer") > 10, "null packets are still sent");
    }
}
