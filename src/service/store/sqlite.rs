//! The embedded backend: SQLite (bundled build, WAL journal, synchronous FULL) for shape records, fingerprints and
//! the job queue; uploads and results as content-addressed files in the data directory, written atomically.

use super::*;
use crate::service::ids::{file_in, JobId};
use crate::service::jobs::{now, Clock, JobProgress, Status, SystemClock};
use crate::service::problem::Problem;
use rusqlite::OptionalExtension;
use std::io::Write;
use std::time::Duration;

/// The embedded database: SQLite (bundled build, WAL journal, synchronous FULL) for shape and job records, and
/// the original uploads as content-addressed files (`DIR/shapes/{id}`), parsed again on first use after a
/// restart.
pub struct Database {
    conn: Mutex<rusqlite::Connection>,
    /// Where leases are read from.
    clock: Arc<dyn Clock>,
    shape_dir: PathBuf,
    /// Locks striped by shape id: an insert or removal of one id (its file and its record together) runs alone, so
    /// simultaneous uploads of one shape, in one format or several, store one file and one record that agree.
    id_locks: [Mutex<()>; ID_LOCKS],
    /// Parsed shapes in memory, bounded by (about) their size.
    parsed: Mutex<ByteLru<StoredShape>>,
    max_vertices: usize,
    /// Ids of jobs as they change.
    changes: tokio::sync::broadcast::Sender<String>,
    /// Held (locked) while the store is open.
    _lock: Arc<std::fs::File>,
}

/// Locks the data directory for this process: it belongs to one process (its recovery requeues every job another
/// held), so a second `kac serve` on it is refused while the first runs (the lock goes with the process, kill -9
/// included). Stores of one process share the lock (a test may open a directory twice).
/// The second value: whether this call took the lock (false: a store of this process already held it).
fn lock_dir(data_dir: &Path) -> std::io::Result<(Arc<std::fs::File>, bool)> {
    static HELD: Mutex<Vec<(PathBuf, std::sync::Weak<std::fs::File>)>> = Mutex::new(Vec::new());
    let path = data_dir.canonicalize()?.join("kac.lock");
    let mut held = HELD.lock().unwrap_or_else(|e| e.into_inner());
    held.retain(|(_, f)| f.strong_count() > 0);
    if let Some(f) = held.iter().find(|(p, _)| *p == path).and_then(|(_, f)| f.upgrade()) {
        return Ok((f, false));
    }
    let file = std::fs::File::create(&path)?;
    match file.try_lock() {
        Ok(()) => {}
        Err(std::fs::TryLockError::WouldBlock) => {
            return Err(std::io::Error::new(
                std::io::ErrorKind::WouldBlock,
                format!("{} is in use by another kac process", data_dir.display()),
            ))
        }
        Err(std::fs::TryLockError::Error(e)) => return Err(e),
    }
    let file = Arc::new(file);
    held.push((path, Arc::downgrade(&file)));
    Ok((file, true))
}

/// What a process killed mid-write left in a data directory it held, removed as the next process takes the lock
/// (so no writer of it is alive), each removal logged: temporary files of atomic writes (`*.tmp.*`, `*.new.*`,
/// the index snapshot's `search-index.*.tmp`), uploads without a shape record (written before their record, never
/// acknowledged), and results' numbers that no result names (written before their result's record).
fn sweep_leftovers(data_dir: &Path, shape_dir: &Path, conn: &rusqlite::Connection) -> std::io::Result<usize> {
    let temporary = |name: &str| name.contains(".tmp.") || name.contains(".new.") || name.ends_with(".tmp");
    let mut removed = 0;
    let mut remove = |path: &Path, why: &str| match std::fs::remove_file(path) {
        Ok(()) => {
            tracing::warn!(file = %path.display(), why, "removed a leftover of an interrupted write");
            removed += 1;
        }
        Err(e) => tracing::warn!(file = %path.display(), error = %e, "cannot remove a leftover"),
    };
    let names = |dir: &Path| -> std::io::Result<Vec<String>> {
        let mut out = vec![];
        for entry in std::fs::read_dir(dir)? {
            let entry = entry?;
            if entry.file_type()?.is_file() {
                if let Ok(name) = entry.file_name().into_string() {
                    out.push(name);
                }
            }
        }
        Ok(out)
    };
    for name in names(data_dir)? {
        if name.starts_with("search-index.") && name.ends_with(".tmp") {
            remove(&data_dir.join(&name), "a search index snapshot's temporary file");
        }
    }
    let mut st = conn.prepare("SELECT 1 FROM shapes WHERE id = ?1").map_err(db_err)?;
    for name in names(shape_dir)? {
        if temporary(&name) {
            remove(&shape_dir.join(&name), "an upload's temporary file");
        } else if ShapeId::parse(&name).is_some() && !st.exists([&name]).map_err(db_err)? {
            remove(&shape_dir.join(&name), "an upload without its shape record (never acknowledged)");
        }
    }
    let results = data_dir.join("results");
    if results.is_dir() {
        let all = names(&results)?;
        for name in &all {
            if temporary(name) {
                remove(&results.join(name), "a result's temporary file");
                continue;
            }
            // `{id}.{pid}.{seq}.f64`: kept while its result's record names it.
            let Some(stem) = name.strip_suffix(".f64") else { continue };
            let Some((id, _)) = stem.split_once('.') else { continue };
            let meta = results.join(format!("{id}.result.json"));
            let named = match std::fs::read(&meta) {
                Ok(bytes) => serde_json::from_slice::<serde_json::Value>(&bytes)
                    .ok()
                    .is_none_or(|m| m["values_file"].as_str().is_none_or(|v| v == name)),
                Err(e) if e.kind() == std::io::ErrorKind::NotFound => false,
                // Unreadable now: kept.
                Err(_) => true,
            };
            if !named {
                remove(&results.join(name), "a result's numbers that no result names");
            }
        }
    }
    Ok(removed)
}

