//! The data directory's database, `DIR/airroads.db`: SQLite in WAL mode with `synchronous=FULL`, so
//! a commit returns only once its write-ahead log is on disk. It holds the fleet's durable state
//! (parameters, road, hold, and per UAV its policy, goal, link and last position) and the audit
//! log ([`audit_log`]). `--ephemeral` uses the same code on an in-memory database. Only the state writer
//! ([`super::durable`]) touches it while the server runs.

mod audit_log;

pub use audit_log::{AUDIT_RETENTION, AuditEntry, AuditRecord, REFUSED_AUDIT_RETENTION, now_ms, rfc3339_ms};

use super::persist::{self, SavedState, SavedUav};
use roads::AirspaceLayout;
use rusqlite::{Connection, OptionalExtension, params};
use serde::Serialize;
use std::path::{Path, PathBuf};
use uav::Params;

/// Name of the database inside the data directory.
pub const DB_FILE: &str = "airroads.db";

/// Format tag of the database (`meta.format`).
pub const DB_FORMAT: &str = "airroads-db/1";

const SCHEMA: &str = "
CREATE TABLE IF NOT EXISTS meta (key TEXT PRIMARY KEY, value TEXT NOT NULL) STRICT;
CREATE TABLE IF NOT EXISTS uavs (
    id TEXT PRIMARY KEY, ord INTEGER NOT NULL, policy TEXT NOT NULL,
    x REAL NOT NULL, y REAL NOT NULL, goal_x REAL, goal_y REAL, link TEXT) STRICT;
CREATE TABLE IF NOT EXISTS audit (
    seq INTEGER PRIMARY KEY AUTOINCREMENT, time_ms INTEGER NOT NULL, method TEXT NOT NULL,
    route TEXT NOT NULL, remote TEXT NOT NULL, status INTEGER NOT NULL, outcome TEXT NOT NULL,
    detail TEXT NOT NULL) STRICT;
CREATE INDEX IF NOT EXISTS audit_applied ON audit(seq) WHERE outcome = 'applied';
CREATE INDEX IF NOT EXISTS audit_refused ON audit(seq) WHERE outcome <> 'applied';
";

/// Why the database could not be opened, read or written.
#[derive(Debug, thiserror::Error)]
pub enum StoreError {
    /// The data directory cannot be created or written.
    #[error("{path}: {reason}")]
    Directory {
        /// The directory.
        path: PathBuf,
        /// What failed.
        reason: String,
    },
    /// SQLite refused (full disk, I/O error, corrupt file, ...).
    #[error("{0}")]
    Sqlite(#[from] rusqlite::Error),
    /// The stored state does not parse or validate.
    #[error("stored state: {0}")]
    Corrupt(String),
}

/// One change to the stored state.
#[derive(Debug, Clone, PartialEq)]
pub enum Write {
    /// Everything at once (a scenario load, the first state of a new database).
    Replace(SavedState),
    /// A new road (its segments and regions) or network.
    Road(AirspaceLayout),
    /// Hold on or off.
    Paused(bool),
    /// A UAV added or changed (policy, goal).
    Uav(SavedUav),
    /// A UAV removed.
    RemoveUav(String),
    /// The UAVs' last positions (written every second while flying).
    Positions(Vec<(String, [f64; 2])>),
    /// An audit entry.
    Audit(AuditRecord),
}

/// The open database.
pub struct Store {
    conn: Connection,
    /// Where it lives (None: in memory).
    pub path: Option<PathBuf>,
    audit_since_trim: usize,
}

impl Store {
    /// Opens (creating if needed) `dir/airroads.db` and proves it writable with a committed write;
    /// imports a legacy `state.json` into a new database and removes a stale `state.json.tmp`.
    pub fn open(dir: &Path) -> Result<Self, StoreError> {
        let directory = |reason: String| StoreError::Directory { path: dir.to_path_buf(), reason };
        std::fs::create_dir_all(dir)
            .map_err(|e| directory(format!("cannot create the data directory: {e}")))?;
        if !dir.is_dir() {
            return Err(directory("not a directory".into()));
        }
        let path = dir.join(DB_FILE);
        let conn = Connection::open(&path).map_err(|e| directory(format!("cannot open {DB_FILE}: {e}")))?;
        let mut store = Self { conn, path: Some(path), audit_since_trim: 0 };
        store.prepare().map_err(|e| directory(format!("not writable: {e}")))?;
        // A leftover of the JSON state file's atomic writes (before the database) is garbage.
        let _ = std::fs::remove_file(dir.join(format!("{}.tmp", persist::STATE_FILE)));
        if store.load()?.is_none()
            && let Some(legacy) = persist::load(dir).map_err(|e| StoreError::Corrupt(format!("{e:#}")))?
        {
            store.commit([&Write::Replace(legacy)])?;
            let from = dir.join(persist::STATE_FILE);
            let _ = std::fs::rename(&from, dir.join(format!("{}.imported", persist::STATE_FILE)));
            tracing::info!("imported {} into {DB_FILE}", from.display());
        }
        Ok(store)
    }

