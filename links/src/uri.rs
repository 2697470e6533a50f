//! Link names, parsed strictly: `sim`, or a Crazyflie URI in exactly the forms the `crazyflie`
//! relay opens. The radio and USB forms are those crazyflie-link 0.5 parses
//! (`crazyradio_connection.rs` and `crazyflie_usb_connection.rs` in its source); UDP hosts are IP
//! literals or `localhost`, and only loopback unless [`LinkRules`] allows more.
//!
//! | form | rules |
//! |---|---|
//! | `sim` | the in-process simulator |
//! | `radio://DEV/CHANNEL/RATE/ADDRESS[?FLAGS]` | DEV the Crazyradio's index 0–255; CHANNEL 0–125; RATE `250K`, `1M` or `2M`; ADDRESS 10 hex digits (crazyflie-link 0.5 requires it, although its documentation calls it optional); FLAGS `safelink=0\|1`, `ackfilter=0\|1`, `timeout=MS` (1–60000), each at most once, joined by `&` |
//! | `usb://SERIAL` | the Crazyflie's USB serial number, 1–64 letters and digits (crazyflie-link 0.5 matches it against the serial number string, not an index) |
//! | `udp://HOST:PORT` | HOST an IPv4 literal, a bracketed IPv6 literal or `localhost` (never resolved otherwise); PORT 1–65535 |
//!
//! Everything else is refused, with a message naming the part at fault, e.g.
//! `udp://127.0.0.1:99999: port 99999 is not in 1..=65535`.

use std::fmt::Write as _;
use std::net::{IpAddr, Ipv4Addr, Ipv6Addr};

/// Longest link name accepted (characters).
pub const MAX_LINK_LEN: usize = 256;
/// Largest Crazyradio channel.
pub const MAX_RADIO_CHANNEL: u8 = 125;
/// Largest `timeout=` flag of a radio URI (ms).
pub const MAX_RADIO_TIMEOUT_MS: u32 = 60_000;

/// What a link may name beyond its syntax.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct LinkRules {
    /// Hosts `udp://` links may name besides loopback (127.0.0.0/8, ::1 and `localhost`, always
    /// allowed). Empty by default: a scenario file or a request cannot make the server send
    /// datagrams to another machine unless its operator listed that machine. IPv4-mapped IPv6
    /// addresses match their IPv4 address.
    pub udp_hosts: Vec<IpAddr>,
}

/// A Crazyradio data rate.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RadioRate {
    /// `250K`.
    Kbps250,
    /// `1M`.
    Mbps1,
    /// `2M`.
    Mbps2,
}

/// A parsed `radio://` URI.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RadioUri {
    /// Index of the Crazyradio (0: the first one found).
    pub device: u8,
    /// Radio channel, 0–125.
    pub channel: u8,
    /// Data rate as written. crazyflie-link 0.5.1 does not use it: the Crazyradio stays at its
    /// default, 2M.
    pub rate: RadioRate,
    /// Radio address, 5 bytes.
    pub address: [u8; 5],
    /// `safelink=` flag, if given.
    pub safelink: Option<bool>,
    /// `ackfilter=` flag, if given.
    pub ackfilter: Option<bool>,
    /// `timeout=` flag (ms), if given.
    pub timeout_ms: Option<u32>,
}

/// The host of a `udp://` URI.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum UdpHost {
    /// An IP literal.
    Ip(IpAddr),
    /// `localhost`.
    Localhost,
}

/// A parsed link name.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum LinkUri {
    /// `sim`: the in-process simulator.
    Sim,
    /// A Crazyradio URI.
    Radio(RadioUri),
    /// A Crazyflie on a USB cable, by serial number.
    Usb {
        /// The USB serial number string.
        serial: String,
    },
    /// CRTP over UDP (a simulator or a bridge).
    Udp {
        /// The peer's host.
        host: UdpHost,
        /// The peer's port, 1–65535.
        port: u16,
    },
}

/// A link name that was refused. Displays as `LINK: REASON`; `link` is the name as given with
/// control and other invisible characters escaped (`\u{202e}`), cut after 80 characters.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{link}: {reason}")]
pub struct LinkError {
    /// The refused name, escaped and shortened for display.
    pub link: String,
    /// What is wrong with it.
    pub reason: String,
}