/// The queue's columns on a jobs table of an older version (id and view only): added, and filled from the views.
fn migrate_jobs(conn: &rusqlite::Connection) -> std::io::Result<()> {
    let has_status: bool = conn
        .prepare("SELECT 1 FROM pragma_table_info('jobs') WHERE name = 'status'")
        .and_then(|mut st| st.exists([]))
        .map_err(db_err)?;
    if !has_status {
        conn.execute_batch(
            "BEGIN;
             ALTER TABLE jobs ADD COLUMN status TEXT NOT NULL DEFAULT 'enqueued';
             ALTER TABLE jobs ADD COLUMN owner TEXT;
             ALTER TABLE jobs ADD COLUMN lease_until INTEGER NOT NULL DEFAULT 0;
             ALTER TABLE jobs ADD COLUMN cancel INTEGER NOT NULL DEFAULT 0;
             UPDATE jobs SET status = COALESCE(json_extract(view, '$.status'), 'failed');
             COMMIT;",
        )
        .map_err(db_err)?;
    }
    conn.execute_batch("CREATE INDEX IF NOT EXISTS jobs_status ON jobs (status, seq);").map_err(db_err)?;
    Ok(())
}

const ID_LOCKS: usize = 64;

fn db_err(e: rusqlite::Error) -> std::io::Error {
    std::io::Error::other(format!("sqlite: {e}"))
}

impl Database {
    pub fn open(data_dir: &Path, max_vertices: usize, cache_bytes: usize) -> std::io::Result<Self> {
        Self::open_with_clock(data_dir, max_vertices, cache_bytes, Arc::new(SystemClock::default()))
    }
    /// [`Database::open`] with the clock its leases are read from (the tests' [`crate::service::jobs::ManualClock`]).
    pub fn open_with_clock(
        data_dir: &Path,
        max_vertices: usize,
        cache_bytes: usize,
        clock: Arc<dyn Clock>,
    ) -> std::io::Result<Self> {
        let shape_dir = data_dir.join("shapes");
        std::fs::create_dir_all(&shape_dir)?;
        let (lock, took_lock) = lock_dir(data_dir)?;
        let conn = rusqlite::Connection::open(data_dir.join("kac.sqlite3")).map_err(db_err)?;
        conn.execute_batch(
            "PRAGMA journal_mode = WAL;
             PRAGMA synchronous = FULL;
             PRAGMA busy_timeout = 5000;
             CREATE TABLE IF NOT EXISTS shapes (
                 id TEXT PRIMARY KEY, format TEXT NOT NULL, created_at TEXT NOT NULL,
                 bytes INTEGER NOT NULL, summary TEXT NOT NULL);
             CREATE TABLE IF NOT EXISTS jobs (
                 seq INTEGER PRIMARY KEY AUTOINCREMENT, id TEXT UNIQUE NOT NULL, view TEXT NOT NULL);
             CREATE TABLE IF NOT EXISTS fingerprints (
                 family TEXT NOT NULL, shape_id TEXT NOT NULL, fingerprint BLOB NOT NULL,
                 PRIMARY KEY (family, shape_id));
             CREATE TABLE IF NOT EXISTS fingerprint_log (
                 seq INTEGER PRIMARY KEY AUTOINCREMENT, family TEXT NOT NULL, shape_id TEXT NOT NULL,
                 fingerprint BLOB);
             CREATE TABLE IF NOT EXISTS shape_tags (
                 shape_id TEXT NOT NULL, tag TEXT NOT NULL, PRIMARY KEY (shape_id, tag));
             CREATE TABLE IF NOT EXISTS meta (key TEXT PRIMARY KEY, value TEXT NOT NULL);
             INSERT OR IGNORE INTO meta (key, value) VALUES ('store_id', lower(hex(randomblob(16))));",
        )
        .map_err(db_err)?;
        migrate_jobs(&conn)?;
        if took_lock {
            let removed = sweep_leftovers(data_dir, &shape_dir, &conn)?;
            if removed > 0 {
                tracing::warn!(removed, "leftovers of interrupted writes removed from the data directory");
            }
        }
        Ok(Database {
            clock,
            _lock: lock,
            changes: tokio::sync::broadcast::channel(1024).0,
            conn: Mutex::new(conn),
            shape_dir,
            id_locks: std::array::from_fn(|_| Mutex::new(())),
            parsed: Mutex::new(ByteLru::new(cache_bytes)),
            max_vertices,
        })
    }
    fn conn(&self) -> std::sync::MutexGuard<'_, rusqlite::Connection> {
        self.conn.lock().unwrap_or_else(|e| e.into_inner())
    }
    /// The lock of `id`'s stripe (ids are hex digests: their first bytes are uniform).
    fn id_lock(&self, id: &str) -> std::sync::MutexGuard<'_, ()> {
        let h = id.bytes().take(8).fold(0usize, |h, b| h.wrapping_mul(31).wrapping_add(b as usize));
        self.id_locks[h % ID_LOCKS].lock().unwrap_or_else(|e| e.into_inner())
    }
    fn record(&self, id: &str) -> std::io::Result<Option<ShapeRecord>> {
        let c = self.conn();
        c.query_row("SELECT id, format, created_at, bytes, summary FROM shapes WHERE id = ?1", [id], row_record)
            .optional()
            .map_err(db_err)
    }
}

