//! The embedded backend: SQLite (bundled build, WAL journal, synchronous FULL) for shape records, fingerprints and
//! the job queue; uploads and results as content-addressed files in the data directory, written atomically.

use super::*;
use crate::clock::{Clock, SystemClock};
use crate::failure::Failure;
use crate::ids::{file_in, BatchId, JobId};
use crate::record::{now, BatchProgress, JobProgress, Status};
use rusqlite::OptionalExtension;
use std::io::Write;
use std::time::Duration;

mod fingerprints;
mod queue;
mod results;
mod shapes;
pub(crate) use results::read_values;
pub use results::{write_atomic, FileResults};
use shapes::row_record;

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

/// The queue's columns on a jobs table of an older version (id and view only, or no lane): added, and filled from
/// the views.
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
    // The lane (0 run, 1 backlog: [`Lane::rank`]); the jobs of a data directory from before lanes ran in the run
    // lane.
    let has_lane: bool = conn
        .prepare("SELECT 1 FROM pragma_table_info('jobs') WHERE name = 'lane'")
        .and_then(|mut st| st.exists([]))
        .map_err(db_err)?;
    if !has_lane {
        conn.execute_batch("ALTER TABLE jobs ADD COLUMN lane INTEGER NOT NULL DEFAULT 0;").map_err(db_err)?;
    }
    // The claim's order (run lane first, then submission) and the lanes' counts read from one index.
    conn.execute_batch(
        "CREATE INDEX IF NOT EXISTS jobs_status ON jobs (status, seq);
         CREATE INDEX IF NOT EXISTS jobs_claim ON jobs (status, lane, seq);",
    )
    .map_err(db_err)?;
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
    /// [`Database::open`] with the clock its leases are read from (the tests' [`crate::clock::ManualClock`]).
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
             CREATE TABLE IF NOT EXISTS batches (id TEXT PRIMARY KEY, created_at TEXT NOT NULL);
             CREATE TABLE IF NOT EXISTS batch_jobs (
                 batch TEXT NOT NULL, position INTEGER NOT NULL, job TEXT NOT NULL, PRIMARY KEY (batch, position));
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