/// The link name for messages: escaped like a Rust string, at most 80 characters of it.
fn shown(link: &str) -> String {
    let mut out = String::new();
    for (k, c) in link.chars().enumerate() {
        if k == 80 {
            out.push('…');
            break;
        }
        let _ = write!(out, "{}", c.escape_debug());
    }
    out
}

/// Parses a link name, checking it against `rules`.
pub fn parse_link(link: &str, rules: &LinkRules) -> Result<LinkUri, LinkError> {
    parse(link, rules).map_err(|reason| LinkError { link: shown(link), reason })
}

fn parse(link: &str, rules: &LinkRules) -> Result<LinkUri, String> {
    let len = link.chars().count();
    if len > MAX_LINK_LEN {
        return Err(format!("longer than {MAX_LINK_LEN} characters ({len})"));
    }
    if let Some((k, c)) = link.chars().enumerate().find(|&(_, c)| !c.is_ascii_graphic()) {
        return Err(format!(
            "character {:?} at position {k} is not allowed (link names are printable ASCII, without spaces)",
            c
        ));
    }
    if link == crate::SIM_LINK {
        return Ok(LinkUri::Sim);
    }
    if let Some(rest) = link.strip_prefix("radio://") {
        return parse_radio(rest).map(LinkUri::Radio);
    }
    if let Some(serial) = link.strip_prefix("usb://") {
        let ok = (1..=64).contains(&serial.len()) && serial.bytes().all(|b| b.is_ascii_alphanumeric());
        return if ok {
            Ok(LinkUri::Usb { serial: serial.to_string() })
        } else {
            Err(format!(
                "serial `{serial}` is not 1 to 64 letters and digits (usb://SERIAL, the USB serial number)"
            ))
        };
    }
    if let Some(rest) = link.strip_prefix("udp://") {
        return parse_udp(rest, rules);
    }
    Err("not `sim` or a Crazyflie URI (radio://DEV/CHANNEL/RATE/ADDRESS, usb://SERIAL, udp://HOST:PORT)"
        .into())
}

/// A decimal number without sign or leading zero, within `min..=max`; `what` names it in errors.
fn number(text: &str, min: u32, max: u32, what: &str) -> Result<u32, String> {
    let digits = !text.is_empty() && text.bytes().all(|b| b.is_ascii_digit());
    if !digits {
        return Err(format!("{what} `{text}` is not a number in {min}..={max}"));
    }
    if text.len() > 1 && text.starts_with('0') {
        return Err(format!("{what} `{text}` has a leading zero"));
    }
    match text.parse::<u32>() {
        Ok(n) if (min..=max).contains(&n) => Ok(n),
        _ => Err(format!("{what} {text} is not in {min}..={max}")),
    }
}

fn parse_radio(rest: &str) -> Result<RadioUri, String> {
    const FORM: &str = "radio://DEV/CHANNEL/RATE/ADDRESS";
    let (path, query) = match rest.split_once('?') {
        Some((path, query)) => (path, Some(query)),
        None => (rest, None),
    };
    let parts: Vec<&str> = path.split('/').collect();
    let [device, channel, rate, address] = parts[..] else {
        return Err(if parts.len() == 3 {
            format!(
                "the address is missing: crazyflie-link 0.5 needs {FORM}, e.g. radio://0/80/2M/E7E7E7E7E7"
            )
        } else {
            format!("has {} path parts, expected 4: {FORM}", parts.len())
        });
    };
    // Both fit: the limits are at most 255.
    let device = number(device, 0, u8::MAX.into(), "device")? as u8;
    let channel = number(channel, 0, MAX_RADIO_CHANNEL.into(), "channel")? as u8;
    let rate = match rate {
        "250K" => RadioRate::Kbps250,
        "1M" => RadioRate::Mbps1,
        "2M" => RadioRate::Mbps2,
        other => return Err(format!("rate `{other}` is not 250K, 1M or 2M")),
    };
    if address.len() != 10 || !address.bytes().all(|b| b.is_ascii_hexdigit()) {
        return Err(format!("address `{address}` is not 10 hex digits"));
    }
    let mut bytes = [0u8; 5];
    for (k, byte) in bytes.iter_mut().enumerate() {
        // Two hex digits, checked above.
        *byte = u8::from_str_radix(&address[2 * k..2 * k + 2], 16).map_err(|e| e.to_string())?;
    }
    let mut uri =
        RadioUri { device, channel, rate, address: bytes, safelink: None, ackfilter: None, timeout_ms: None };
    if let Some(query) = query {
        parse_flags(query, &mut uri)?;
    }
    Ok(uri)
}