fn row_record(r: &rusqlite::Row<'_>) -> rusqlite::Result<ShapeRecord> {
    let summary: String = r.get(4)?;
    Ok(ShapeRecord {
        id: r.get(0)?,
        format: r.get(1)?,
        created_at: r.get(2)?,
        bytes: r.get::<_, i64>(3)? as usize,
        summary: serde_json::from_str(&summary).unwrap_or(Value::Null),
    })
}

impl ShapeStore for Database {
    fn insert(&self, shape: StoredShape, original: &[u8]) -> std::io::Result<(bool, Arc<StoredShape>)> {
        let path = file_in(&self.shape_dir, &shape.id)?;
        // Twice at most: a shape stored under this id (record and file) is returned as it is; if it cannot be
        // read back (its file lost or unreadable, or removed in between), the second round stores this upload.
        for force in [false, true] {
            {
                // One writer per id from the check to the record: the first upload's file and record win
                // together, and every other caller gets the stored shape (in the first one's format) back.
                let _id = self.id_lock(&shape.id);
                if force || self.record(&shape.id)?.is_none() || !path.exists() {
                    // The upload first (atomically), then its record: a crash between leaves an unreferenced file
                    // only, which the next upload of that id replaces.
                    write_atomic(&path, original)?;
                    let r = &shape.record;
                    self.conn()
                        .execute(
                            "INSERT INTO shapes (id, format, created_at, bytes, summary) VALUES (?1, ?2, ?3, ?4, ?5)
                             ON CONFLICT(id) DO UPDATE SET format = excluded.format, bytes = excluded.bytes,
                             summary = excluded.summary",
                            rusqlite::params![r.id, r.format, r.created_at, r.bytes as i64, r.summary.to_string()],
                        )
                        .map_err(db_err)?;
                    let s = Arc::new(shape);
                    self.parsed.lock().unwrap_or_else(|e| e.into_inner()).put(&s.id, s.clone(), shape_size(&s));
                    return Ok((true, s));
                }
            }
            if let Some(existing) = ShapeStore::get(self, &shape.validated.id)? {
                return Ok((false, existing));
            }
        }
        unreachable!("the forced round stores the shape or returns its error")
    }
    fn get(&self, id: &ShapeId) -> std::io::Result<Option<Arc<StoredShape>>> {
        let id = &*id.hex();
        if let Some(s) = self.parsed.lock().unwrap_or_else(|e| e.into_inner()).get(id) {
            return Ok(Some(s));
        }
        let Some(record) = self.record(id)? else { return Ok(None) };
        // A record whose upload was lost (or no longer parses) is not a stored shape: the next upload of the id
        // stores it again.
        let bytes = match std::fs::read(file_in(&self.shape_dir, id)?) {
            Ok(b) => b,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
            Err(e) => return Err(e),
        };
        let Some(s) = parse_shape(record, &bytes, self.max_vertices) else { return Ok(None) };
        let s = Arc::new(s);
        // Cached only if still stored: a removal that ran while this parsed must not be undone by the cache.
        let _id = self.id_lock(id);
        if self.record(id)?.is_none() {
            return Ok(None);
        }
        self.parsed.lock().unwrap_or_else(|e| e.into_inner()).put(id, s.clone(), shape_size(&s));
        Ok(Some(s))
    }
    fn list(&self, offset: usize, limit: usize) -> std::io::Result<(Vec<ShapeRecord>, usize)> {
        let c = self.conn();
        let total: i64 = c.query_row("SELECT COUNT(*) FROM shapes", [], |r| r.get(0)).map_err(db_err)?;
        let mut st = c
            .prepare("SELECT id, format, created_at, bytes, summary FROM shapes ORDER BY id LIMIT ?1 OFFSET ?2")
            .map_err(db_err)?;
        let rows = st.query_map([limit as i64, offset as i64], row_record).map_err(db_err)?;
        Ok((rows.collect::<Result<_, _>>().map_err(db_err)?, total as usize))
    }
    fn remove(&self, id: &ShapeId) -> std::io::Result<bool> {
        let id = &*id.hex();
        let _id = self.id_lock(id);
        let n = {
            let mut c = self.conn();
            let tx = c.transaction().map_err(db_err)?;
            let n = tx.execute("DELETE FROM shapes WHERE id = ?1", [id]).map_err(db_err)?;
            tx.execute("DELETE FROM fingerprints WHERE shape_id = ?1", [id]).map_err(db_err)?;
            tx.execute("DELETE FROM shape_tags WHERE shape_id = ?1", [id]).map_err(db_err)?;
            if n > 0 {
                tx.execute("INSERT INTO fingerprint_log (family, shape_id, fingerprint) VALUES ('', ?1, NULL)", [id])
                    .map_err(db_err)?;
            }
            tx.commit().map_err(db_err)?;
            n
        };
        self.parsed.lock().unwrap_or_else(|e| e.into_inner()).remove(id);
        let _ = std::fs::remove_file(file_in(&self.shape_dir, id)?);
        Ok(n > 0)
    }
    fn healthy(&self) -> bool {
        self.conn().query_row("SELECT 1", [], |r| r.get::<_, i64>(0)).is_ok()
    }
}