    /// An in-memory database (`--ephemeral`): the same API, nothing survives the process.
    pub fn in_memory() -> Result<Self, StoreError> {
        let mut store = Self { conn: Connection::open_in_memory()?, path: None, audit_since_trim: 0 };
        store.prepare()?;
        Ok(store)
    }

    fn prepare(&mut self) -> Result<(), rusqlite::Error> {
        // WAL: a commit appends to the log and fsyncs it once (FULL), readers never block it.
        let _mode: String = self.conn.query_row("PRAGMA journal_mode=WAL", [], |r| r.get(0))?;
        self.conn.execute_batch("PRAGMA synchronous=FULL; PRAGMA foreign_keys=OFF;")?;
        self.conn.busy_timeout(std::time::Duration::from_secs(2))?;
        self.conn.execute_batch(SCHEMA)?;
        // Proves the file and its directory writable now rather than at the first change.
        let tx = self.conn.transaction()?;
        tx.execute(
            "INSERT INTO meta(key, value) VALUES('format', ?1) ON CONFLICT(key) DO UPDATE SET value = ?1",
            [DB_FORMAT],
        )?;
        tx.commit()
    }

    /// The stored fleet; None when nothing was stored yet.
    pub fn load(&self) -> Result<Option<SavedState>, StoreError> {
        let meta = |key: &str| -> Result<Option<String>, StoreError> {
            Ok(self
                .conn
                .query_row("SELECT value FROM meta WHERE key = ?1", [key], |r| r.get(0))
                .optional()?)
        };
        let (Some(params), Some(segments)) = (meta("params")?, meta("segments")?) else {
            return Ok(None);
        };
        let corrupt = |what: &str, e: serde_json::Error| StoreError::Corrupt(format!("{what}: {e}"));
        let params: Params = serde_json::from_str(&params).map_err(|e| corrupt("params", e))?;
        let segments = serde_json::from_str(&segments).map_err(|e| corrupt("segments", e))?;
        let regions = match meta("regions")? {
            Some(r) => Some(serde_json::from_str(&r).map_err(|e| corrupt("regions", e))?),
            None => None,
        };
        let network = match meta("network")? {
            Some(n) => Some(serde_json::from_str(&n).map_err(|e| corrupt("network", e))?),
            None => None,
        };
        let paused = meta("paused")?.as_deref() == Some("1");
        let mut statement =
            self.conn.prepare("SELECT id, policy, x, y, goal_x, goal_y, link FROM uavs ORDER BY ord")?;
        let uavs = statement
            .query_map([], |r| {
                let goal = match (r.get::<_, Option<f64>>(4)?, r.get::<_, Option<f64>>(5)?) {
                    (Some(x), Some(y)) => Some([x, y]),
                    _ => None,
                };
                Ok(SavedUav {
                    id: r.get(0)?,
                    policy: r.get(1)?,
                    position: [r.get(2)?, r.get(3)?],
                    goal,
                    link: r.get(6)?,
                })
            })?
            .collect::<Result<Vec<_>, _>>()?;
        Ok(Some(SavedState {
            format: persist::FORMAT.into(),
            params,
            segments,
            regions,
            network,
            paused,
            uavs,
        }))
    }

    /// Writes `writes` in one transaction; Ok only once it is on disk. On an error nothing of it is
    /// stored.
    pub fn commit<'a>(&mut self, writes: impl IntoIterator<Item = &'a Write>) -> Result<(), StoreError> {
        let tx = self.conn.transaction()?;
        let mut audited = 0;
        for write in writes {
            audited += usize::from(matches!(write, Write::Audit(_)));
            apply(&tx, write)?;
        }
        if audited > 0 && self.audit_since_trim + audited >= 1000 {
            audit_log::trim(&tx, AUDIT_RETENTION, REFUSED_AUDIT_RETENTION)?;
        }
        tx.commit()?;
        self.audit_since_trim =
            if self.audit_since_trim + audited >= 1000 { 0 } else { self.audit_since_trim + audited };
        Ok(())
    }

    /// After a failed commit: moves the write-ahead log into the database and truncates it, which
    /// frees its space when the disk filled up (errors are ignored: the next commit reports them).
    pub fn compact_log(&self) {
        let _ = self.conn.query_row("PRAGMA wal_checkpoint(TRUNCATE)", [], |_| Ok(()));
    }
}

