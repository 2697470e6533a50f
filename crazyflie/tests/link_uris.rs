//! Every link name `links::check_link` accepts is one the relay's transports parse: UDP URIs give
//! `crazyflie::udp::parse_uri` the same host and port, and radio URIs get past crazyflie-link's own
//! URI parser (opening then fails only for want of a Crazyradio). Its refusals are refused too.
//! (`usb://SERIAL` cannot be told apart this way: crazyflie-link answers `InvalidUri` both for a
//! malformed URI and for a serial number no connected Crazyflie has.)

use crazyflie_link::Error;
use crazyflie_link::crazyradio::Error as RadioError;
use links::uri::UdpHost;
use links::{LinkRules, LinkUri, parse_link};
use std::net::IpAddr;

#[test]
fn accepted_udp_links_give_the_relay_the_same_host_and_port() {
    let rules = LinkRules { udp_hosts: vec!["192.168.1.20".parse().unwrap(), "fd00::20".parse().unwrap()] };
    for link in [
        "udp://127.0.0.1:19850",
        "udp://127.255.0.9:1",
        "udp://localhost:65535",
        "udp://[::1]:19851",
        "udp://[::ffff:127.0.0.1]:19852",
        "udp://192.168.1.20:5005",
        "udp://[fd00::20]:5005",
    ] {
        let Ok(LinkUri::Udp { host, port }) = parse_link(link, &rules) else { panic!("{link} is accepted") };
        let (relay_host, relay_port) = crazyflie::udp::parse_uri(link).expect(link);
        assert_eq!(relay_port, port, "{link}");
        match host {
            UdpHost::Localhost => assert_eq!(relay_host, "localhost"),
            UdpHost::Ip(ip) => assert_eq!(relay_host.parse::<IpAddr>().expect(link), ip, "{link}"),
        }
    }
}

/// crazyflie-link's answer when it could not parse a radio URI.
fn parse_error(e: &Error) -> bool {
    matches!(
        e,
        Error::InvalidUri | Error::InvalidUriScheme | Error::CrazyradioError(RadioError::InvalidArgument)
    )
}

/// Opens `link` with crazyflie-link in its own task: `Ok` when it got past the URI parser (the radio
/// then opened, failed, or panicked for want of a USB context, as in a container without
/// `/dev/bus/usb`), `Err` with the parser's error otherwise.
async fn open(link: &'static str) -> Result<(), Error> {
    let task =
        tokio::spawn(async move { crazyflie_link::LinkContext::new().open_link(link).await.map(drop) });
    match task.await {
        Ok(Err(e)) if parse_error(&e) => Err(e),
        Ok(_) => Ok(()),
        Err(join) => {
            assert!(join.is_panic(), "{link}: {join}");
            Ok(())
        }
    }
}

#[tokio::test]
async fn accepted_radio_links_pass_crazyflie_links_parser() {
    let accepted = [
        "radio://0/80/2M/E7E7E7E7E7",
        "radio://0/0/250K/e7e7e7e7e7",
        "radio://3/125/1M/0123456789",
        "radio://255/80/2M/ABCDEFabcd?safelink=0&ackfilter=1&timeout=250",
        "radio://0/80/2M/E7E7E7E7E7?timeout=60000",
    ];
    // The control: what crazyflie-link cannot parse, the links parser refuses.
    let refused = ["radio://0/126/2M/E7E7E7E7E7", "radio://0/80/2M", "radio://x/80/2M/E7E7E7E7E7"];
    // Without a USB context the radio's own thread panics; keep that out of the test's output.
    let hook = std::panic::take_hook();
    std::panic::set_hook(Box::new(|_| {}));
    let mut opened = Vec::new();
    for link in accepted.into_iter().chain(refused) {
        opened.push((link, open(link).await));
    }
    std::panic::set_hook(hook);
    for (link, result) in opened {
        let accept = links::check_link(link).is_ok();
        assert_eq!(accept, accepted.contains(&link), "{link}");
        assert_eq!(result.is_ok(), accept, "{link}: crazyflie-link says {result:?}");
    }
}