impl FingerprintStore for Database {
    fn put_fingerprint(&self, family: &str, shape_id: &str, values: &[f64]) -> std::io::Result<bool> {
        // Little-endian f64s: 8 bytes a value, exact. Under the shape's lock and only while it is stored, so a
        // shape deleted while its analysis ran leaves no fingerprint behind.
        let blob: Vec<u8> = values.iter().flat_map(|v| v.to_le_bytes()).collect();
        let _id = self.id_lock(shape_id);
        let mut c = self.conn();
        let tx = c.transaction().map_err(db_err)?;
        let n = tx
            .execute(
                "INSERT INTO fingerprints (family, shape_id, fingerprint)
                 SELECT ?1, ?2, ?3 WHERE EXISTS (SELECT 1 FROM shapes WHERE id = ?2)
                 ON CONFLICT(family, shape_id) DO UPDATE SET fingerprint = excluded.fingerprint",
                rusqlite::params![family, shape_id, blob],
            )
            .map_err(db_err)?;
        if n > 0 {
            tx.execute(
                "INSERT INTO fingerprint_log (family, shape_id, fingerprint) VALUES (?1, ?2, ?3)",
                rusqlite::params![family, shape_id, blob],
            )
            .map_err(db_err)?;
        }
        tx.commit().map_err(db_err)?;
        Ok(n > 0)
    }
    fn fingerprint_counts(&self) -> std::io::Result<Vec<(String, usize)>> {
        let c = self.conn();
        let mut st = c.prepare("SELECT family, COUNT(*) FROM fingerprints GROUP BY family").map_err(db_err)?;
        let rows = st.query_map([], |r| Ok((r.get(0)?, r.get::<_, i64>(1)? as usize))).map_err(db_err)?;
        rows.collect::<Result<_, _>>().map_err(db_err)
    }
    fn for_each_fingerprint(&self, f: &mut dyn FnMut(&str, &str, &[f64])) -> std::io::Result<()> {
        let c = self.conn();
        let mut st = c.prepare("SELECT family, shape_id, fingerprint FROM fingerprints").map_err(db_err)?;
        let mut rows = st.query([]).map_err(db_err)?;
        let mut values = vec![];
        while let Some(r) = rows.next().map_err(db_err)? {
            let (family, id) = (r.get_ref(0).map_err(db_err)?, r.get_ref(1).map_err(db_err)?);
            let (family, id) =
                (family.as_str().map_err(std::io::Error::other)?, id.as_str().map_err(std::io::Error::other)?);
            let blob = r.get_ref(2).map_err(db_err)?.as_blob().map_err(std::io::Error::other)?;
            values.clear();
            values.extend(blob.chunks_exact(8).map(|b| f64::from_le_bytes(b.try_into().unwrap_or([0; 8]))));
            f(family, id, &values);
        }
        Ok(())
    }
    fn fingerprints_of(&self, family: &str, shape_ids: &[String]) -> std::io::Result<HashMap<String, Vec<f64>>> {
        let c = self.conn();
        let mut st = c
            .prepare_cached("SELECT fingerprint FROM fingerprints WHERE family = ?1 AND shape_id = ?2")
            .map_err(db_err)?;
        let mut out = HashMap::new();
        for id in shape_ids {
            let blob: Option<Vec<u8>> =
                st.query_row(rusqlite::params![family, id], |r| r.get(0)).optional().map_err(db_err)?;
            if let Some(b) = blob {
                out.insert(id.clone(), f64s_of(&b));
            }
        }
        Ok(out)
    }
    fn set_tags(&self, shape_id: &str, edit: &TagEdit) -> std::io::Result<TagsOutcome> {
        let _id = self.id_lock(shape_id);
        let mut c = self.conn();
        let tx = c.transaction().map_err(db_err)?;
        let stored = tx
            .query_row("SELECT 1 FROM shapes WHERE id = ?1", [shape_id], |_| Ok(()))
            .optional()
            .map_err(db_err)?
            .is_some();
        if !stored {
            return Ok(TagsOutcome::NotStored);
        }
        let current: Vec<String> = {
            let mut st = tx.prepare("SELECT tag FROM shape_tags WHERE shape_id = ?1").map_err(db_err)?;
            let rows = st.query_map([shape_id], |r| r.get(0)).map_err(db_err)?;
            rows.collect::<Result<_, _>>().map_err(db_err)?
        };
        let tags = match edit.apply(current) {
            Ok(t) => t,
            Err(n) => return Ok(TagsOutcome::TooMany(n)),
        };
        tx.execute("DELETE FROM shape_tags WHERE shape_id = ?1", [shape_id]).map_err(db_err)?;
        for t in &tags {
            tx.execute("INSERT INTO shape_tags (shape_id, tag) VALUES (?1, ?2)", [shape_id, t]).map_err(db_err)?;
        }
        tx.execute(
            "INSERT INTO fingerprint_log (family, shape_id, fingerprint) VALUES (?1, ?2, ?3)",
            rusqlite::params![TAGS_ENTRY, shape_id, tags_blob(&tags)],
        )
        .map_err(db_err)?;
        tx.commit().map_err(db_err)?;
        Ok(TagsOutcome::Set(tags))
    }
    fn tags_of(&self, shape_id: &str) -> std::io::Result<Vec<String>> {
        let c = self.conn();
        let mut st = c.prepare_cached("SELECT tag FROM shape_tags WHERE shape_id = ?1 ORDER BY tag").map_err(db_err)?;
        let rows = st.query_map([shape_id], |r| r.get(0)).map_err(db_err)?;
        rows.collect::<Result<_, _>>().map_err(db_err)
    }
    fn for_each_tag(&self, f: &mut dyn FnMut(&str, &str)) -> std::io::Result<()> {
        let c = self.conn();
        let mut st = c.prepare("SELECT shape_id, tag FROM shape_tags").map_err(db_err)?;
        let mut rows = st.query([]).map_err(db_err)?;
        while let Some(r) = rows.next().map_err(db_err)? {
            f(
                r.get_ref(0).map_err(db_err)?.as_str().map_err(std::io::Error::other)?,
                r.get_ref(1).map_err(db_err)?.as_str().map_err(std::io::Error::other)?,
            );
        }
        Ok(())
    }
    fn fingerprint_log_end(&self) -> std::io::Result<i64> {
        self.conn().query_row("SELECT COALESCE(MAX(seq), 0) FROM fingerprint_log", [], |r| r.get(0)).map_err(db_err)
    }
    fn tag_count(&self) -> std::io::Result<usize> {
        let n: i64 = self.conn().query_row("SELECT COUNT(*) FROM shape_tags", [], |r| r.get(0)).map_err(db_err)?;
        Ok(n as usize)
    }
    fn store_identity(&self) -> std::io::Result<String> {
        self.conn().query_row("SELECT value FROM meta WHERE key = 'store_id'", [], |r| r.get(0)).map_err(db_err)
    }
    fn fingerprint_log_entry(&self, seq: i64) -> std::io::Result<Option<String>> {
        self.conn()
            .query_row("SELECT shape_id FROM fingerprint_log WHERE seq = ?1", [seq], |r| r.get(0))
            .optional()
            .map_err(db_err)
    }
    fn fingerprint_changes(&self, after: i64) -> std::io::Result<(Vec<FingerprintChange>, i64)> {
        let c = self.conn();
        let mut st = c
            .prepare("SELECT seq, family, shape_id, fingerprint FROM fingerprint_log WHERE seq > ?1 ORDER BY seq")
            .map_err(db_err)?;
        let mut end = after;
        let rows = st
            .query_map([after], |r| {
                let blob: Option<Vec<u8>> = r.get(3)?;
                Ok((r.get::<_, i64>(0)?, FingerprintChange::of_row(r.get(1)?, r.get(2)?, blob.as_deref())))
            })
            .map_err(db_err)?;
        let mut out = vec![];
        for row in rows {
            let (seq, change) = row.map_err(db_err)?;
            end = seq;
            out.push(change);
        }
        Ok((out, end))
    }
}

