//! The audit log's table: its entries, their insertion and reading, and their retention. Applied
//! changes and everything else (refusals of any kind, unknown UAVs, ...) are kept apart: the newest
//! [`AUDIT_RETENTION`] applied entries and the newest [`REFUSED_AUDIT_RETENTION`] others. A flood of
//! refused requests (which needs no token) thus never pushes an applied change out of the log; only
//! newer applied changes do.

use super::{Store, StoreError};
use rusqlite::params;
use serde::Serialize;

/// Applied changes kept in the audit log; older ones are deleted as new ones arrive.
pub const AUDIT_RETENTION: i64 = 100_000;

/// Entries of requests not applied (refused, failed) kept in the audit log, apart from the applied
/// ones; older ones are deleted as new ones arrive.
pub const REFUSED_AUDIT_RETENTION: i64 = 10_000;

/// One entry of the audit log.
#[derive(Debug, Clone, PartialEq, Serialize, schemars::JsonSchema)]
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

fn clip(text: &str, max: usize) -> &str {
    let mut end = text.len().min(max);
    while !text.is_char_boundary(end) {
        end -= 1;
    }
    &text[..end]
}

/// Inserts one entry (long texts clipped).
pub(super) fn insert(tx: &rusqlite::Transaction<'_>, a: &AuditRecord) -> rusqlite::Result<()> {
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
    Ok(())
}

/// Deletes all but the newest `applied` applied entries and the newest `refused` other ones (each
/// kind through its own partial index, so neither scans the other).
pub(super) fn trim(tx: &rusqlite::Transaction<'_>, applied: i64, refused: i64) -> rusqlite::Result<()> {
    // The WHERE terms repeat the partial indexes' own (`audit_applied`, `audit_refused`) word for
    // word: SQLite uses such an index only then.
    tx.execute(
        "DELETE FROM audit WHERE outcome = 'applied' AND seq <= (SELECT seq FROM audit
         WHERE outcome = 'applied' ORDER BY seq DESC LIMIT 1 OFFSET ?1)",
        [applied],
    )?;
    tx.execute(
        "DELETE FROM audit WHERE outcome <> 'applied' AND seq <= (SELECT seq FROM audit
         WHERE outcome <> 'applied' ORDER BY seq DESC LIMIT 1 OFFSET ?1)",
        [refused],
    )?;
    Ok(())
}

