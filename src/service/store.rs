//! Storage behind traits, so that a shared backend can replace the embedded one without touching handlers.
//! This module holds the embedded defaults: shapes in memory, results in memory and as content-addressed JSON
//! files in the data directory (written atomically: temporary file, fsync, rename), and a byte-bounded cache of
//! eigenpairs.

use super::jobs::JobView;
use crate::analysis::{Eigen, SpectrumCache, VertexArray};
use kac_core::Validated;
use serde_json::Value;
use std::collections::HashMap;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

/// A map bounded by bytes: the least recently used entries go first. Values are shared (`Arc`).
pub struct ByteLru<V> {
    limit: usize,
    map: HashMap<String, (Arc<V>, usize, u64)>,
    bytes: usize,
    clock: u64,
}

impl<V> ByteLru<V> {
    pub fn new(limit: usize) -> Self {
        ByteLru { limit, map: HashMap::new(), bytes: 0, clock: 0 }
    }
    pub fn get(&mut self, key: &str) -> Option<Arc<V>> {
        self.clock += 1;
        let clock = self.clock;
        self.map.get_mut(key).map(|(v, _, used)| {
            *used = clock;
            v.clone()
        })
    }
    /// Keeps the value unless it alone is larger than the limit.
    pub fn put(&mut self, key: &str, value: Arc<V>, size: usize) {
        self.remove(key);
        if size > self.limit {
            return;
        }
        self.clock += 1;
        self.map.insert(key.to_string(), (value, size, self.clock));
        self.bytes += size;
        while self.bytes > self.limit {
            let Some(victim) = self.map.iter().min_by_key(|(_, (_, _, used))| *used).map(|(k, _)| k.clone()) else {
                break;
            };
            self.remove(&victim);
        }
    }
    pub fn remove(&mut self, key: &str) {
        if let Some((_, size, _)) = self.map.remove(key) {
            self.bytes -= size;
        }
    }
}

/// What is known of a stored shape without parsing it again.
#[derive(Debug, Clone)]
pub struct ShapeRecord {
    pub id: String,
    pub format: String,
    pub created_at: String,
    pub bytes: usize,
    /// The validation summary (`kac inspect`'s output).
    pub summary: Value,
}

/// A stored shape, parsed and validated.
pub struct StoredShape {
    pub record: ShapeRecord,
    pub validated: Validated,
}

impl std::ops::Deref for StoredShape {
    type Target = ShapeRecord;
    fn deref(&self) -> &ShapeRecord {
        &self.record
    }
}

pub trait ShapeStore: Send + Sync {
    /// Stores the shape (and its original bytes) unless one with its id exists; true if it was new.
    fn insert(&self, shape: StoredShape, original: &[u8]) -> std::io::Result<(bool, Arc<StoredShape>)>;
    fn get(&self, id: &str) -> Option<Arc<StoredShape>>;
    /// Records in id order from `offset`, at most `limit`, and the total.
    fn list(&self, offset: usize, limit: usize) -> (Vec<ShapeRecord>, usize);
    fn remove(&self, id: &str) -> bool;
    /// Whether the storage answers (for readiness).
    fn healthy(&self) -> bool;
}

/// Shape-DNA fingerprints of stored shapes, by family (the parameters they were computed with), kept as shapes
/// are analysed so that a search compares against every shape the service holds.
pub trait FingerprintStore: Send + Sync {
    /// Inserts or replaces one shape's fingerprint in a family, if the shape is still stored (true then).
    fn put_fingerprint(&self, family: &str, shape_id: &str, values: &[f64]) -> std::io::Result<bool>;
    /// Every fingerprint: (family, shape id, values).
    fn load_fingerprints(&self) -> std::io::Result<Vec<(String, String, Vec<f64>)>>;
}

/// Job records as clients see them, kept so that a restart loses no accepted job.
pub trait JobStore: Send + Sync {
    /// Inserts or replaces a job's record.
    fn save(&self, job: &JobView) -> std::io::Result<()>;
    /// Every job, in submission order.
    fn load_all(&self) -> std::io::Result<Vec<JobView>>;
}

