//! Link names: every form the relay opens is accepted with its parts, everything else is refused
//! with a message naming the part at fault, and the parser never panics.

use links::uri::{RadioRate, RadioUri, UdpHost};
use links::{LinkRules, LinkUri, check_link, check_link_with, parse_link};
use proptest::prelude::*;
use std::net::{IpAddr, Ipv4Addr, Ipv6Addr};

fn refused(link: &str) -> String {
    check_link(link).expect_err(link)
}

#[test]
fn the_documented_forms_are_accepted() {
    let e7 = [0xe7; 5];
    let radio = |channel, rate| {
        LinkUri::Radio(RadioUri {
            device: 0,
            channel,
            rate,
            address: e7,
            safelink: None,
            ackfilter: None,
            timeout_ms: None,
        })
    };
    let rules = LinkRules::default();
    assert_eq!(parse_link("sim", &rules), Ok(LinkUri::Sim));
    assert_eq!(parse_link("radio://0/80/2M/E7E7E7E7E7", &rules), Ok(radio(80, RadioRate::Mbps2)));
    assert_eq!(parse_link("radio://0/0/250K/e7e7e7e7e7", &rules), Ok(radio(0, RadioRate::Kbps250)));
    assert_eq!(parse_link("radio://0/125/1M/E7E7e7e7E7", &rules), Ok(radio(125, RadioRate::Mbps1)));
    let flags = parse_link("radio://1/80/2M/0102030405?safelink=0&ackfilter=1&timeout=250", &rules);
    assert_eq!(
        flags,
        Ok(LinkUri::Radio(RadioUri {
            device: 1,
            channel: 80,
            rate: RadioRate::Mbps2,
            address: [1, 2, 3, 4, 5],
            safelink: Some(false),
            ackfilter: Some(true),
            timeout_ms: Some(250),
        }))
    );
    assert_eq!(parse_link("usb://206B35754E4B", &rules), Ok(LinkUri::Usb { serial: "206B35754E4B".into() }));
    let udp = |host, port| Ok(LinkUri::Udp { host, port });
    let v4 = |a, b, c, d| UdpHost::Ip(IpAddr::V4(Ipv4Addr::new(a, b, c, d)));
    assert_eq!(parse_link("udp://127.0.0.1:19850", &rules), udp(v4(127, 0, 0, 1), 19850));
    assert_eq!(parse_link("udp://127.1.2.3:1", &rules), udp(v4(127, 1, 2, 3), 1));
    assert_eq!(parse_link("udp://localhost:65535", &rules), udp(UdpHost::Localhost, 65535));
    assert_eq!(
        parse_link("udp://[::1]:19850", &rules),
        udp(UdpHost::Ip(IpAddr::V6(Ipv6Addr::LOCALHOST)), 19850)
    );
    let mapped = "udp://[::ffff:127.0.0.1]:19850";
    assert!(check_link(mapped).is_ok(), "an IPv4-mapped loopback address is loopback");
}