impl Store {
    /// Audit entries: with `after`, the oldest `limit` entries newer than it and older than `before`
    /// (if given), oldest first; otherwise the newest `limit` entries older than `before` (if
    /// given), newest first.
    pub fn audit(
        &self,
        after: Option<i64>,
        before: Option<i64>,
        limit: usize,
    ) -> Result<Vec<AuditEntry>, StoreError> {
        let limit = i64::try_from(limit).unwrap_or(i64::MAX);
        let columns = "seq, time_ms, method, route, remote, status, outcome, detail";
        let before = before.unwrap_or(i64::MAX);
        let (sql, after) = match after {
            Some(after) => (
                format!("SELECT {columns} FROM audit WHERE seq > ?1 AND seq < ?2 ORDER BY seq ASC LIMIT ?3"),
                after,
            ),
            None => (
                format!("SELECT {columns} FROM audit WHERE seq > ?1 AND seq < ?2 ORDER BY seq DESC LIMIT ?3"),
                i64::MIN,
            ),
        };
        let mut statement = self.conn.prepare_cached(&sql)?;
        let rows = statement.query_map(params![after, before, limit], |r| {
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
    use super::super::Write;
    use super::*;

    fn record(i: i64, outcome: &str) -> Write {
        Write::Audit(AuditRecord {
            time_ms: 1_700_000_000_000 + i,
            method: "POST".into(),
            route: format!("/api/x/{i}"),
            remote: "127.0.0.1:1".into(),
            status: if outcome == "applied" { 200 } else { 401 },
            outcome: outcome.into(),
            detail: "x".repeat(2000),
        })
    }

    /// Every entry, oldest first.
    fn all(store: &Store) -> Vec<AuditEntry> {
        let (mut entries, mut after) = (Vec::new(), 0);
        loop {
            let page = store.audit(Some(after), None, 1000).unwrap();
            let Some(last) = page.last() else { return entries };
            after = last.seq;
            entries.extend(page);
        }
    }

    #[test]
    fn audit_pages_both_ways() {
        let mut store = Store::in_memory().unwrap();
        let writes: Vec<Write> = (0..10).map(|i| record(i, "applied")).collect();
        store.commit(&writes).unwrap();
        let newest = store.audit(None, None, 3).unwrap();
        assert_eq!(newest.iter().map(|e| e.seq).collect::<Vec<_>>(), vec![10, 9, 8]);
        assert_eq!(newest[0].detail.len(), 512);
        let older = store.audit(None, Some(8), 2).unwrap();
        assert_eq!(older.iter().map(|e| e.seq).collect::<Vec<_>>(), vec![7, 6]);
        let tail = store.audit(Some(8), None, 10).unwrap();
        assert_eq!(tail.iter().map(|e| e.seq).collect::<Vec<_>>(), vec![9, 10]);
        // Both: the window between them, oldest first; an empty window is no entries.
        let window = store.audit(Some(3), Some(7), 10).unwrap();
        assert_eq!(window.iter().map(|e| e.seq).collect::<Vec<_>>(), vec![4, 5, 6]);
        assert_eq!(store.audit(Some(3), Some(7), 2).unwrap().len(), 2);
        assert!(store.audit(Some(7), Some(3), 10).unwrap().is_empty());
        assert_eq!(newest[2].time, "2023-11-14T22:13:20.007Z");
    }

    #[test]
    fn a_flood_of_refused_requests_never_pushes_applied_changes_out() {
        let mut store = Store::in_memory().unwrap();
        let applied: Vec<Write> = (0..5).map(|i| record(i, "applied")).collect();
        store.commit(&applied).unwrap();
        // More refused entries than the whole log used to keep, in the writer's group commits.
        let flood = AUDIT_RETENTION + 1000;
        for batch in 0..flood / 1000 {
            let writes: Vec<Write> =
                (0..1000).map(|i| record(10 + batch * 1000 + i, "unauthorized")).collect();
            store.commit(&writes).unwrap();
        }
        let entries = all(&store);
        let kept: Vec<&str> =
            entries.iter().filter(|e| e.outcome == "applied").map(|e| e.route.as_str()).collect();
        assert_eq!(kept, ["/api/x/0", "/api/x/1", "/api/x/2", "/api/x/3", "/api/x/4"]);
        let refused = entries.iter().filter(|e| e.outcome == "unauthorized").count() as i64;
        // Trimmed every 1000 entries: at most that many beyond the bound between two trims.
        assert!((REFUSED_AUDIT_RETENTION..REFUSED_AUDIT_RETENTION + 1000).contains(&refused), "{refused}");
        // The newest refused ones are the ones kept.
        assert_eq!(entries.last().map(|e| e.route.clone()), Some(format!("/api/x/{}", 10 + flood - 1)));
    }

    #[test]
    fn each_kind_is_trimmed_by_its_own_kind_only() {
        let mut store = Store::in_memory().unwrap();
        // Interleaved: a0 r0 r1 a1 r2 r3 a2 ... (applied every third entry).
        let writes: Vec<Write> =
            (0..30).map(|i| record(i, if i % 3 == 0 { "applied" } else { "invalid_value" })).collect();
        store.commit(&writes).unwrap();
        let tx = store.conn.transaction().unwrap();
        trim(&tx, 4, 3).unwrap();
        tx.commit().unwrap();
        let routes = |outcome: &str| -> Vec<String> {
            all(&store).into_iter().filter(|e| e.outcome == outcome).map(|e| e.route).collect()
        };
        assert_eq!(routes("applied"), ["/api/x/18", "/api/x/21", "/api/x/24", "/api/x/27"]);
        assert_eq!(routes("invalid_value"), ["/api/x/26", "/api/x/28", "/api/x/29"]);
    }

    #[test]
    fn rfc3339_of_known_instants() {
        assert_eq!(rfc3339_ms(0), "1970-01-01T00:00:00.000Z");
        assert_eq!(rfc3339_ms(951_782_400_123), "2000-02-29T00:00:00.123Z");
        assert_eq!(rfc3339_ms(1_798_761_599_999), "2026-12-31T23:59:59.999Z");
    }
}
