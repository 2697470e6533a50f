//! The data directory's database, `DIR/airroads.db`: SQLite in WAL mode with `synchronous=FULL`, so
//! a commit returns only once its write-ahead log is on disk. It holds the fleet's durable state
//! (parameters, road, hold, and per UAV its policy, goal, link and last position) and the audit
//! log. `--ephemeral` uses the same code on an in-memory database. Only the state writer
//! ([`super::durable`]) touches it while the server runs.

use super::persist::{self, SavedState, SavedUav};
use roads::RoadLayout;
use rusqlite::{Connection, OptionalExtension, params};
use serde::Serialize;
use std::path::{Path, PathBuf};
use uav::Params;

/// Name of the database inside the data directory.
pub const DB_FILE: &str = "airroads.db";

/// Format tag of the database (`meta.format`).
pub const DB_FORMAT: &str = "airroads-db/1";

/// Audit entries kept; older ones are deleted as new ones arrive.
pub const AUDIT_RETENTION: i64 = 100_000;

const SCHEMA: &str = "
CREATE TABLE IF NOT EXISTS meta (key TEXT PRIMARY KEY, value TEXT NOT NULL) STRICT;
CREATE TABLE IF NOT EXISTS uavs (
    id TEXT PRIMARY KEY, ord INTEGER NOT NULL, policy TEXT NOT NULL,
    x REAL NOT NULL, y REAL NOT NULL, goal_x REAL, goal_y REAL, link TEXT) STRICT;
CREATE TABLE IF NOT EXISTS audit (
    seq INTEGER PRIMARY KEY AUTOINCREMENT, time_ms INTEGER NOT NULL, method TEXT NOT NULL,
    route TEXT NOT NULL, remote TEXT NOT NULL, status INTEGER NOT NULL, outcome TEXT NOT NULL,
    detail TEXT NOT NULL) STRICT;
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

/// One entry of the audit log.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct AuditEntry {
    /// Increasing sequence number (the cursor of `GET /api/audit`).
    pub seq: i64,
    /// When the request arrived (UTC, RFC 3339 with milliseconds).
    pub time: String,
    /// HTTP method.
    pub method: String,
    /// Path and query (at most 512 bytes).
    pub route: String,
    /// The client's address `ip:port`.
    pub remote: String,
    /// The answer's HTTP status.
    pub status: u16,
    /// `applied`, or the error code of the answer (`unauthorized`, `invalid_value`, ...).
    pub outcome: String,
    /// What changed, or the error message (at most 512 bytes).
    pub detail: String,
}

/// An audit entry to write (its sequence number is assigned by the database).
#[derive(Debug, Clone, PartialEq)]
pub struct AuditRecord {
    /// Milliseconds since the Unix epoch.
    pub time_ms: i64,
    /// HTTP method.
    pub method: String,
    /// Path and query.
    pub route: String,
    /// The client's address.
    pub remote: String,
    /// HTTP status.
    pub status: u16,
    /// `applied` or an error code.
    pub outcome: String,
    /// What changed, or why not.
    pub detail: String,
}

/// One change to the stored state.
#[derive(Debug, Clone, PartialEq)]
pub enum Write {
    /// Everything at once (a scenario load, the first state of a new database).
    Replace(SavedState),
    /// A new road (its segments and regions).
    Road(RoadLayout),
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

fn clip(text: &str, max: usize) -> &str {
    let mut end = text.len().min(max);
    while !text.is_char_boundary(end) {
        end -= 1;
    }
    &text[..end]
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
        Ok(Some(SavedState { format: persist::FORMAT.into(), params, segments, regions, paused, uavs }))
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
            tx.execute(
                "DELETE FROM audit WHERE seq <= (SELECT MAX(seq) FROM audit) - ?1",
                [AUDIT_RETENTION],
            )?;
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

    /// Audit entries: with `after`, the oldest `limit` entries newer than it (oldest first);
    /// otherwise the newest `limit` entries older than `before` (if given), newest first.
    pub fn audit(
        &self,
        after: Option<i64>,
        before: Option<i64>,
        limit: usize,
    ) -> Result<Vec<AuditEntry>, StoreError> {
        let limit = i64::try_from(limit).unwrap_or(i64::MAX);
        let columns = "seq, time_ms, method, route, remote, status, outcome, detail";
        let (sql, bound) = match after {
            Some(after) => {
                (format!("SELECT {columns} FROM audit WHERE seq > ?1 ORDER BY seq ASC LIMIT ?2"), after)
            }
            None => (
                format!("SELECT {columns} FROM audit WHERE seq < ?1 ORDER BY seq DESC LIMIT ?2"),
                before.unwrap_or(i64::MAX),
            ),
        };
        let mut statement = self.conn.prepare_cached(&sql)?;
        let rows = statement.query_map(params![bound, limit], |r| {
            Ok(AuditEntry {
                seq: r.get(0)?,
                time: rfc3339_ms(r.get(1)?),
                method: r.get(2)?,
                route: r.get(3)?,
                remote: r.get(4)?,
                status: r.get(5)?,
                outcome: r.get(6)?,
                detail: r.get(7)?,
            })
        })?;
        Ok(rows.collect::<Result<Vec<_>, _>>()?)
    }
}

fn put_meta(tx: &rusqlite::Transaction<'_>, key: &str, value: &str) -> rusqlite::Result<()> {
    tx.execute(
        "INSERT INTO meta(key, value) VALUES(?1, ?2) ON CONFLICT(key) DO UPDATE SET value = ?2",
        [key, value],
    )?;
    Ok(())
}

/// The road's keys: `segments`, and `regions` (deleted when the layout has none).
fn put_road(
    tx: &rusqlite::Transaction<'_>,
    segments: &[[[f64; 2]; 4]],
    regions: Option<&[roads::Region]>,
) -> rusqlite::Result<()> {
    put_meta(tx, "segments", &json(&segments)?)?;
    match regions {
        Some(regions) => put_meta(tx, "regions", &json(&regions)?),
        None => tx.execute("DELETE FROM meta WHERE key = 'regions'", []).map(|_| ()),
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
            put_road(tx, &state.segments, state.regions.as_deref())?;
            put_meta(tx, "paused", if state.paused { "1" } else { "0" })?;
            tx.execute("DELETE FROM uavs", [])?;
            for u in &state.uavs {
                put_uav(tx, u)?;
            }
        }
        Write::Road(layout) => put_road(tx, &layout.segments, layout.regions.as_deref())?,
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
        Write::Audit(a) => {
            tx.prepare_cached(
                "INSERT INTO audit(time_ms, method, route, remote, status, outcome, detail)
                 VALUES(?1, ?2, ?3, ?4, ?5, ?6, ?7)",
            )?
            .execute(params![
                a.time_ms,
                clip(&a.method, 16),
                clip(&a.route, 512),
                clip(&a.remote, 64),
                a.status,
                clip(&a.outcome, 64),
                clip(&a.detail, 512)
            ])?;
        }
    }
    Ok(())
}