#[test]
fn each_refusal_names_what_is_wrong() {
    let cases = [
        ("udp://127.0.0.1:99999", "udp://127.0.0.1:99999: port 99999 is not in 1..=65535"),
        ("udp://127.0.0.1:0", "udp://127.0.0.1:0: port 0 is not in 1..=65535"),
        ("udp://127.0.0.1:019850", "udp://127.0.0.1:019850: port `019850` has a leading zero"),
        ("udp://127.0.0.1:", "udp://127.0.0.1:: port `` is not a number in 1..=65535"),
        ("udp://127.0.0.1:19850/", "udp://127.0.0.1:19850/: port `19850/` is not a number in 1..=65535"),
        ("udp://127.0.0.1", "udp://127.0.0.1: the port is missing (udp://HOST:PORT)"),
        (
            "udp://10.0.0.5:19850",
            "udp://10.0.0.5:19850: host 10.0.0.5 is not loopback, and no other UDP host is allowed",
        ),
        ("udp://0.0.0.0:19850", "udp://0.0.0.0:19850: host 0.0.0.0 is not a unicast address"),
        ("udp://[::]:19850", "udp://[::]:19850: host :: is not a unicast address"),
        ("udp://255.255.255.255:1", "udp://255.255.255.255:1: host 255.255.255.255 is not a unicast address"),
        ("udp://224.0.0.1:1", "udp://224.0.0.1:1: host 224.0.0.1 is not a unicast address"),
        (
            "udp://example.com:19850",
            "udp://example.com:19850: host `example.com` is not an IP address or localhost (host names are not resolved)",
        ),
        (
            "udp://::1:19850",
            "udp://::1:19850: host `::1`: an IPv6 address goes in brackets, udp://[::1]:PORT",
        ),
        ("udp://[::1:19850", "udp://[::1:19850: the IPv6 host has no closing `]` (udp://[ADDRESS]:PORT)"),
        ("udp://[fe80::1%eth0]:1", "udp://[fe80::1%eth0]:1: host `[fe80::1%eth0]` is not an IPv6 address"),
        (
            "udp://127.0.0.01:1",
            "udp://127.0.0.01:1: host `127.0.0.01` is not an IP address or localhost (host names are not resolved)",
        ),
        ("radio://0/126/2M/E7E7E7E7E7", "radio://0/126/2M/E7E7E7E7E7: channel 126 is not in 0..=125"),
        ("radio://0/080/2M/E7E7E7E7E7", "radio://0/080/2M/E7E7E7E7E7: channel `080` has a leading zero"),
        ("radio://0/+8/2M/E7E7E7E7E7", "radio://0/+8/2M/E7E7E7E7E7: channel `+8` is not a number in 0..=125"),
        ("radio://256/80/2M/E7E7E7E7E7", "radio://256/80/2M/E7E7E7E7E7: device 256 is not in 0..=255"),
        ("radio://0/80/3M/E7E7E7E7E7", "radio://0/80/3M/E7E7E7E7E7: rate `3M` is not 250K, 1M or 2M"),
        ("radio://0/80/2m/E7E7E7E7E7", "radio://0/80/2m/E7E7E7E7E7: rate `2m` is not 250K, 1M or 2M"),
        ("radio://0/80/2M/E7E7", "radio://0/80/2M/E7E7: address `E7E7` is not 10 hex digits"),
        (
            "radio://0/80/2M/E7E7E7E7G7",
            "radio://0/80/2M/E7E7E7E7G7: address `E7E7E7E7G7` is not 10 hex digits",
        ),
        (
            "radio://0/80/2M",
            "radio://0/80/2M: the address is missing: crazyflie-link 0.5 needs radio://DEV/CHANNEL/RATE/ADDRESS, e.g. radio://0/80/2M/E7E7E7E7E7",
        ),
        (
            "radio://0/80/2M/E7E7E7E7E7/",
            "radio://0/80/2M/E7E7E7E7E7/: has 5 path parts, expected 4: radio://DEV/CHANNEL/RATE/ADDRESS",
        ),
        (
            "radio://0/80/2M/E7E7E7E7E7?safelink=2",
            "radio://0/80/2M/E7E7E7E7E7?safelink=2: safelink=2: must be 0 or 1",
        ),
        (
            "radio://0/80/2M/E7E7E7E7E7?timeout=0",
            "radio://0/80/2M/E7E7E7E7E7?timeout=0: timeout (ms) 0 is not in 1..=60000",
        ),
        (
            "radio://0/80/2M/E7E7E7E7E7?safelink=0&safelink=1",
            "radio://0/80/2M/E7E7E7E7E7?safelink=0&safelink=1: flag `safelink` is given twice",
        ),
        (
            "radio://0/80/2M/E7E7E7E7E7?foo=1",
            "radio://0/80/2M/E7E7E7E7E7?foo=1: flag `foo` is not one of safelink=0|1, ackfilter=0|1 or timeout=MS",
        ),
        (
            "radio://0/80/2M/E7E7E7E7E7?",
            "radio://0/80/2M/E7E7E7E7E7?: flag `` is not KEY=VALUE (safelink=0|1, ackfilter=0|1 or timeout=MS)",
        ),
        (
            "usb://",
            "usb://: serial `` is not 1 to 64 letters and digits (usb://SERIAL, the USB serial number)",
        ),
        (
            "usb://0/",
            "usb://0/: serial `0/` is not 1 to 64 letters and digits (usb://SERIAL, the USB serial number)",
        ),
        (
            "",
            ": not `sim` or a Crazyflie URI (radio://DEV/CHANNEL/RATE/ADDRESS, usb://SERIAL, udp://HOST:PORT)",
        ),
        (
            "SIM",
            "SIM: not `sim` or a Crazyflie URI (radio://DEV/CHANNEL/RATE/ADDRESS, usb://SERIAL, udp://HOST:PORT)",
        ),
        (
            "RADIO://0/80/2M/E7E7E7E7E7",
            "RADIO://0/80/2M/E7E7E7E7E7: not `sim` or a Crazyflie URI (radio://DEV/CHANNEL/RATE/ADDRESS, usb://SERIAL, udp://HOST:PORT)",
        ),
        (
            "udp://127.0.0.1:1 ",
            "udp://127.0.0.1:1 : character ' ' at position 17 is not allowed (link names are printable ASCII, without spaces)",
        ),
        (
            "udp://127.0.0.1:1\u{202e}",
            "udp://127.0.0.1:1\\u{202e}: character '\\u{202e}' at position 17 is not allowed (link names are printable ASCII, without spaces)",
        ),
    ];
    for (link, message) in cases {
        assert_eq!(refused(link), message);
    }
    let long = format!("udp://127.0.0.1:1{}", "1".repeat(300));
    assert_eq!(refused(&long), format!("{}…: longer than 256 characters (317)", &long[..80]));
}