fn put_meta(tx: &rusqlite::Transaction<'_>, key: &str, value: &str) -> rusqlite::Result<()> {
    tx.execute(
        "INSERT INTO meta(key, value) VALUES(?1, ?2) ON CONFLICT(key) DO UPDATE SET value = ?2",
        [key, value],
    )?;
    Ok(())
}

/// The road's keys: `segments`, `regions` and `network`, each deleted when the layout has none
/// (a network's `segments` are the empty list).
fn put_road(tx: &rusqlite::Transaction<'_>, layout: &AirspaceLayout) -> rusqlite::Result<()> {
    let empty = Vec::new();
    let (segments, regions, network) = match layout {
        AirspaceLayout::Road(road) => (&road.segments, road.regions.as_ref(), None),
        AirspaceLayout::Network(network) => (&empty, None, Some(network)),
    };
    put_meta(tx, "segments", &json(segments)?)?;
    match regions {
        Some(regions) => put_meta(tx, "regions", &json(regions)?)?,
        None => drop(tx.execute("DELETE FROM meta WHERE key = 'regions'", [])?),
    }
    match network {
        Some(network) => put_meta(tx, "network", &json(network)?),
        None => tx.execute("DELETE FROM meta WHERE key = 'network'", []).map(|_| ()),
    }
}

fn json(value: &impl Serialize) -> rusqlite::Result<String> {
    serde_json::to_string(value).map_err(|e| rusqlite::Error::ToSqlConversionFailure(Box::new(e)))
}

fn put_uav(tx: &rusqlite::Transaction<'_>, u: &SavedUav) -> rusqlite::Result<()> {
    let (gx, gy) = (u.goal.map(|g| g[0]), u.goal.map(|g| g[1]));
    // A new id goes last; an existing one keeps its place in the fleet's order.
    tx.prepare_cached(
        "INSERT INTO uavs(id, ord, policy, x, y, goal_x, goal_y, link)
         VALUES(?1, (SELECT COALESCE(MAX(ord), 0) + 1 FROM uavs), ?2, ?3, ?4, ?5, ?6, ?7)
         ON CONFLICT(id) DO UPDATE SET policy = ?2, x = ?3, y = ?4, goal_x = ?5, goal_y = ?6, link = ?7",
    )?
    .execute(params![u.id, u.policy, u.position[0], u.position[1], gx, gy, u.link])?;
    Ok(())
}

