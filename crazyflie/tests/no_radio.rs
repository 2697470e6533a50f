//! A radio or USB link on a host without a Crazyradio (the development machine and CI containers
//! have no USB devices at all, where libusb cannot even start) reports why as the link's error,
//! keeps trying, and never panics, on any thread. (One test in this binary: the panic hook is the
//! process's.)

use crazyflie::{CrazyflieLink, RelayConfig};
use links::{Link, LinkPhase};
use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::{Duration, Instant};

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_radio_link_without_a_crazyradio_reports_an_error_and_never_panics() {
    // Every panic in this process is counted, the USB library's own threads included.
    let panics = Arc::new(AtomicUsize::new(0));
    let counted = panics.clone();
    let previous = std::panic::take_hook();
    std::panic::set_hook(Box::new(move |info| {
        counted.fetch_add(1, Ordering::SeqCst);
        previous(info);
    }));
    let config = RelayConfig { connect_timeout: 3.0, ..RelayConfig::default() };
    let runtime = tokio::runtime::Handle::current();
    let uris = ["radio://0/80/2M/E7E7E7E7E7", "usb://0123456789"];
    for uri in uris {
        assert!(links::check_link(uri).is_ok(), "{uri} is a link the server accepts");
    }
    let links: Vec<CrazyflieLink> =
        uris.iter().map(|uri| CrazyflieLink::spawn(&runtime, uri, config)).collect();
    let deadline = Instant::now() + Duration::from_secs(10);
    while links.iter().any(|l| l.error().is_none()) {
        assert!(Instant::now() < deadline, "no link error within 10 s");
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    // Several more attempts (retried after 0.1 s, then backing off): still no panic.
    tokio::time::sleep(Duration::from_millis(1500)).await;
    assert_eq!(panics.load(Ordering::SeqCst), 0, "a panic happened (see above)");
    for (link, uri) in links.iter().zip(uris) {
        let error = link.error().unwrap_or_default();
        assert!(error.starts_with(uri), "{uri}: {error}");
        if !crazyflie::transport::usb_devices_visible() {
            assert!(error.contains("no USB device"), "{uri}: {error}");
        }
        assert_eq!(link.phase(), LinkPhase::Connecting, "{uri}");
    }
}
