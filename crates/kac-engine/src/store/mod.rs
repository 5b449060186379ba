//! Storage behind traits, so that a shared backend can replace the embedded one without touching handlers.
//! This module holds the embedded defaults: shapes in memory, results in memory and as content-addressed JSON
//! files in the data directory (written atomically: temporary file, fsync, rename), and a byte-bounded cache of
//! eigenpairs.

use super::ids::{ResultId, ShapeId};
use crate::analysis::{Eigen, SpectrumCache, VertexArray};
use crate::record::JobView;
use kac_core::Validated;
use serde_json::Value;
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

mod memory;
mod postgres;
mod queue;
mod result;
mod sqlite;
pub use memory::MemoryQueue;
pub use postgres::Postgres;
pub(crate) use result::result_size;
pub use result::{StoredResult, SMALL_BODY};

/// The stores of one backend.
pub struct Backend {
    pub shapes: Arc<dyn ShapeStore>,
    pub fingerprints: Arc<dyn FingerprintStore>,
    pub results: Arc<dyn ResultStore>,
    pub queue: Arc<dyn JobQueue>,
    /// Where this replica keeps its search index's snapshot (its data directory, with either store).
    pub index_snapshot: Option<PathBuf>,
}

/// Opens the backend `--store` names (default: the embedded one in `--data-dir`).
pub fn open(config: &crate::config::EngineConfig) -> std::io::Result<Backend> {
    let store = config.store.clone().unwrap_or_else(|| format!("sqlite:{}", config.data_dir.display()));
    if let Some(dir) = store.strip_prefix("sqlite:") {
        let dir = Path::new(dir);
        std::fs::create_dir_all(dir)?;
        let db = Arc::new(Database::open(dir, config.max_vertices, config.store_cache_bytes)?);
        let results = Arc::new(FileResults::open(dir, config.store_cache_bytes)?);
        let index_snapshot = Some(dir.join("search-index.bin"));
        return Ok(Backend { shapes: db.clone(), fingerprints: db.clone(), results, queue: db, index_snapshot });
    }
    if config.shared_store() {
        let pg = Arc::new(Postgres::open(&store, config.pg_pool_size, config.max_vertices, config.store_cache_bytes)?);
        return Ok(Backend {
            shapes: pg.clone(),
            fingerprints: pg.clone(),
            results: pg.clone(),
            queue: pg,
            index_snapshot: Some(config.data_dir.join("search-index.bin")),
        });
    }
    Err(std::io::Error::new(
        std::io::ErrorKind::InvalidInput,
        format!("--store {store}: give sqlite:DIR or postgres://…"),
    ))
}
pub use queue::{Enqueued, JobQueue, Lane, Lease};
pub use sqlite::{write_atomic, Database, FileResults};

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
    /// The shape, parsed (None: not stored; an error: the store cannot be read now).
    fn get(&self, id: &ShapeId) -> std::io::Result<Option<Arc<StoredShape>>>;
    /// Records in id order from `offset`, at most `limit`, and the total.
    fn list(&self, offset: usize, limit: usize) -> std::io::Result<(Vec<ShapeRecord>, usize)>;
    /// Removes the shape and its fingerprints (false: it was not stored).
    fn remove(&self, id: &ShapeId) -> std::io::Result<bool>;
    /// Whether the storage answers (for readiness).
    fn healthy(&self) -> bool;
    /// A connection pool's size, idle connections and waiting callers, where the store has one.
    fn pool_status(&self) -> Option<(usize, usize, usize)> {
        None
    }
}

/// Shape-DNA fingerprints of stored shapes, by family (the parameters they were computed with), kept as shapes
/// are analysed so that a search compares against every shape the service holds; and the shapes' tags, which a
/// search may be limited to. Both are logged, in one log, so that every replica's index follows the store.
pub trait FingerprintStore: Send + Sync {
    /// Inserts or replaces one shape's fingerprint in a family, if the shape is still stored (true then).
    fn put_fingerprint(&self, family: &str, shape_id: &str, values: &[f64]) -> std::io::Result<bool>;
    /// How many fingerprints each family holds.
    fn fingerprint_counts(&self) -> std::io::Result<Vec<(String, usize)>>;
    /// Every fingerprint, one at a time: (family, shape id, values).
    fn for_each_fingerprint(&self, f: &mut dyn FnMut(&str, &str, &[f64])) -> std::io::Result<()>;
    /// The fingerprints of a family for some shapes (those stored), by shape id.
    fn fingerprints_of(&self, family: &str, shape_ids: &[String]) -> std::io::Result<HashMap<String, Vec<f64>>>;
    /// Replaces a stored shape's tags, or adds to them, in one transaction (so that edits made at once, on any
    /// replica, are never lost); logged with the whole set that results.
    fn set_tags(&self, shape_id: &str, edit: &TagEdit) -> std::io::Result<TagsOutcome>;
    /// A shape's tags, sorted.
    fn tags_of(&self, shape_id: &str) -> std::io::Result<Vec<String>>;
    /// Every (shape id, tag), one at a time.
    fn for_each_tag(&self, f: &mut dyn FnMut(&str, &str)) -> std::io::Result<()>;
    /// How many (shape id, tag) pairs are stored.
    fn tag_count(&self) -> std::io::Result<usize>;
    /// This store's identity: drawn at random when it was created, so that a search index snapshot of another store
    /// (or of a store created again) is never read as its own.
    fn store_identity(&self) -> std::io::Result<String>;
    /// The end of the log of changes (every fingerprint put, every removed shape, every change of tags), for
    /// [`fingerprint_changes`].
    ///
    /// [`fingerprint_changes`]: FingerprintStore::fingerprint_changes
    fn fingerprint_log_end(&self) -> std::io::Result<i64>;
    /// The shape id of the log's entry at position `seq` (None: there is none), which tells a snapshot of this
    /// store from one of another store or of a store rolled back.
    fn fingerprint_log_entry(&self, seq: i64) -> std::io::Result<Option<String>>;
    /// The changes logged after position `after`, in order, and the position of the last. Other replicas'
    /// indexes follow the store through it.
    fn fingerprint_changes(&self, after: i64) -> std::io::Result<(Vec<FingerprintChange>, i64)>;
}