fn view_of(text: &str) -> std::io::Result<JobView> {
    serde_json::from_str(text).map_err(std::io::Error::other)
}

fn status_name(v: &JobView) -> &'static str {
    v.status.name()
}

/// The job queue on SQLite: one row per job (its view as JSON beside the columns the queue works on), every
/// transition one statement or transaction under the connection's lock.
impl JobQueue for Database {
    fn enqueue(&self, view: JobView, capacity: usize) -> std::io::Result<Enqueued> {
        let mut c = self.conn();
        let tx = c.transaction().map_err(db_err)?;
        let existing: Option<String> =
            tx.query_row("SELECT view FROM jobs WHERE id = ?1", [&view.id], |r| r.get(0)).optional().map_err(db_err)?;
        if let Some(text) = &existing {
            let old = view_of(text)?;
            if !matches!(old.status, Status::Failed | Status::Canceled) {
                return Ok(Enqueued::Existing(old));
            }
        }
        let active: i64 = tx
            .query_row("SELECT COUNT(*) FROM jobs WHERE status IN ('enqueued', 'processing')", [], |r| r.get(0))
            .map_err(db_err)?;
        if active as usize >= capacity {
            return Ok(Enqueued::Full);
        }
        let text = serde_json::to_string(&view).map_err(std::io::Error::other)?;
        // A failed or canceled job enqueued again goes to the back of the queue (a new row, a new seq).
        tx.execute("DELETE FROM jobs WHERE id = ?1", [&view.id]).map_err(db_err)?;
        tx.execute(
            "INSERT INTO jobs (id, view, status, owner, lease_until, cancel) VALUES (?1, ?2, 'enqueued', NULL, 0, 0)",
            rusqlite::params![view.id, text],
        )
        .map_err(db_err)?;
        tx.commit().map_err(db_err)?;
        drop(c);
        let _ = self.changes.send(view.id.clone());
        Ok(Enqueued::New(view))
    }
    fn claim(&self, owner: &str, lease: Duration) -> std::io::Result<Option<JobView>> {
        self.claim_where(None, owner, lease)
    }
    fn claim_id(&self, id: &str, owner: &str, lease: Duration) -> std::io::Result<Option<JobView>> {
        self.claim_where(Some(id), owner, lease)
    }
    fn heartbeat(&self, id: &str, owner: &str, progress: &JobProgress, lease: Duration) -> std::io::Result<Lease> {
        let c = self.conn();
        let row: Option<(String, i64)> = c
            .query_row(
                "SELECT view, cancel FROM jobs WHERE id = ?1 AND owner = ?2 AND status = 'processing'",
                [id, owner],
                |r| Ok((r.get(0)?, r.get(1)?)),
            )
            .optional()
            .map_err(db_err)?;
        let Some((text, cancel)) = row else { return Ok(Lease::Lost) };
        let mut view = view_of(&text)?;
        view.progress = progress.clone();
        let text = serde_json::to_string(&view).map_err(std::io::Error::other)?;
        c.execute(
            "UPDATE jobs SET lease_until = ?3, view = ?4 WHERE id = ?1 AND owner = ?2",
            rusqlite::params![id, owner, self.clock.wall_ms() + lease.as_millis() as i64, text],
        )
        .map_err(db_err)?;
        Ok(Lease::Held { cancel: cancel != 0 })
    }
    fn finish(&self, id: &str, owner: &str, view: &JobView) -> std::io::Result<bool> {
        let text = serde_json::to_string(view).map_err(std::io::Error::other)?;
        let n = self
            .conn()
            .execute(
                "UPDATE jobs SET status = ?3, view = ?4, owner = NULL WHERE id = ?1 AND owner = ?2 AND status = 'processing'",
                rusqlite::params![id, owner, status_name(view), text],
            )
            .map_err(db_err)?;
        if n > 0 {
            let _ = self.changes.send(id.to_string());
        }
        Ok(n > 0)
    }
    fn cancel(&self, id: &JobId, problem: &Problem) -> std::io::Result<Option<JobView>> {
        let id = &*id.hex();
        let mut c = self.conn();
        let tx = c.transaction().map_err(db_err)?;
        let row: Option<String> =
            tx.query_row("SELECT view FROM jobs WHERE id = ?1", [id], |r| r.get(0)).optional().map_err(db_err)?;
        let Some(text) = row else { return Ok(None) };
        let mut view = view_of(&text)?;
        match view.status {
            Status::Enqueued => {
                view.status = Status::Canceled;
                view.finished_at = Some(now());
                view.error = Some(problem.clone());
                let text = serde_json::to_string(&view).map_err(std::io::Error::other)?;
                tx.execute("UPDATE jobs SET status = 'canceled', view = ?2 WHERE id = ?1", rusqlite::params![id, text])
                    .map_err(db_err)?;
            }
            Status::Processing => {
                tx.execute("UPDATE jobs SET cancel = 1 WHERE id = ?1", [id]).map_err(db_err)?;
            }
            _ => return Ok(Some(view)),
        }
        tx.commit().map_err(db_err)?;
        drop(c);
        let _ = self.changes.send(id.to_string());
        Ok(Some(view))
    }
    fn requeue_expired(&self, held: &[String]) -> std::io::Result<Vec<String>> {
        self.requeue_where("lease_until < ?1", self.clock.wall_ms(), held)
    }
    fn recover(&self) -> std::io::Result<usize> {
        // The data directory belongs to this process: no other worker can hold a claim.
        self.requeue_where("?1 = ?1", 0, &[])?;
        Ok(self.depth()?.0)
    }
    fn get(&self, id: &JobId) -> std::io::Result<Option<JobView>> {
        let id = &*id.hex();
        let text: Option<String> = self
            .conn()
            .query_row("SELECT view FROM jobs WHERE id = ?1", [id], |r| r.get(0))
            .optional()
            .map_err(db_err)?;
        text.map(|t| view_of(&t)).transpose()
    }
    fn list(&self) -> std::io::Result<Vec<JobView>> {
        let c = self.conn();
        let mut st = c.prepare("SELECT view FROM jobs ORDER BY seq").map_err(db_err)?;
        let rows = st.query_map([], |r| r.get::<_, String>(0)).map_err(db_err)?;
        Ok(rows.flatten().filter_map(|v| serde_json::from_str(&v).ok()).collect())
    }
    fn counts(&self) -> std::io::Result<Vec<(String, usize)>> {
        let c = self.conn();
        let mut st = c.prepare("SELECT status, COUNT(*) FROM jobs GROUP BY status").map_err(db_err)?;
        let rows = st.query_map([], |r| Ok((r.get::<_, String>(0)?, r.get::<_, i64>(1)? as usize))).map_err(db_err)?;
        Ok(rows.flatten().collect())
    }
    fn waiting(&self, except: &str) -> std::io::Result<usize> {
        let c = self.conn();
        let n: i64 = c
            .query_row(
                "SELECT COUNT(*) FROM jobs WHERE status = 'enqueued' AND json_extract(view, '$.analysis') <> ?1",
                [except],
                |r| r.get(0),
            )
            .map_err(db_err)?;
        Ok(n as usize)
    }
    fn changes(&self) -> tokio::sync::broadcast::Receiver<String> {
        self.changes.subscribe()
    }
}