fn parse_flags(query: &str, uri: &mut RadioUri) -> Result<(), String> {
    const FLAGS: &str = "safelink=0|1, ackfilter=0|1 or timeout=MS";
    for pair in query.split('&') {
        let Some((key, value)) = pair.split_once('=') else {
            return Err(format!("flag `{pair}` is not KEY=VALUE ({FLAGS})"));
        };
        let twice = || format!("flag `{key}` is given twice");
        let bit = |value: &str| match value {
            "0" => Ok(false),
            "1" => Ok(true),
            _ => Err(format!("{key}={value}: must be 0 or 1")),
        };
        match key {
            "safelink" if uri.safelink.is_some() => return Err(twice()),
            "safelink" => uri.safelink = Some(bit(value)?),
            "ackfilter" if uri.ackfilter.is_some() => return Err(twice()),
            "ackfilter" => uri.ackfilter = Some(bit(value)?),
            "timeout" if uri.timeout_ms.is_some() => return Err(twice()),
            "timeout" => {
                uri.timeout_ms = Some(number(value, 1, MAX_RADIO_TIMEOUT_MS, "timeout (ms)")?);
            }
            other => return Err(format!("flag `{other}` is not one of {FLAGS}")),
        }
    }
    Ok(())
}

fn parse_udp(rest: &str, rules: &LinkRules) -> Result<LinkUri, String> {
    let (host, port) = if let Some(bracketed) = rest.strip_prefix('[') {
        let (inside, after) =
            bracketed.split_once(']').ok_or("the IPv6 host has no closing `]` (udp://[ADDRESS]:PORT)")?;
        let port = after.strip_prefix(':').ok_or("the port is missing (udp://HOST:PORT)")?;
        let ip: Ipv6Addr = inside.parse().map_err(|_| format!("host `[{inside}]` is not an IPv6 address"))?;
        (UdpHost::Ip(IpAddr::V6(ip)), port)
    } else {
        let (host, port) = rest.rsplit_once(':').ok_or("the port is missing (udp://HOST:PORT)")?;
        let host = if host == "localhost" {
            UdpHost::Localhost
        } else if let Ok(ip) = host.parse::<Ipv4Addr>() {
            UdpHost::Ip(IpAddr::V4(ip))
        } else if host.contains(':') {
            return Err(format!("host `{host}`: an IPv6 address goes in brackets, udp://[{host}]:PORT"));
        } else {
            return Err(format!(
                "host `{host}` is not an IP address or localhost (host names are not resolved)"
            ));
        };
        (host, port)
    };
    let port = udp_port(port)?;
    if let UdpHost::Ip(ip) = host {
        check_udp_host(ip, rules)?;
    }
    Ok(LinkUri::Udp { host, port })
}

fn udp_port(text: &str) -> Result<u16, String> {
    // Fits: at most 65535.
    number(text, 1, u16::MAX.into(), "port").map(|n| n as u16)
}

fn check_udp_host(ip: IpAddr, rules: &LinkRules) -> Result<(), String> {
    let ip = ip.to_canonical();
    let unicast = match ip {
        IpAddr::V4(v4) => !(v4.is_unspecified() || v4.is_multicast() || v4.is_broadcast()),
        IpAddr::V6(v6) => !(v6.is_unspecified() || v6.is_multicast()),
    };
    if !unicast {
        return Err(format!("host {ip} is not a unicast address"));
    }
    if ip.is_loopback() || rules.udp_hosts.iter().any(|h| h.to_canonical() == ip) {
        return Ok(());
    }
    if rules.udp_hosts.is_empty() {
        Err(format!("host {ip} is not loopback, and no other UDP host is allowed"))
    } else {
        let allowed: Vec<String> = rules.udp_hosts.iter().map(IpAddr::to_string).collect();
        Err(format!("host {ip} is neither loopback nor an allowed UDP host ({})", allowed.join(", ")))
    }
}