/// The embedded database: SQLite (bundled build, WAL journal, synchronous FULL) for shape and job records, and
/// the original uploads as content-addressed files (`DIR/shapes/{id}`), parsed again on first use after a
/// restart.
pub struct Database {
    conn: Mutex<rusqlite::Connection>,
    shape_dir: PathBuf,
    /// Locks striped by shape id: an insert or removal of one id (its file and its record together) runs alone, so
    /// simultaneous uploads of one shape, in one format or several, store one file and one record that agree.
    id_locks: [Mutex<()>; ID_LOCKS],
    /// Parsed shapes in memory, bounded by (about) their size.
    parsed: Mutex<ByteLru<StoredShape>>,
    max_vertices: usize,
}

/// Bytes a parsed shape holds, about: its upload counts twice (geometry plus topology and the report).
fn shape_size(s: &StoredShape) -> usize {
    2 * s.bytes + 48 * s.validated.shape.vertex_count()
}

const ID_LOCKS: usize = 64;

fn db_err(e: rusqlite::Error) -> std::io::Error {
    std::io::Error::other(format!("sqlite: {e}"))
}

impl Database {
    pub fn open(data_dir: &Path, max_vertices: usize, cache_bytes: usize) -> std::io::Result<Self> {
        let shape_dir = data_dir.join("shapes");
        std::fs::create_dir_all(&shape_dir)?;
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
                 PRIMARY KEY (family, shape_id));",
        )
        .map_err(db_err)?;
        Ok(Database {
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
    fn record(&self, id: &str) -> Option<ShapeRecord> {
        let c = self.conn();
        c.query_row("SELECT id, format, created_at, bytes, summary FROM shapes WHERE id = ?1", [id], row_record).ok()
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
        let path = self.shape_dir.join(&shape.id);
        // Twice at most: a shape stored under this id (record and file) is returned as it is; if it cannot be
        // read back (its file lost or unreadable, or removed in between), the second round stores this upload.
        for force in [false, true] {
            {
                // One writer per id from the check to the record: the first upload's file and record win
                // together, and every other caller gets the stored shape (in the first one's format) back.
                let _id = self.id_lock(&shape.id);
                if force || self.record(&shape.id).is_none() || !path.exists() {
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
            if let Some(existing) = self.get(&shape.id) {
                return Ok((false, existing));
            }
        }
        unreachable!("the forced round stores the shape or returns its error")
    }
    fn get(&self, id: &str) -> Option<Arc<StoredShape>> {
        if let Some(s) = self.parsed.lock().unwrap_or_else(|e| e.into_inner()).get(id) {
            return Some(s);
        }
        let record = self.record(id)?;
        let bytes = std::fs::read(self.shape_dir.join(id)).ok()?;
        let format = kac_core::Format::from_name(&record.format)?;
        let read = kac_core::ReadOptions { max_vertices: self.max_vertices.max(1), ..Default::default() };
        let validated = kac_core::load_bytes(&bytes, format, &read, &Default::default()).ok()?;
        let s = Arc::new(StoredShape { record, validated });
        // Cached only if still stored: a removal that ran while this parsed must not be undone by the cache.
        let _id = self.id_lock(id);
        self.record(id)?;
        self.parsed.lock().unwrap_or_else(|e| e.into_inner()).put(id, s.clone(), shape_size(&s));
        Some(s)
    }
    fn list(&self, offset: usize, limit: usize) -> (Vec<ShapeRecord>, usize) {
        let c = self.conn();
        let total: i64 = c.query_row("SELECT COUNT(*) FROM shapes", [], |r| r.get(0)).unwrap_or(0);
        let mut out = vec![];
        if let Ok(mut st) =
            c.prepare("SELECT id, format, created_at, bytes, summary FROM shapes ORDER BY id LIMIT ?1 OFFSET ?2")
        {
            if let Ok(rows) = st.query_map([limit as i64, offset as i64], row_record) {
                out = rows.flatten().collect();
            }
        }
        (out, total as usize)
    }
    fn remove(&self, id: &str) -> bool {
        let _id = self.id_lock(id);
        let n = self.conn().execute("DELETE FROM shapes WHERE id = ?1", [id]).unwrap_or(0);
        let _ = self.conn().execute("DELETE FROM fingerprints WHERE shape_id = ?1", [id]);
        self.parsed.lock().unwrap_or_else(|e| e.into_inner()).remove(id);
        let _ = std::fs::remove_file(self.shape_dir.join(id));
        n > 0
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
        let n = self
            .conn()
            .execute(
                "INSERT INTO fingerprints (family, shape_id, fingerprint)
                 SELECT ?1, ?2, ?3 WHERE EXISTS (SELECT 1 FROM shapes WHERE id = ?2)
                 ON CONFLICT(family, shape_id) DO UPDATE SET fingerprint = excluded.fingerprint",
                rusqlite::params![family, shape_id, blob],
            )
            .map_err(db_err)?;
        Ok(n > 0)
    }
    fn load_fingerprints(&self) -> std::io::Result<Vec<(String, String, Vec<f64>)>> {
        let c = self.conn();
        let mut st = c.prepare("SELECT family, shape_id, fingerprint FROM fingerprints").map_err(db_err)?;
        let rows = st
            .query_map([], |r| {
                let blob: Vec<u8> = r.get(2)?;
                let values = blob.chunks_exact(8).map(|b| f64::from_le_bytes(b.try_into().unwrap_or([0; 8]))).collect();
                Ok((r.get(0)?, r.get(1)?, values))
            })
            .map_err(db_err)?;
        Ok(rows.flatten().collect())
    }
}

impl JobStore for Database {
    fn save(&self, job: &JobView) -> std::io::Result<()> {
        let view = serde_json::to_string(job).map_err(std::io::Error::other)?;
        self.conn()
            .execute(
                "INSERT INTO jobs (id, view) VALUES (?1, ?2) ON CONFLICT(id) DO UPDATE SET view = excluded.view",
                rusqlite::params![job.id, view],
            )
            .map_err(db_err)?;
        Ok(())
    }
    fn load_all(&self) -> std::io::Result<Vec<JobView>> {
        let c = self.conn();
        let mut st = c.prepare("SELECT view FROM jobs ORDER BY seq").map_err(db_err)?;
        let rows = st.query_map([], |r| r.get::<_, String>(0)).map_err(db_err)?;
        Ok(rows.flatten().filter_map(|v| serde_json::from_str(&v).ok()).collect())
    }
}

/// A finished result: the JSON summary, per-vertex arrays, and the serialized body with its strong ETag.
pub struct StoredResult {
    pub id: String,
    pub summary: Value,
    pub arrays: Vec<VertexArray>,
    /// The JSON body, shared (not copied) by every response.
    pub body: axum::body::Bytes,
    pub etag: String,
    /// The body without per-vertex values (`?values=false`), made once.
    pub summary_body: axum::body::Bytes,
}

impl StoredResult {
    pub fn new(id: &str, summary: Value, arrays: Vec<VertexArray>, body: Vec<u8>) -> Self {
        let mut light = summary.clone();
        if let Some(map) = light.get_mut("arrays").and_then(Value::as_object_mut) {
            for a in map.values_mut() {
                if let Some(o) = a.as_object_mut() {
                    o.remove("values");
                }
            }
        }
        let summary_body = serde_json::to_vec(&light).unwrap_or_default().into();
        StoredResult { id: id.to_string(), etag: etag_of(&body), summary, arrays, body: body.into(), summary_body }
    }
}

pub trait ResultStore: Send + Sync {
    fn put(&self, result: StoredResult) -> std::io::Result<Arc<StoredResult>>;
    fn get(&self, id: &str) -> Option<Arc<StoredResult>>;
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

fn result_size(r: &StoredResult) -> usize {
    r.body.len() + r.summary_body.len() + r.arrays.iter().map(|a| 8 * a.data.len()).sum::<usize>()
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

impl ResultStore for FileResults {
    fn put(&self, result: StoredResult) -> std::io::Result<Arc<StoredResult>> {
        write_atomic(&self.dir.join(format!("{}.json", result.id)), &result.body)?;
        let r = Arc::new(result);
        self.results.lock().unwrap_or_else(|e| e.into_inner()).put(&r.id, r.clone(), result_size(&r));
        Ok(r)
    }
    fn get(&self, id: &str) -> Option<Arc<StoredResult>> {
        if let Some(r) = self.results.lock().unwrap_or_else(|e| e.into_inner()).get(id) {
            return Some(r);
        }
        // After a restart: read the file back (its arrays carry their values).
        if !id.bytes().all(|b| b.is_ascii_hexdigit()) {
            return None;
        }
        let body = std::fs::read(self.dir.join(format!("{id}.json"))).ok()?;
        let summary: Value = serde_json::from_slice(&body).ok()?;
        let mut arrays = vec![];
        if let Some(map) = summary.get("arrays").and_then(Value::as_object) {
            for (name, a) in map {
                let rows = a["rows"].as_u64()? as usize;
                let cols = a["cols"].as_u64()? as usize;
                let data: Vec<f64> = a["values"]
                    .as_array()?
                    .iter()
                    .flat_map(|r| r.as_array().cloned().unwrap_or_default())
                    .map(|v| v.as_f64().unwrap_or(f64::NAN))
                    .collect();
                let columns =
                    a["columns"].as_array().map(|c| c.iter().map(|v| v.as_f64().unwrap_or(f64::NAN)).collect());
                let Some(name) = crate::analysis::ARRAY_NAMES.iter().copied().find(|n| n == name) else { continue };
                arrays.push(VertexArray { name, rows, cols, data, columns });
            }
        }
        let r = Arc::new(StoredResult::new(id, summary, arrays, body));
        self.results.lock().unwrap_or_else(|e| e.into_inner()).put(id, r.clone(), result_size(&r));
        Some(r)
    }
}

/// The strong ETag of a body: the first 128 bits of its SHA-256, quoted.
pub fn etag_of(body: &[u8]) -> String {
    use sha2::Digest;
    format!("\"{}\"", sha2::Sha256::digest(body).iter().take(16).map(|b| format!("{b:02x}")).collect::<String>())
}

/// Eigenpairs by (shape, operator, solver) key, bounded by bytes (least recently used first). An entry with k
/// pairs serves any request for at most k.
pub struct EigenCache {
    inner: Mutex<ByteLru<Eigen>>,
    pub hits: std::sync::atomic::AtomicU64,
    pub misses: std::sync::atomic::AtomicU64,
}

impl EigenCache {
    pub fn new(limit: usize) -> Self {
        EigenCache { inner: Mutex::new(ByteLru::new(limit)), hits: Default::default(), misses: Default::default() }
    }
    fn size(e: &Eigen) -> usize {
        let s = &e.spectrum;
        8 * (s.vectors.nrows() * s.vectors.ncols() + 2 * s.values.len())
            + 16 * (e.operator.pair.stiffness.len() + e.operator.pair.pattern.row_idx.len())
    }
}

impl SpectrumCache for EigenCache {
    fn get(&self, key: &str, k: usize) -> Option<Arc<Eigen>> {
        use std::sync::atomic::Ordering::Relaxed;
        let found =
            self.inner.lock().unwrap_or_else(|e| e.into_inner()).get(key).filter(|e| e.spectrum.values.len() >= k);
        if found.is_some() { &self.hits } else { &self.misses }.fetch_add(1, Relaxed);
        found
    }
    fn put(&self, key: &str, eigen: Arc<Eigen>) {
        let mut g = self.inner.lock().unwrap_or_else(|e| e.into_inner());
        // Keep whichever entry holds more pairs.
        if g.get(key).is_some_and(|old| old.spectrum.values.len() >= eigen.spectrum.values.len()) {
            return;
        }
        let size = Self::size(&eigen);
        g.put(key, eigen, size);
    }
}

#[cfg(test)]
mod tests {
    use super::ByteLru;
    use std::sync::Arc;

    #[test]
    fn byte_lru_evicts_the_least_recently_used_and_skips_oversized_values() {
        let mut c = ByteLru::new(10);
        c.put("a", Arc::new(1), 4);
        c.put("b", Arc::new(2), 4);
        assert_eq!(c.get("a").as_deref(), Some(&1)); // a is now the most recent
        c.put("c", Arc::new(3), 4); // 12 > 10: b goes
        assert!(c.get("b").is_none());
        assert_eq!((c.get("a").as_deref(), c.get("c").as_deref()), (Some(&1), Some(&3)));
        c.put("huge", Arc::new(4), 11);
        assert!(c.get("huge").is_none());
        c.put("a", Arc::new(5), 2); // replacing frees the old size
        assert_eq!(c.bytes, 6);
    }
}