impl Database {
    /// Claims the oldest enqueued job, or `only` if it is enqueued.
    fn claim_where(&self, only: Option<&str>, owner: &str, lease: Duration) -> std::io::Result<Option<JobView>> {
        let mut c = self.conn();
        let tx = c.transaction().map_err(db_err)?;
        let next: Option<(String, String)> = tx
            .query_row(
                "SELECT id, view FROM jobs WHERE status = 'enqueued' AND (?1 IS NULL OR id = ?1) ORDER BY seq LIMIT 1",
                [only],
                |r| Ok((r.get(0)?, r.get(1)?)),
            )
            .optional()
            .map_err(db_err)?;
        let Some((id, text)) = next else { return Ok(None) };
        let mut view = view_of(&text)?;
        view.status = Status::Processing;
        view.started_at = Some(now());
        view.progress = JobProgress { phase: "operator".into(), converged: 0, wanted: 0 };
        let text = serde_json::to_string(&view).map_err(std::io::Error::other)?;
        tx.execute(
            "UPDATE jobs SET status = 'processing', owner = ?2, lease_until = ?3, view = ?4 WHERE id = ?1",
            rusqlite::params![id, owner, self.clock.wall_ms() + lease.as_millis() as i64, text],
        )
        .map_err(db_err)?;
        tx.commit().map_err(db_err)?;
        drop(c);
        let _ = self.changes.send(id);
        Ok(Some(view))
    }
    /// Requeues the processing jobs that meet `condition` (on `arg`), except those whose owner is in `held`.
    fn requeue_where(&self, condition: &str, arg: i64, held: &[String]) -> std::io::Result<Vec<String>> {
        let mut c = self.conn();
        let tx = c.transaction().map_err(db_err)?;
        let rows: Vec<(String, String, i64, Option<String>)> = {
            let mut st = tx
                .prepare(&format!(
                    "SELECT id, view, cancel, owner FROM jobs WHERE status = 'processing' AND {condition}"
                ))
                .map_err(db_err)?;
            let rows = st.query_map([arg], |r| Ok((r.get(0)?, r.get(1)?, r.get(2)?, r.get(3)?))).map_err(db_err)?;
            rows.collect::<Result<_, _>>().map_err(db_err)?
        };
        let mut ids = vec![];
        for (id, text, cancel, owner) in rows {
            if owner.is_some_and(|o| held.contains(&o)) {
                continue;
            }
            let mut view = view_of(&text)?;
            let status = super::queue::release(&mut view, cancel != 0);
            let text = serde_json::to_string(&view).map_err(std::io::Error::other)?;
            tx.execute(
                "UPDATE jobs SET status = ?3, owner = NULL, lease_until = 0, view = ?2 WHERE id = ?1",
                rusqlite::params![id, text, status.name()],
            )
            .map_err(db_err)?;
            ids.push(id);
        }
        tx.commit().map_err(db_err)?;
        drop(c);
        for id in &ids {
            let _ = self.changes.send(id.clone());
        }
        Ok(ids)
    }
}

