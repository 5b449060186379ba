//! Storage behind traits, so that a shared backend can replace the embedded one without touching handlers.
//! This module holds the embedded defaults: shapes in memory, results in memory and as content-addressed JSON
//! files in the data directory (written atomically: temporary file, fsync, rename), and a byte-bounded cache of
//! eigenpairs.

use crate::analysis::{Eigen, SpectrumCache, VertexArray};
use kac_core::Validated;
use serde_json::Value;
use std::collections::{BTreeMap, HashMap};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

/// A stored shape.
pub struct StoredShape {
    pub id: String,
    pub validated: Validated,
    pub summary: Value,
    pub format: String,
    pub created_at: String,
    pub bytes: usize,
}

pub trait ShapeStore: Send + Sync {
    /// Stores the shape unless one with its id exists; true if it was new.
    fn insert(&self, shape: StoredShape) -> (bool, Arc<StoredShape>);
    fn get(&self, id: &str) -> Option<Arc<StoredShape>>;
    /// Shapes in id order from `offset`, at most `limit`, and the total.
    fn list(&self, offset: usize, limit: usize) -> (Vec<Arc<StoredShape>>, usize);
    fn remove(&self, id: &str) -> bool;
}

#[derive(Default)]
pub struct MemoryShapes {
    shapes: Mutex<BTreeMap<String, Arc<StoredShape>>>,
}

impl ShapeStore for MemoryShapes {
    fn insert(&self, shape: StoredShape) -> (bool, Arc<StoredShape>) {
        let mut m = self.shapes.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(s) = m.get(&shape.id) {
            return (false, s.clone());
        }
        let s = Arc::new(shape);
        m.insert(s.id.clone(), s.clone());
        (true, s)
    }
    fn get(&self, id: &str) -> Option<Arc<StoredShape>> {
        self.shapes.lock().unwrap_or_else(|e| e.into_inner()).get(id).cloned()
    }
    fn list(&self, offset: usize, limit: usize) -> (Vec<Arc<StoredShape>>, usize) {
        let m = self.shapes.lock().unwrap_or_else(|e| e.into_inner());
        (m.values().skip(offset).take(limit).cloned().collect(), m.len())
    }
    fn remove(&self, id: &str) -> bool {
        self.shapes.lock().unwrap_or_else(|e| e.into_inner()).remove(id).is_some()
    }
}

/// A finished result: the JSON summary, per-vertex arrays, and the serialized body with its strong ETag.
pub struct StoredResult {
    pub id: String,
    pub summary: Value,
    pub arrays: Vec<VertexArray>,
    pub body: Vec<u8>,
    pub etag: String,
}

pub trait ResultStore: Send + Sync {
    fn put(&self, result: StoredResult) -> std::io::Result<Arc<StoredResult>>;
    fn get(&self, id: &str) -> Option<Arc<StoredResult>>;
}

/// Results in memory, each also written to `DIR/results/{id}.json`.
pub struct FileResults {
    dir: PathBuf,
    results: Mutex<HashMap<String, Arc<StoredResult>>>,
}

impl FileResults {
    pub fn open(data_dir: &Path) -> std::io::Result<Self> {
        let dir = data_dir.join("results");
        std::fs::create_dir_all(&dir)?;
        Ok(FileResults { dir, results: Mutex::new(HashMap::new()) })
    }
}

/// Writes a file atomically: a temporary file beside it, fsync, rename.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    let tmp = path.with_extension(format!("tmp.{}", std::process::id()));
    {
        let mut f = std::fs::File::create(&tmp)?;
        f.write_all(bytes)?;
        f.sync_all()?;
    }
    std::fs::rename(&tmp, path)
}

impl ResultStore for FileResults {
    fn put(&self, result: StoredResult) -> std::io::Result<Arc<StoredResult>> {
        write_atomic(&self.dir.join(format!("{}.json", result.id)), &result.body)?;
        let r = Arc::new(result);
        self.results.lock().unwrap_or_else(|e| e.into_inner()).insert(r.id.clone(), r.clone());
        Ok(r)
    }
    fn get(&self, id: &str) -> Option<Arc<StoredResult>> {
        self.results.lock().unwrap_or_else(|e| e.into_inner()).get(id).cloned()
    }
}

/// Eigenpairs by (shape, operator, solver) key, bounded by bytes; the least recently used go first. An entry
/// with k pairs serves any request for at most k.
pub struct EigenCache {
    limit: usize,
    inner: Mutex<CacheInner>,
    pub hits: std::sync::atomic::AtomicU64,
    pub misses: std::sync::atomic::AtomicU64,
}

#[derive(Default)]
struct CacheInner {
    entries: HashMap<String, (Arc<Eigen>, usize, u64)>,
    bytes: usize,
    clock: u64,
}

impl EigenCache {
    pub fn new(limit: usize) -> Self {
        EigenCache {
            limit,
            inner: Mutex::new(CacheInner::default()),
            hits: Default::default(),
            misses: Default::default(),
        }
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
        let mut g = self.inner.lock().unwrap_or_else(|e| e.into_inner());
        g.clock += 1;
        let clock = g.clock;
        match g.entries.get_mut(key) {
            Some((e, _, used)) if e.spectrum.values.len() >= k => {
                *used = clock;
                self.hits.fetch_add(1, Relaxed);
                Some(e.clone())
            }
            _ => {
                self.misses.fetch_add(1, Relaxed);
                None
            }
        }
    }
    fn put(&self, key: &str, eigen: Arc<Eigen>) {
        let size = Self::size(&eigen);
        if size > self.limit {
            return;
        }
        let mut g = self.inner.lock().unwrap_or_else(|e| e.into_inner());
        g.clock += 1;
        let clock = g.clock;
        if let Some((old, s, _)) = g.entries.get(key) {
            if old.spectrum.values.len() >= eigen.spectrum.values.len() {
                return;
            }
            let s = *s;
            g.bytes -= s;
        }
        g.entries.insert(key.to_string(), (eigen, size, clock));
        g.bytes += size;
        while g.bytes > self.limit {
            let Some(victim) = g.entries.iter().min_by_key(|(_, (_, _, used))| *used).map(|(k, _)| k.clone()) else {
                break;
            };
            if let Some((_, s, _)) = g.entries.remove(&victim) {
                g.bytes -= s;
            }
        }
    }
}
