//! How a region server joins Zenoh: the options of `serve --region` and the configuration made
//! from them (endpoints, scouting, and the transport of `secure`).

use super::secure;
use anyhow::Context as _;
use std::path::PathBuf;

/// How `serve --region` joins Zenoh.
#[derive(Debug, Clone, Default)]
pub struct ZenohOptions {
    /// Endpoints to listen on (`tcp/HOST:PORT`).
    pub listen: Vec<String>,
    /// Endpoints to connect to.
    pub connect: Vec<String>,
    /// A Zenoh configuration file (JSON5, Zenoh's own format), applied first.
    pub config_file: Option<PathBuf>,
    /// The first chunks of every key (`--zenoh-prefix`).
    pub prefix: String,
    /// TLS with the deployment's certificates, or plain TCP on loopback.
    pub transport: secure::Transport,
    /// Every region of the deployment's road (the access control names them).
    pub regions: Vec<String>,
}

/// The Zenoh configuration: the file's if given, then the endpoints. With endpoints given, multicast
/// scouting is off (only the endpoints named are used, so separate deployments, and tests run side
/// by side, never find each other).
pub fn zenoh_config(options: &ZenohOptions) -> anyhow::Result<zenoh::Config> {
    let mut config = match &options.config_file {
        Some(file) => zenoh::Config::from_file(file)
            .map_err(|e| anyhow::anyhow!("{e}"))
            .with_context(|| format!("--zenoh-config {}", file.display()))?,
        None => zenoh::Config::default(),
    };
    let set = |config: &mut zenoh::Config, key: &str, value: String| {
        config.insert_json5(key, &value).map_err(|e| anyhow::anyhow!("{key}: {e}"))
    };
    for (key, endpoints, flag) in [
        ("listen/endpoints", &options.listen, "--zenoh-listen"),
        ("connect/endpoints", &options.connect, "--zenoh-connect"),
    ] {
        if !endpoints.is_empty() {
            let list = serde_json::to_string(endpoints)?;
            set(&mut config, key, list).with_context(|| format!("{flag} {}", endpoints.join(" ")))?;
        }
    }
    if !(options.listen.is_empty() && options.connect.is_empty()) {
        set(&mut config, "scouting/multicast/enabled", "false".into())?;
    }
    if options.listen.is_empty() && options.config_file.is_none() {
        // Zenoh's default is to listen on plain TCP on every interface: listen on nothing unless told.
        set(&mut config, "listen/endpoints", "[]".into())?;
    }
    // Every endpoint, the file's too, must suit the transport.
    let mut endpoints = Vec::new();
    for key in ["listen/endpoints", "connect/endpoints"] {
        let listed = config.get_json(key).map_err(|e| anyhow::anyhow!("{key}: {e}"))?;
        let listed: serde_json::Value = serde_json::from_str(&listed)?;
        // A plain list, or one per mode ({"peer": [...], ...}).
        let lists = match &listed {
            serde_json::Value::Object(modes) => modes.values().cloned().collect(),
            other => vec![other.clone()],
        };
        for list in lists {
            endpoints.extend(serde_json::from_value::<Vec<String>>(list).unwrap_or_default());
        }
    }
    secure::check_endpoints(&options.transport, &endpoints).map_err(anyhow::Error::msg)?;
    secure::apply(&mut config, &options.transport, &options.prefix, &options.regions)?;
    Ok(config)
}