fn apply(tx: &rusqlite::Transaction<'_>, write: &Write) -> rusqlite::Result<()> {
    match write {
        Write::Replace(state) => {
            put_meta(tx, "params", &json(&state.params)?)?;
            put_road(tx, &state.layout())?;
            put_meta(tx, "paused", if state.paused { "1" } else { "0" })?;
            tx.execute("DELETE FROM uavs", [])?;
            for u in &state.uavs {
                put_uav(tx, u)?;
            }
        }
        Write::Road(layout) => put_road(tx, layout)?,
        Write::Paused(paused) => put_meta(tx, "paused", if *paused { "1" } else { "0" })?,
        Write::Uav(u) => put_uav(tx, u)?,
        Write::RemoveUav(id) => {
            tx.prepare_cached("DELETE FROM uavs WHERE id = ?1")?.execute([id])?;
        }
        Write::Positions(positions) => {
            let mut update = tx.prepare_cached("UPDATE uavs SET x = ?2, y = ?3 WHERE id = ?1")?;
            for (id, p) in positions {
                update.execute(params![id, p[0], p[1]])?;
            }
        }
        Write::Audit(a) => audit_log::insert(tx, a)?,
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use roads::RoadLayout;

    fn uav(id: &str, x: f64) -> SavedUav {
        SavedUav { id: id.into(), policy: "pd".into(), position: [x, 0.5], goal: None, link: None }
    }

    fn state() -> SavedState {
        SavedState {
            format: persist::FORMAT.into(),
            params: Params::default(),
            segments: roads::RoadLayout::straight(0.0, 10.0, 4.0, 2).segments,
            regions: None,
            network: None,
            paused: false,
            uavs: vec![uav("a", 1.0), uav("b", 2.0)],
        }
    }

    #[test]
    fn writes_round_trip_and_keep_the_fleet_order() {
        let dir = std::env::temp_dir().join(format!("airroads-store-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let mut store = Store::open(&dir).unwrap();
        assert_eq!(store.load().unwrap(), None);
        store.commit([&Write::Replace(state())]).unwrap();
        let mut changed = uav("a", 1.0);
        changed.goal = Some([8.0, 1.0]);
        let writes = [
            Write::Uav(changed.clone()),
            Write::Uav(uav("c", 3.0)),
            Write::RemoveUav("b".into()),
            Write::Paused(true),
            Write::Positions(vec![("c".into(), [3.5, -0.5])]),
        ];
        store.commit(&writes).unwrap();
        drop(store);
        let loaded = Store::open(&dir).unwrap().load().unwrap().unwrap();
        let mut c = uav("c", 3.5);
        c.position = [3.5, -0.5];
        assert_eq!(loaded.uavs, vec![changed, c]);
        assert!(loaded.paused);
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn a_roads_regions_survive_reopening_and_leave_with_a_road_without_them() {
        let dir = std::env::temp_dir().join(format!("airroads-store-regions-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let mut store = Store::open(&dir).unwrap();
        store.commit([&Write::Replace(state())]).unwrap();
        let regions = vec![
            roads::Region { name: "east".into(), segments: [1, 2] },
            roads::Region { name: "west".into(), segments: [0, 0] },
        ];
        let layout = RoadLayout { regions: Some(regions.clone()), ..RoadLayout::straight(0.0, 30.0, 4.0, 3) };
        store.commit([&Write::Road(layout.clone().into())]).unwrap();
        drop(store);
        let mut store = Store::open(&dir).unwrap();
        let loaded = store.load().unwrap().unwrap();
        assert_eq!((&loaded.segments, &loaded.regions), (&layout.segments, &Some(regions)));
        assert_eq!(loaded.road().unwrap().region_at(&uav::Vec2::new(25.0, 0.0)), Some("east"));
        // A road without regions (or a scenario) removes them.
        store.commit([&Write::Road(RoadLayout::straight(0.0, 20.0, 4.0, 2).into())]).unwrap();
        assert_eq!(store.load().unwrap().unwrap().regions, None);
        let mut with = state();
        with.regions = Some(vec![roads::Region { name: "all".into(), segments: [0, 1] }]);
        store.commit([&Write::Replace(with.clone())]).unwrap();
        assert_eq!(store.load().unwrap(), Some(with));
        store.commit([&Write::Replace(state())]).unwrap();
        assert_eq!(store.load().unwrap(), Some(state()));
        drop(store);
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn a_network_survives_reopening_and_a_chain_road_replaces_it() {
        let dir = std::env::temp_dir().join(format!("airroads-store-network-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let mut store = Store::open(&dir).unwrap();
        store.commit([&Write::Replace(state())]).unwrap();
        let mut network = roads::network::NetworkLayout::from(&RoadLayout::straight(0.0, 30.0, 4.0, 3));
        network.roads[0].name = "main".into();
        store.commit([&Write::Road(network.clone().into())]).unwrap();
        drop(store);
        let mut store = Store::open(&dir).unwrap();
        let loaded = store.load().unwrap().unwrap();
        assert_eq!(loaded.layout(), AirspaceLayout::Network(network.clone()));
        assert!(loaded.segments.is_empty());
        assert_eq!(loaded.road().unwrap().network().map(|n| n.cells().len()), Some(3));
        // A whole state flying the network keeps it too; a chain road removes it.
        let mut flying = state();
        (flying.segments, flying.network) = (Vec::new(), Some(network));
        store.commit([&Write::Replace(flying.clone())]).unwrap();
        assert_eq!(store.load().unwrap(), Some(flying));
        store.commit([&Write::Road(RoadLayout::straight(0.0, 20.0, 4.0, 2).into())]).unwrap();
        let loaded = store.load().unwrap().unwrap();
        assert_eq!((loaded.network, loaded.segments.len()), (None, 2));
        drop(store);
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn a_legacy_state_file_is_imported_once() {
        let dir = std::env::temp_dir().join(format!("airroads-store-legacy-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        std::fs::write(dir.join("state.json"), serde_json::to_string(&state()).unwrap()).unwrap();
        std::fs::write(dir.join("state.json.tmp"), "half a file").unwrap();
        let store = Store::open(&dir).unwrap();
        assert_eq!(store.load().unwrap(), Some(state()));
        assert!(!dir.join("state.json").exists() && !dir.join("state.json.tmp").exists());
        assert!(dir.join("state.json.imported").exists());
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn an_uncreatable_directory_is_refused() {
        let err = Store::open(Path::new("/proc/airroads/data")).err().expect("cannot create under /proc");
        assert!(err.to_string().contains("/proc/airroads/data"), "{err}");
        let file = std::env::temp_dir().join(format!("airroads-store-file-{}", std::process::id()));
        std::fs::write(&file, "x").unwrap();
        assert!(Store::open(&file).is_err());
        std::fs::remove_file(&file).unwrap();
    }
}
