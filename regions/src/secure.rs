//! The region network's transport (docs/regions.md, Security): by default Zenoh's TLS
//! transport with mutual authentication against the deployment's own authority (`airroads certs`),
//! and
//! Zenoh's access control, which lets the certificate of region R (common name R) act only as R:
//!
//! | R may                                   | on                                   |
//! |-----------------------------------------|--------------------------------------|
//! | publish, declare tokens and queryables, reply | `P/region/R/**` (its states, mirror, ownership tokens, API) |
//! | send handover messages                  | `P/region/*/handover/R` (the sender is the last chunk) |
//! | ask another region's API                | `P/region/*/api/R` (the asker is the last chunk) |
//! | subscribe, ask for liveliness           | `P/**`                               |
//!
//! Everything else from a peer is dropped by Zenoh before this server sees it, and a peer without a
//! certificate of the authority cannot connect at all. Plain TCP is only for loopback and only by
//! an explicit flag (`--zenoh-insecure`), logged as a warning.

use serde_json::{Value, json};
use std::path::PathBuf;

/// A server's TLS files.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TlsFiles {
    /// The deployment's authority (`ca.pem`).
    pub ca: PathBuf,
    /// This server's certificate (common name: its region).
    pub cert: PathBuf,
    /// This server's private key.
    pub key: PathBuf,
}

/// How a region server joins the region network.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub enum Transport {
    /// TLS with mutual authentication and access control by region (the default of `serve --region`).
    Tls(TlsFiles),
    /// Plain TCP, loopback endpoints only (`--zenoh-insecure`): any process on the host can join.
    #[default]
    InsecureLoopback,
}

/// True when `endpoint` (`PROTO/HOST:PORT[#...]`) is on a loopback address.
fn on_loopback(endpoint: &str) -> bool {
    let Some((_, address)) = endpoint.split_once('/') else { return false };
    let address = address.split(['#', '?']).next().unwrap_or_default();
    let Some((host, _port)) = address.rsplit_once(':') else { return false };
    let host = host.trim_start_matches('[').trim_end_matches(']');
    host.eq_ignore_ascii_case("localhost")
        || host.parse::<std::net::IpAddr>().is_ok_and(|ip| ip.is_loopback())
}

/// Checks the endpoints against the transport: `tls/` with certificates, `tcp/` on loopback without; the
/// error names the endpoint and what to do.
pub fn check_endpoints<'a>(
    transport: &Transport,
    endpoints: impl IntoIterator<Item = &'a String>,
) -> Result<(), String> {
    for endpoint in endpoints {
        let protocol = endpoint.split_once('/').map_or("", |(p, _)| p);
        match transport {
            Transport::Tls(_) if protocol != "tls" => {
                return Err(format!(
                    "{endpoint}: the region network is TLS (`tls/HOST:PORT`); plain `tcp/` only with \
                     --zenoh-insecure on loopback"
                ));
            }
            Transport::InsecureLoopback if protocol != "tcp" || !on_loopback(endpoint) => {
                return Err(format!(
                    "{endpoint}: --zenoh-insecure allows only `tcp/` on a loopback address (127.0.0.1, \
                     ::1, localhost); give --zenoh-ca, --zenoh-cert and --zenoh-key for any other"
                ));
            }
            _ => {}
        }
    }
    Ok(())
}