/// `time_ms` (ms since the Unix epoch, UTC) as RFC 3339 with milliseconds.
pub fn rfc3339_ms(time_ms: i64) -> String {
    let (days, ms) = (time_ms.div_euclid(86_400_000), time_ms.rem_euclid(86_400_000));
    // Civil date from days since 1970-01-01 (Howard Hinnant's algorithm).
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z.rem_euclid(146_097);
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let day = doy - (153 * mp + 2) / 5 + 1;
    let month = if mp < 10 { mp + 3 } else { mp - 9 };
    let year = yoe + era * 400 + i64::from(month <= 2);
    let (h, m, s, milli) = (ms / 3_600_000, ms / 60_000 % 60, ms / 1000 % 60, ms % 1000);
    format!("{year:04}-{month:02}-{day:02}T{h:02}:{m:02}:{s:02}.{milli:03}Z")
}

/// Milliseconds since the Unix epoch now.
pub fn now_ms() -> i64 {
    let since = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).unwrap_or_default();
    i64::try_from(since.as_millis()).unwrap_or(i64::MAX)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn uav(id: &str, x: f64) -> SavedUav {
        SavedUav { id: id.into(), policy: "pd".into(), position: [x, 0.5], goal: None, link: None }
    }

    fn state() -> SavedState {
        SavedState {
            format: persist::FORMAT.into(),
            params: Params::default(),
            segments: roads::RoadLayout::straight(0.0, 10.0, 4.0, 2).segments,
            regions: None,
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
        store.commit([&Write::Road(layout.clone())]).unwrap();
        drop(store);
        let mut store = Store::open(&dir).unwrap();
        let loaded = store.load().unwrap().unwrap();
        assert_eq!((&loaded.segments, &loaded.regions), (&layout.segments, &Some(regions)));
        assert_eq!(loaded.road().unwrap().region_of(2).map(|r| r.name.as_str()), Some("east"));
        // A road without regions (or a scenario) removes them.
        store.commit([&Write::Road(RoadLayout::straight(0.0, 20.0, 4.0, 2))]).unwrap();
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
    fn audit_pages_both_ways() {
        let mut store = Store::in_memory().unwrap();
        let record = |i: i64| {
            Write::Audit(AuditRecord {
                time_ms: 1_700_000_000_000 + i,
                method: "POST".into(),
                route: format!("/api/x/{i}"),
                remote: "127.0.0.1:1".into(),
                status: 200,
                outcome: "applied".into(),
                detail: "x".repeat(2000),
            })
        };
        let writes: Vec<Write> = (0..10).map(record).collect();
        store.commit(&writes).unwrap();
        let newest = store.audit(None, None, 3).unwrap();
        assert_eq!(newest.iter().map(|e| e.seq).collect::<Vec<_>>(), vec![10, 9, 8]);
        assert_eq!(newest[0].detail.len(), 512);
        let older = store.audit(None, Some(8), 2).unwrap();
        assert_eq!(older.iter().map(|e| e.seq).collect::<Vec<_>>(), vec![7, 6]);
        let tail = store.audit(Some(8), None, 10).unwrap();
        assert_eq!(tail.iter().map(|e| e.seq).collect::<Vec<_>>(), vec![9, 10]);
        assert_eq!(newest[2].time, "2023-11-14T22:13:20.007Z");
    }

    #[test]
    fn rfc3339_of_known_instants() {
        assert_eq!(rfc3339_ms(0), "1970-01-01T00:00:00.000Z");
        assert_eq!(rfc3339_ms(951_782_400_123), "2000-02-29T00:00:00.123Z");
        assert_eq!(rfc3339_ms(1_798_761_599_999), "2026-12-31T23:59:59.999Z");
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
