//! The data directory: road, parameters, fleet and goals in `state.json`, written atomically (temp
//! file, fsync, rename, fsync of the directory), so a restart, even after kill -9, resumes the last
//! complete state and never a half-written one.

use anyhow::Context as _;
use fleet::Fleet;
use roads::{Road, RoadLayout};
use serde::{Deserialize, Serialize};
use std::io::Write as _;
use std::path::{Path, PathBuf};
use tokio::sync::watch;
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
    /// The road layout.
    pub segments: Vec<[[f64; 2]; 4]>,
    /// True while the fleet holds.
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

/// The format tag written into every state file.
pub const FORMAT: &str = "airroads-state/1";

impl SavedState {
    /// What `fleet` would resume as.
    pub fn of(fleet: &Fleet) -> Self {
        Self {
            format: FORMAT.to_string(),
            params: fleet.config.params,
            segments: fleet.road().layout().segments.clone(),
            paused: fleet.holding(),
            uavs: fleet
                .uavs()
                .iter()
                .map(|u| SavedUav {
                    id: u.id.clone(),
                    policy: u.policy.clone(),
                    position: [u.state.p.x, u.state.p.y],
                    goal: u.nav.goal().map(|g| [g.x, g.y]),
                    link: Some(u.link.describe()).filter(|l| *l != links::SIM_LINK).map(str::to_string),
                })
                .collect(),
        }
    }

    /// The road of this state (validated again: the file may have been edited by hand).
    pub fn road(&self) -> anyhow::Result<Road> {
        Ok(Road::new(RoadLayout { segments: self.segments.clone() })?)
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

/// Writes `state` to `dir/state.json` atomically.
pub fn save(dir: &Path, state: &SavedState) -> anyhow::Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let path = dir.join(STATE_FILE);
    let tmp = dir.join(format!("{STATE_FILE}.tmp"));
    let mut file = std::fs::File::create(&tmp).with_context(|| format!("creating {}", tmp.display()))?;
    file.write_all(&serde_json::to_vec_pretty(state)?)?;
    file.sync_all()?;
    drop(file);
    std::fs::rename(&tmp, &path).with_context(|| format!("renaming to {}", path.display()))?;
    // The rename is durable only once the directory entry is on disk.
    std::fs::File::open(dir)?.sync_all()?;
    Ok(())
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

/// Writes every new state published on `states` until the sender is gone (then writes the last one).
/// Runs on tokio's blocking pool, never in the fleet loop; a failed write is reported and retried
/// with the next state.
pub async fn writer(dir: PathBuf, mut states: watch::Receiver<std::sync::Arc<SavedState>>) {
    let mut last_written: Option<std::sync::Arc<SavedState>> = None;
    loop {
        let closed = states.changed().await.is_err();
        let state = states.borrow_and_update().clone();
        if last_written.as_ref().is_none_or(|w| **w != *state) {
            let dir = dir.clone();
            let to_write = state.clone();
            match tokio::task::spawn_blocking(move || save(&dir, &to_write)).await {
                Ok(Ok(())) => last_written = Some(state),
                Ok(Err(e)) => eprintln!("airroads: could not save the fleet state: {e:#}"),
                Err(e) => eprintln!("airroads: state writer failed: {e}"),
            }
        }
        if closed {
            return;
        }
        // At most a few writes per second, whatever the rate of changes.
        tokio::time::sleep(std::time::Duration::from_millis(200)).await;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn save_then_load_round_trips_and_leaves_no_temp_file() {
        let dir = std::env::temp_dir().join(format!("airroads-persist-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        assert!(load(&dir).unwrap().is_none());
        let state = SavedState {
            format: FORMAT.into(),
            params: Params::default(),
            segments: RoadLayout::straight(0.0, 10.0, 4.0, 2).segments,
            paused: true,
            uavs: vec![
                SavedUav {
                    id: "a".into(),
                    policy: "pd".into(),
                    position: [1.0, 0.5],
                    goal: None,
                    link: None,
                },
                SavedUav {
                    id: "cf1".into(),
                    policy: "pd".into(),
                    position: [3.0, -0.5],
                    goal: Some([8.0, 0.0]),
                    link: Some("radio://0/80/2M/E7E7E7E7E1".into()),
                },
            ],
        };
        save(&dir, &state).unwrap();
        save(&dir, &state).unwrap();
        assert_eq!(load(&dir).unwrap(), Some(state));
        assert!(!dir.join("state.json.tmp").exists());
        std::fs::write(dir.join(STATE_FILE), "{\"format\": \"airroads-state/1\"").unwrap();
        assert!(load(&dir).unwrap_err().to_string().contains("not a valid state file"));
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