/// The access-control section for a deployment of `regions` under `prefix` (see the module
/// documentation).
pub fn access_control(prefix: &str, regions: &[String]) -> Value {
    // An allow rule: its id, the messages and flow it allows, on one key expression.
    let rule = |id: String, messages: &[&str], flow: &str, key: String| json!({"id": id, "messages": messages, "flows": [flow], "permission": "allow", "key_exprs": [key]});
    let read = ["declare_subscriber", "declare_liveliness_subscriber", "liveliness_query"];
    let all = ["put", "delete", "declare_subscriber", "query", "reply", "declare_queryable"]
        .into_iter()
        .chain(["liveliness_token", "liveliness_query", "declare_liveliness_subscriber"])
        .collect::<Vec<_>>();
    let mut rules = vec![
        rule("read".into(), &read, "ingress", format!("{prefix}/**")),
        rule("egress".into(), &all, "egress", format!("{prefix}/**")),
    ];
    let mut subjects = Vec::new();
    let mut policies = Vec::new();
    for region in regions {
        let own = ["put", "delete", "declare_queryable", "reply", "liveliness_token"];
        let (own_id, handover_id, ask_id) =
            (format!("own-{region}"), format!("handover-from-{region}"), format!("ask-from-{region}"));
        rules.push(rule(own_id.clone(), &own, "ingress", format!("{prefix}/region/{region}/**")));
        rules.push(rule(
            handover_id.clone(),
            &["put"],
            "ingress",
            format!("{prefix}/region/*/handover/{region}"),
        ));
        rules.push(rule(ask_id.clone(), &["query"], "ingress", format!("{prefix}/region/*/api/{region}")));
        subjects.push(json!({ "id": format!("region-{region}"), "cert_common_names": [region] }));
        policies.push(json!({
            "id": format!("as-{region}"),
            "rules": [own_id, handover_id, ask_id],
            "subjects": [format!("region-{region}")],
        }));
    }
    let everyone: Vec<String> = regions.iter().map(|r| format!("region-{r}")).collect();
    policies.push(json!({ "id": "every-region", "rules": ["read", "egress"], "subjects": everyone }));
    json!({
        "enabled": true,
        "default_permission": "deny",
        "rules": rules,
        "subjects": subjects,
        "policies": policies,
    })
}

/// Puts the transport into `config`: TLS files, mutual authentication and access control, or
/// nothing for plain TCP.
pub fn apply(
    config: &mut zenoh::Config,
    transport: &Transport,
    prefix: &str,
    regions: &[String],
) -> anyhow::Result<()> {
    let Transport::Tls(files) = transport else {
        return Ok(());
    };
    for (flag, path) in
        [("--zenoh-ca", &files.ca), ("--zenoh-cert", &files.cert), ("--zenoh-key", &files.key)]
    {
        std::fs::metadata(path).map_err(|e| anyhow::anyhow!("{flag} {}: {e}", path.display()))?;
    }
    let path = |p: &PathBuf| serde_json::to_string(&p.display().to_string());
    let settings = [
        ("transport/link/tls/root_ca_certificate", path(&files.ca)?),
        ("transport/link/tls/listen_certificate", path(&files.cert)?),
        ("transport/link/tls/listen_private_key", path(&files.key)?),
        ("transport/link/tls/connect_certificate", path(&files.cert)?),
        ("transport/link/tls/connect_private_key", path(&files.key)?),
        ("transport/link/tls/enable_mtls", "true".into()),
        // Identity is the certificate's common name, checked by the access control; host names
        // do not identify a region server (its address may change with a failover).
        ("transport/link/tls/verify_name_on_connect", "false".into()),
        ("transport/link/tls/close_link_on_expiration", "true".into()),
        ("access_control", access_control(prefix, regions).to_string()),
    ];
    for (key, value) in settings {
        config.insert_json5(key, &value).map_err(|e| anyhow::anyhow!("{key}: {e}"))?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn plain_tcp_only_on_loopback_and_tls_only_with_certificates() {
        let tls = Transport::Tls(TlsFiles { ca: "c".into(), cert: "a".into(), key: "k".into() });
        let plain = Transport::InsecureLoopback;
        let ok = |t: &Transport, e: &str| check_endpoints(t, [&e.to_string()]).is_ok();
        assert!(ok(&tls, "tls/10.0.0.2:7447") && ok(&tls, "tls/[::1]:7447"));
        assert!(!ok(&tls, "tcp/127.0.0.1:7447") && !ok(&tls, "quic/127.0.0.1:7447"));
        for e in ["tcp/127.0.0.1:7447", "tcp/127.3.2.1:1", "tcp/[::1]:7447", "tcp/localhost:7447"] {
            assert!(ok(&plain, e), "{e}");
        }
        for e in ["tcp/0.0.0.0:7447", "tcp/10.0.0.2:7447", "tls/127.0.0.1:7447", "udp/127.0.0.1:1", "x"] {
            assert!(!ok(&plain, e), "{e}");
        }
    }

    #[test]
    fn the_access_control_is_accepted_by_zenoh() {
        let regions = vec!["west".to_string(), "east".into()];
        let mut config = zenoh::Config::default();
        let acl = access_control("airroads", &regions);
        config.insert_json5("access_control", &acl.to_string()).unwrap();
        assert_eq!(acl["policies"].as_array().unwrap().len(), 3);
        assert_eq!(acl["rules"][2]["key_exprs"][0], "airroads/region/west/**");
    }
}
