//! Results as files in the data directory, written atomically and once.

use super::*;

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
pub(super) fn write_values(path: &Path, r: &StoredResult) -> std::io::Result<()> {
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