/// Results as files (`DIR/results/{id}.json`), the recently used ones also in memory (bounded by bytes).
pub struct FileResults {
    dir: PathBuf,
    results: Mutex<ByteLru<StoredResult>>,
}

impl FileResults {
    pub fn open(data_dir: &Path, cache_bytes: usize) -> std::io::Result<Self> {
        let dir = data_dir.join("results");
        std::fs::create_dir_all(&dir)?;
        Ok(FileResults { dir, results: Mutex::new(ByteLru::new(cache_bytes)) })
    }
}

/// Writes a file atomically: a temporary file beside it (named uniquely, so simultaneous writers of one path never
/// share one), fsync, rename, fsync of the directory. Readers see the old file or the whole new one, never a part,
/// and a crash at any moment leaves one of the two.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    static SEQ: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
    let seq = SEQ.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let tmp = path.with_extension(format!("tmp.{}.{seq}", std::process::id()));
    let written = (|| {
        let mut f = std::fs::File::create(&tmp)?;
        f.write_all(bytes)?;
        f.sync_all()?;
        std::fs::rename(&tmp, path)
    })();
    if written.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    written?;
    if let Some(dir) = path.parent() {
        // The rename itself made durable (where the platform allows opening a directory).
        if let Ok(d) = std::fs::File::open(dir) {
            let _ = d.sync_all();
        }
    }
    Ok(())
}

/// Creates a file with these bytes unless it exists (false then): the bytes go to a temporary file beside it
/// (fsync), which is hard-linked to the path (the link fails if the path exists, so of simultaneous writers one
/// wins and the others leave it as it is), then removed; the directory is synced.
pub fn write_once(path: &Path, bytes: &[u8]) -> std::io::Result<bool> {
    if path.exists() {
        return Ok(false);
    }
    static SEQ: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
    let seq = SEQ.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let tmp = path.with_extension(format!("new.{}.{seq}", std::process::id()));
    let linked = (|| {
        let mut f = std::fs::File::create(&tmp)?;
        f.write_all(bytes)?;
        f.sync_all()?;
        match std::fs::hard_link(&tmp, path) {
            Ok(()) => Ok(true),
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => Ok(false),
            Err(e) => Err(e),
        }
    })();
    let _ = std::fs::remove_file(&tmp);
    if linked? {
        if let Some(dir) = path.parent() {
            if let Ok(d) = std::fs::File::open(dir) {
                let _ = d.sync_all();
            }
        }
        return Ok(true);
    }
    Ok(false)
}