/// An edit of a shape's tags.
#[derive(Debug, Clone, PartialEq)]
pub enum TagEdit {
    Replace(Vec<String>),
    /// These added to the shape's, unless the shape would then carry more than `max`.
    Add {
        tags: Vec<String>,
        max: usize,
    },
}

/// What an edit of tags did.
#[derive(Debug, Clone, PartialEq)]
pub enum TagsOutcome {
    /// The shape's tags now (sorted).
    Set(Vec<String>),
    NotStored,
    /// The shape would carry this many: nothing changed.
    TooMany(usize),
}

impl TagEdit {
    /// The tags a shape carrying `current` carries after the edit (sorted, each once), or how many it would.
    pub(crate) fn apply(&self, mut current: Vec<String>) -> Result<Vec<String>, usize> {
        match self {
            TagEdit::Replace(t) => current = t.clone(),
            TagEdit::Add { tags, .. } => current.extend(tags.iter().cloned()),
        }
        current.sort();
        current.dedup();
        match self {
            TagEdit::Add { max, .. } if current.len() > *max => Err(current.len()),
            _ => Ok(current),
        }
    }
}

/// One entry of the change log.
#[derive(Debug, Clone, PartialEq)]
pub enum FingerprintChange {
    Kept { family: String, shape_id: String, values: Vec<f64> },
    Removed { shape_id: String },
    Tagged { shape_id: String, tags: Vec<String> },
}

/// The log's row for a change of tags: this family (no fingerprint family starts with `#`) and the tags, one a
/// line, in the fingerprint's column.
pub(crate) const TAGS_ENTRY: &str = "#tags";

impl FingerprintChange {
    pub fn shape_id(&self) -> &str {
        match self {
            FingerprintChange::Kept { shape_id, .. }
            | FingerprintChange::Removed { shape_id }
            | FingerprintChange::Tagged { shape_id, .. } => shape_id,
        }
    }
    /// A log row (family, shape id, blob) read back.
    pub(crate) fn of_row(family: String, shape_id: String, blob: Option<&[u8]>) -> FingerprintChange {
        match blob {
            Some(b) if family == TAGS_ENTRY => FingerprintChange::Tagged {
                shape_id,
                tags: String::from_utf8_lossy(b).split('\n').filter(|t| !t.is_empty()).map(str::to_string).collect(),
            },
            Some(b) => FingerprintChange::Kept { family, shape_id, values: f64s_of(b) },
            None => FingerprintChange::Removed { shape_id },
        }
    }
}

/// Tags as the log's blob holds them.
pub(crate) fn tags_blob(tags: &[String]) -> Vec<u8> {
    tags.join("\n").into_bytes()
}

pub(crate) fn f64s_of(blob: &[u8]) -> Vec<f64> {
    blob.chunks_exact(8).map(|b| f64::from_le_bytes(b.try_into().unwrap_or([0; 8]))).collect()
}

/// Runs a blocking piece of work (a large file, a large result's numbers): inside the service's multi-thread
/// runtime through `block_in_place`, so its other tasks go on; elsewhere as it is.
pub(crate) fn blocking<T>(f: impl FnOnce() -> T) -> T {
    match tokio::runtime::Handle::try_current() {
        Ok(h) if h.runtime_flavor() == tokio::runtime::RuntimeFlavor::MultiThread => tokio::task::block_in_place(f),
        _ => f(),
    }
}

/// Bytes a parsed shape holds, about: its upload counts twice (geometry plus topology and the report).
pub(crate) fn shape_size(s: &StoredShape) -> usize {
    2 * s.bytes + 48 * s.validated.shape.vertex_count()
}

/// A stored upload parsed and validated again (after a restart, or on another replica).
pub(crate) fn parse_shape(record: ShapeRecord, bytes: &[u8], max_vertices: usize) -> Option<StoredShape> {
    let format = kac_core::Format::from_name(&record.format)?;
    let read = kac_core::ReadOptions { max_vertices: max_vertices.max(1), ..Default::default() };
    let validated = kac_core::load_bytes(bytes, format, &read, &Default::default()).ok()?;
    Some(StoredShape { record, validated })
}

pub trait ResultStore: Send + Sync {
    /// Stores a result unless one is stored under its id; the stored one.
    fn put(&self, result: Arc<StoredResult>) -> std::io::Result<Arc<StoredResult>>;
    /// The result (None: not stored; an error: the store cannot be read now).
    fn get(&self, id: &ResultId) -> std::io::Result<Option<Arc<StoredResult>>>;
    /// Removes a result once it has served its one reader (a slice job's pairs, read by the job that offered it);
    /// false when none was stored. Results of analyses are never removed.
    fn remove(&self, id: &ResultId) -> std::io::Result<bool>;
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
