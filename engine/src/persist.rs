//! What is persisted of the fleet ([`SavedState`]: parameters, road or network, hold, and per UAV its policy,
//! goal, link and last position), the default data directory, and the reader of the JSON state file
//! of earlier versions (`state.json`), which [`super::store`] imports once into its database.

use anyhow::Context as _;
use fleet::Fleet;
use roads::network::NetworkLayout;
use roads::{Airspace, AirspaceLayout, Region, RoadLayout};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use uav::Params;

/// Name of the state file inside the data directory.
pub const STATE_FILE: &str = "state.json";

/// The persisted fleet.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SavedState {
    /// Format tag, `airroads-state/1`.
    pub format: String,
    /// Parameters.
    pub params: Params,
    /// The road layout (empty when the fleet flies a network).
    pub segments: Vec<[[f64; 2]; 4]>,
    /// The layout's regions; absent when it has none.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub regions: Option<Vec<Region>>,
    /// The network the fleet flies instead of `segments`; absent for a chain road.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub network: Option<NetworkLayout>,
    /// True while the fleet is paused.
    pub paused: bool,
    /// The UAVs.
    pub uavs: Vec<SavedUav>,
}

/// One persisted UAV.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SavedUav {
    /// Unique id.
    pub id: String,
    /// Policy name.
    pub policy: String,
    /// Last known position (m); a simulated UAV resumes there at rest.
    pub position: [f64; 2],
    /// Goal, or null.
    pub goal: Option<[f64; 2]>,
    /// Its Crazyflie URI; absent for an in-process UAV.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub link: Option<String>,
}

impl SavedUav {
    /// The record of one UAV of the fleet.
    pub fn of(u: &fleet::Uav) -> Self {
        Self {
            id: u.id.clone(),
            policy: u.policy.to_string(),
            position: [u.state.p.x, u.state.p.y],
            goal: u.nav.goal().map(|g| [g.x, g.y]),
            link: Some(u.link.describe()).filter(|l| *l != links::SIM_LINK).map(str::to_string),
        }
    }
}

/// The format tag written into every state file.
pub const FORMAT: &str = "airroads-state/1";

impl SavedState {
    /// What `fleet` would resume as.
    pub fn of(fleet: &Fleet) -> Self {
        let (segments, regions, network) = parts_of(fleet.airspace().layout());
        Self {
            format: FORMAT.to_string(),
            params: fleet.config.params,
            segments,
            regions,
            network,
            paused: fleet.paused(),
            uavs: fleet.uavs().iter().map(SavedUav::of).collect(),
        }
    }

    /// The layout of this state: its network, else its road.
    pub fn layout(&self) -> AirspaceLayout {
        match &self.network {
            Some(network) => AirspaceLayout::Network(network.clone()),
            None => AirspaceLayout::Road(RoadLayout {
                segments: self.segments.clone(),
                regions: self.regions.clone(),
            }),
        }
    }

    /// The road or network of this state (validated again, a network for this state's parameters:
    /// the file may have been edited by hand).
    pub fn road(&self) -> anyhow::Result<Airspace> {
        Ok(self.layout().build(fleet::min_passage_m(&self.params))?)
    }
}

/// A layout as the saved state's keys: `segments`, `regions` and `network`.
type LayoutParts = (Vec<[[f64; 2]; 4]>, Option<Vec<Region>>, Option<NetworkLayout>);

/// The saved state's keys of `layout`: a chain's segments and regions, or a network.
pub fn parts_of(layout: AirspaceLayout) -> LayoutParts {
    match layout {
        AirspaceLayout::Road(road) => (road.segments, road.regions, None),
        AirspaceLayout::Network(network) => (Vec::new(), None, Some(network)),
    }
}

/// Reads `dir/state.json`; Ok(None) when there is none yet.
pub fn load(dir: &Path) -> anyhow::Result<Option<SavedState>> {
    let path = dir.join(STATE_FILE);
    let text = match std::fs::read_to_string(&path) {
        Ok(t) => t,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(e) => return Err(e).with_context(|| format!("reading {}", path.display())),
    };
    let state: SavedState =
        serde_json::from_str(&text).with_context(|| format!("{}: not a valid state file", path.display()))?;
    anyhow::ensure!(state.format == FORMAT, "{}: unknown format `{}`", path.display(), state.format);
    Ok(Some(state))
}

/// The default data directory: `$XDG_DATA_HOME/airroads` or `~/.local/share/airroads`.
pub fn default_dir() -> PathBuf {
    match std::env::var_os("XDG_DATA_HOME").filter(|d| !d.is_empty()) {
        Some(d) => PathBuf::from(d).join("airroads"),
        None => {
            let home = std::env::var_os("HOME").unwrap_or_else(|| ".".into());
            PathBuf::from(home).join(".local/share/airroads")
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_legacy_state_file_loads_and_a_broken_one_is_named() {
        let dir = std::env::temp_dir().join(format!("airroads-persist-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        assert!(load(&dir).unwrap().is_none());
        let state = SavedState {
            format: FORMAT.into(),
            params: Params::default(),
            segments: RoadLayout::straight(0.0, 10.0, 4.0, 2).segments,
            regions: None,
            network: None,
            paused: true,
            uavs: vec![SavedUav {
                id: "cf1".into(),
                policy: "pd".into(),
                position: [3.0, -0.5],
                goal: Some([8.0, 0.0]),
                link: Some("radio://0/80/2M/E7E7E7E7E1".into()),
            }],
        };
        std::fs::write(dir.join(STATE_FILE), serde_json::to_string(&state).unwrap()).unwrap();
        assert_eq!(load(&dir).unwrap(), Some(state));
        std::fs::write(dir.join(STATE_FILE), "{\"format\": \"airroads-state/1\"").unwrap();
        assert!(load(&dir).unwrap_err().to_string().contains("not a valid state file"));
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