/// A result's files: `{id}.result.json` (its ETag, summary and arrays' shapes; written once, last) and
/// `{id}.{etag}.f64` (the numbers, little-endian float64, written first; named by the ETag, so two writers of one
/// id never write one file). `{id}.json` is a result written by an earlier version (its whole body).
impl ResultStore for FileResults {
    fn put(&self, result: Arc<StoredResult>) -> std::io::Result<Arc<StoredResult>> {
        let meta_path = file_in(&self.dir, &format!("{}.result.json", result.id))?;
        if !meta_path.exists() && !file_in(&self.dir, &format!("{}.json", result.id))?.exists() {
            // The numbers under a name of this writer's own (two writers of one id never share a file), which the
            // meta names; the meta is created once, last.
            static SEQ: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
            let seq = SEQ.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
            let name = format!("{}.{}.{}.f64", result.id, std::process::id(), seq);
            let values_path = file_in(&self.dir, &name)?;
            blocking(|| write_values(&values_path, &result))?;
            let mut meta = result.meta();
            meta["values_file"] = name.into();
            let meta = serde_json::to_vec(&meta).map_err(std::io::Error::other)?;
            if write_once(&meta_path, &meta)? {
                self.results.lock().unwrap_or_else(|e| e.into_inner()).put(
                    &result.id,
                    result.clone(),
                    result_size(&result),
                );
                return Ok(result);
            }
            // Another writer stored this id first: its result stays, these numbers go.
            let _ = std::fs::remove_file(&values_path);
        }
        // Written once: the result stored under the id (the same request computed again) stays.
        let id = JobId::parse(&result.id).ok_or_else(|| std::io::Error::other("a result id that is not a job id"))?;
        self.get(&id)?.ok_or_else(|| std::io::Error::other("the stored result went missing"))
    }
    fn get(&self, id: &ResultId) -> std::io::Result<Option<Arc<StoredResult>>> {
        let id = &*id.hex();
        if let Some(r) = self.results.lock().unwrap_or_else(|e| e.into_inner()).get(id) {
            return Ok(Some(r));
        }
        let not_found = |e: &std::io::Error| e.kind() == std::io::ErrorKind::NotFound;
        let r = match std::fs::read(file_in(&self.dir, &format!("{id}.result.json"))?) {
            Ok(meta) => {
                let meta: Value = serde_json::from_slice(&meta).map_err(std::io::Error::other)?;
                let name = meta["values_file"].as_str().unwrap_or("");
                if name.contains('/') || !name.starts_with(id) {
                    return Err(std::io::Error::other(format!("the stored result {id} names no numbers file")));
                }
                let mut f = std::io::BufReader::with_capacity(1 << 20, std::fs::File::open(file_in(&self.dir, name)?)?);
                blocking(|| StoredResult::from_meta(id, &meta, |data| read_values(&mut f, data)))?
            }
            Err(e) if not_found(&e) => match std::fs::read(file_in(&self.dir, &format!("{id}.json"))?) {
                Ok(body) => blocking(|| StoredResult::parse_legacy(id, &body))
                    .ok_or_else(|| std::io::Error::other(format!("the stored result {id} does not parse")))?,
                Err(e) if not_found(&e) => return Ok(None),
                Err(e) => return Err(e),
            },
            Err(e) => return Err(e),
        };
        let r = Arc::new(r);
        self.results.lock().unwrap_or_else(|e| e.into_inner()).put(id, r.clone(), result_size(&r));
        Ok(Some(r))
    }
    fn remove(&self, id: &ResultId) -> std::io::Result<bool> {
        let id = &*id.hex();
        self.results.lock().unwrap_or_else(|e| e.into_inner()).remove(id);
        let meta_path = file_in(&self.dir, &format!("{id}.result.json"))?;
        let meta = match std::fs::read(&meta_path) {
            Ok(m) => m,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(false),
            Err(e) => return Err(e),
        };
        // The meta first: a result whose meta is gone is not stored, whatever became of its numbers.
        std::fs::remove_file(&meta_path)?;
        let meta: Value = serde_json::from_slice(&meta).unwrap_or_default();
        if let Some(name) = meta["values_file"].as_str().filter(|n| !n.contains('/') && n.starts_with(id)) {
            let _ = std::fs::remove_file(file_in(&self.dir, name)?);
        }
        Ok(true)
    }
}

/// Writes a result's numbers to a file atomically, a megabyte at a time.
fn write_values(path: &Path, r: &StoredResult) -> std::io::Result<()> {
    static SEQ: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
    let seq = SEQ.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let tmp = path.with_extension(format!("tmp.{}.{seq}", std::process::id()));
    let written = (|| {
        let mut f = std::io::BufWriter::new(std::fs::File::create(&tmp)?);
        for chunk in r.value_chunks(1 << 20) {
            f.write_all(&chunk)?;
        }
        f.into_inner().map_err(|e| e.into_error())?.sync_all()?;
        std::fs::rename(&tmp, path)
    })();
    if written.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    written
}

/// Fills `data` with the next little-endian float64s of a reader.
pub(crate) fn read_values(f: &mut impl std::io::Read, data: &mut [f64]) -> std::io::Result<()> {
    let mut buf = vec![0u8; 1 << 20];
    for part in data.chunks_mut(1 << 17) {
        let bytes = &mut buf[..part.len() * 8];
        f.read_exact(bytes)?;
        for (v, b) in part.iter_mut().zip(bytes.chunks_exact(8)) {
            *v = f64::from_le_bytes(b.try_into().unwrap_or([0; 8]));
        }
    }
    Ok(())
}
