//! Opening a CRTP connection from a URI: `radio://…` and `usb://…` through crazyflie-link's
//! [`crazyflie_link::LinkContext`] (a Crazyradio or USB cable), `udp://HOST:PORT` through
//! [`crate::udp::UdpConnection`] (CrazySim, cflib's UDP driver, `cfsim`).
//!
//! A radio or USB link on a host without USB devices (a container without `/dev/bus/usb`) used to
//! panic: crazyflie-link opens the Crazyradio through crazyradio, whose open thread calls
//! `rusb::devices()`, which panics when libusb cannot start (`Can't init Global usb context` in
//! rusb's `GlobalContext`); the thread's end then panics crazyradio's `open_nth_async` in the
//! caller. [`open`] therefore (1) checks the precondition first: a USB device node that libusb
//! would find ([`usb_devices_visible`]), else [`TransportError::Unavailable`] without calling the
//! library; (2) runs the library's open in its own task and turns a panic there into the same
//! error, remembering it for the process (rusb's global context never starts after a failed start;
//! every later call would panic again).

use crate::udp::UdpConnection;
use crazyflie_link::Connection;
use std::sync::OnceLock;
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
    /// Radio and USB links cannot be opened on this host (no USB devices visible, or the USB
    /// library failed to start).
    #[error("{uri}: {reason}")]
    Unavailable {
        /// The URI.
        uri: String,
        /// Why, for the operator.
        reason: String,
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
    open_usb(uri).await
}

/// Why the USB library failed in this process, once it panicked.
static USB_FAILED: OnceLock<String> = OnceLock::new();

/// True when a USB device node exists where libusb looks for them on Linux (`/dev/bus/usb/*`, or
/// `/dev/usbdev*`): without one, libusb cannot start (rusb then panics) and no Crazyradio could be
/// found anyway. Elsewhere than Linux, true (the library's own answer stands).
pub fn usb_devices_visible() -> bool {
    if !cfg!(target_os = "linux") {
        return true;
    }
    let has_entry = |dir: &str, prefix: &str| {
        std::fs::read_dir(dir).is_ok_and(|mut entries| {
            entries.any(|e| {
                e.is_ok_and(|e| {
                    let name = e.file_name();
                    let name = name.to_string_lossy();
                    !name.starts_with('.') && name.starts_with(prefix)
                })
            })
        })
    };
    has_entry("/dev/bus/usb", "") || has_entry("/dev", "usbdev")
}

/// Aborts the task of a handle when dropped (a timed-out open is not left running).
struct AbortOnDrop<T>(tokio::task::JoinHandle<T>);

impl<T> Drop for AbortOnDrop<T> {
    fn drop(&mut self) {
        self.0.abort();
    }
}

/// Opens a `radio://` or `usb://` link through crazyflie-link (see the module documentation).
async fn open_usb(uri: &str) -> Result<Connection, TransportError> {
    let unavailable = |reason: String| TransportError::Unavailable { uri: uri.into(), reason };
    if let Some(reason) = USB_FAILED.get() {
        return Err(unavailable(reason.clone()));
    }
    if !usb_devices_visible() {
        return Err(unavailable(
            "no USB device is visible on this host (/dev/bus/usb is missing or empty): plug a \
             Crazyradio in, or give the container the USB bus (--device /dev/bus/usb)"
                .into(),
        ));
    }
    // The Crazyradio context lives only for this attempt; its USB scan runs in a task of its own, so
    // a panic inside the library is caught here rather than ending the caller.
    let owned = uri.to_string();
    let mut task =
        AbortOnDrop(tokio::spawn(async move { crazyflie_link::LinkContext::new().open_link(&owned).await }));
    match (&mut task.0).await {
        Ok(opened) => opened.map_err(|source| TransportError::Radio { uri: uri.into(), source }),
        Err(e) if e.is_panic() => {
            let payload = e.into_panic();
            let message = payload
                .downcast_ref::<&str>()
                .map(|s| (*s).to_string())
                .or_else(|| payload.downcast_ref::<String>().cloned())
                .unwrap_or_else(|| "no message".into());
            let reason = format!("the USB library failed ({message}); restart the server once USB works");
            Err(unavailable(USB_FAILED.get_or_init(|| reason).clone()))
        }
        Err(e) => Err(unavailable(format!("the open was cancelled: {e}"))),
    }
}