#[test]
fn rules_allow_listed_udp_hosts_only() {
    let rules = LinkRules { udp_hosts: vec!["10.0.0.5".parse().unwrap(), "fd00::7".parse().unwrap()] };
    assert_eq!(check_link_with("udp://10.0.0.5:19850", &rules), Ok(()));
    assert_eq!(check_link_with("udp://[fd00::7]:19850", &rules), Ok(()));
    assert_eq!(check_link_with("udp://[::ffff:10.0.0.5]:19850", &rules), Ok(()), "IPv4-mapped");
    assert_eq!(check_link_with("udp://127.0.0.1:19850", &rules), Ok(()), "loopback stays allowed");
    assert_eq!(
        check_link_with("udp://10.0.0.6:19850", &rules).unwrap_err(),
        "udp://10.0.0.6:19850: host 10.0.0.6 is neither loopback nor an allowed UDP host (10.0.0.5, fd00::7)"
    );
    assert!(check_link("udp://10.0.0.5:19850").is_err(), "the default allows loopback only");
    let any = LinkRules { udp_hosts: vec!["0.0.0.0".parse().unwrap()] };
    assert!(check_link_with("udp://0.0.0.0:1", &any).is_err(), "never a non-unicast address");
}

/// A valid link name and what it must parse to.
fn valid_link() -> impl Strategy<Value = (String, LinkUri)> {
    let hex = proptest::sample::select(b"0123456789abcdefABCDEF".to_vec());
    let radio = (
        0u8..=255,
        0u8..=125,
        prop_oneof![Just(RadioRate::Kbps250), Just(RadioRate::Mbps1), Just(RadioRate::Mbps2)],
        proptest::collection::vec(hex, 10),
        proptest::option::of(any::<bool>()),
        proptest::option::of(any::<bool>()),
        proptest::option::of(1u32..=60_000),
        any::<u8>(),
    )
        .prop_map(|(device, channel, rate, digits, safelink, ackfilter, timeout_ms, order)| {
            let address_text: String = digits.iter().map(|&b| b as char).collect();
            let mut address = [0u8; 5];
            for (k, a) in address.iter_mut().enumerate() {
                *a = u8::from_str_radix(&address_text[2 * k..2 * k + 2], 16).unwrap();
            }
            let rate_text = match rate {
                RadioRate::Kbps250 => "250K",
                RadioRate::Mbps1 => "1M",
                RadioRate::Mbps2 => "2M",
            };
            let mut flags: Vec<String> = [
                safelink.map(|b| format!("safelink={}", u8::from(b))),
                ackfilter.map(|b| format!("ackfilter={}", u8::from(b))),
                timeout_ms.map(|t| format!("timeout={t}")),
            ]
            .into_iter()
            .flatten()
            .collect();
            let turn = usize::from(order) % flags.len().max(1);
            flags.rotate_left(turn);
            let query = if flags.is_empty() { String::new() } else { format!("?{}", flags.join("&")) };
            let text = format!("radio://{device}/{channel}/{rate_text}/{address_text}{query}");
            let uri = RadioUri { device, channel, rate, address, safelink, ackfilter, timeout_ms };
            (text, LinkUri::Radio(uri))
        });
    let usb = "[A-Za-z0-9]{1,64}".prop_map(|serial| (format!("usb://{serial}"), LinkUri::Usb { serial }));
    let host = prop_oneof![
        (any::<u8>(), any::<u8>(), any::<u8>())
            .prop_map(|(a, b, c)| UdpHost::Ip(IpAddr::V4(Ipv4Addr::new(127, a, b, c)))),
        Just(UdpHost::Ip(IpAddr::V6(Ipv6Addr::LOCALHOST))),
        Just(UdpHost::Localhost),
    ];
    let udp = (host, 1u16..=u16::MAX).prop_map(|(host, port)| {
        let text = match host {
            UdpHost::Ip(IpAddr::V6(ip)) => format!("udp://[{ip}]:{port}"),
            UdpHost::Ip(ip) => format!("udp://{ip}:{port}"),
            UdpHost::Localhost => format!("udp://localhost:{port}"),
        };
        (text, LinkUri::Udp { host, port })
    });
    prop_oneof![Just(("sim".to_string(), LinkUri::Sim)), radio, usb, udp]
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(2000))]

    #[test]
    fn never_panics_on_arbitrary_text(text in any::<String>()) {
        let _ = check_link(&text);
    }

    #[test]
    fn never_panics_on_near_misses(
        scheme in prop_oneof![Just("radio://"), Just("usb://"), Just("udp://"), Just("udp://["), Just("")],
        rest in "[0-9a-fA-FKM/:?&=.\\[\\]%#@ -]{0,40}",
    ) {
        let _ = check_link(&format!("{scheme}{rest}"));
    }

    #[test]
    fn generated_valid_links_parse_to_their_parts((text, uri) in valid_link()) {
        prop_assert_eq!(parse_link(&text, &LinkRules::default()), Ok(uri));
    }

    #[test]
    fn any_change_of_a_part_out_of_range_is_refused(
        channel in 126u32..100_000,
        port in 65_536u64..10_000_000_000,
        device in 256u32..100_000,
        a in 0u8..=255,
        b in 1u8..=255,
    ) {
        let channel_link = format!("radio://0/{channel}/2M/E7E7E7E7E7");
        let expected = format!("channel {channel} is not in 0..=125");
        prop_assert!(check_link(&channel_link).unwrap_err().ends_with(&expected));
        let device_link = format!("radio://{device}/80/2M/E7E7E7E7E7");
        prop_assert!(check_link(&device_link).is_err());
        let port_link = format!("udp://127.0.0.1:{port}");
        let expected = format!("port {port} is not in 1..=65535");
        prop_assert!(check_link(&port_link).unwrap_err().ends_with(&expected));
        // A non-loopback unicast host: refused by default, accepted once listed.
        let ip = Ipv4Addr::new(10, a, b, 1);
        let link = format!("udp://{ip}:19850");
        prop_assert!(check_link(&link).is_err());
        prop_assert_eq!(check_link_with(&link, &LinkRules { udp_hosts: vec![IpAddr::V4(ip)] }), Ok(()));
    }
}
