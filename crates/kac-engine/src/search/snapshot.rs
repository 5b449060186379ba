//! The search index on disk, so that a start reads one file instead of every fingerprint in the store and training
//! the cells again: the log position it reflects, each family's ids, single-precision rows, rounding bounds and
//! cells, and the shapes' tags. Little-endian, ending in a CRC-32 of every byte before it; written to a temporary
//! file, synced and renamed over the last one.
//!
//! A snapshot proves itself before anything in it is used: its checksum matches (a flipped bit anywhere is
//! refused), it is of this store, its position is not beyond the store's log and the log's entry there is the one
//! it recorded (a snapshot of another store, or of a store rolled back, is refused). The index then checks, after
//! applying the log's later changes, that every family holds as many rows as the store and that the tags agree in
//! number ([`super::Index::load`]); on any doubt it is built from the tables again, and the reason logged.

use super::ivf::Ivf;
use super::{Family, Tag, Tags};
use crate::ids::ShapeId;
use std::collections::HashMap;
use std::io::{BufReader, BufWriter, Read, Write};
use std::path::Path;

const MAGIC: &[u8; 8] = b"KACIDX04";
const END: &[u8; 8] = b"KACIDXOK";

/// A writer that keeps the CRC-32 of every byte written.
struct W<T: Write>(T, crc32fast::Hasher);
impl<T: Write> W<T> {
    fn bytes(&mut self, b: &[u8]) -> std::io::Result<()> {
        self.1.update(b);
        self.0.write_all(b)
    }
    fn u32(&mut self, v: u32) -> std::io::Result<()> {
        self.bytes(&v.to_le_bytes())
    }
    fn u64(&mut self, v: u64) -> std::io::Result<()> {
        self.bytes(&v.to_le_bytes())
    }
    fn f64s(&mut self, v: &[f64]) -> std::io::Result<()> {
        for c in v.chunks(8192) {
            let b: Vec<u8> = c.iter().flat_map(|x| x.to_le_bytes()).collect();
            self.bytes(&b)?;
        }
        Ok(())
    }
    fn f32s(&mut self, v: &[f32]) -> std::io::Result<()> {
        for c in v.chunks(16384) {
            let b: Vec<u8> = c.iter().flat_map(|x| x.to_le_bytes()).collect();
            self.bytes(&b)?;
        }
        Ok(())
    }
    fn u32s(&mut self, v: &[u32]) -> std::io::Result<()> {
        for c in v.chunks(16384) {
            let b: Vec<u8> = c.iter().flat_map(|x| x.to_le_bytes()).collect();
            self.bytes(&b)?;
        }
        Ok(())
    }
    fn text(&mut self, s: &str) -> std::io::Result<()> {
        self.u32(s.len() as u32)?;
        self.bytes(s.as_bytes())
    }
}

/// Writes the snapshot of `families` and `tags` at log position `at`.
pub(crate) fn write(
    path: &Path,
    store: &str,
    at: &(i64, String),
    families: &HashMap<String, Family>,
    tags: &Tags,
) -> std::io::Result<()> {
    // One temporary file a process: replicas sharing a directory each publish whole files.
    let tmp = path.with_extension(format!("{}.tmp", std::process::id()));
    if let Some(dir) = path.parent() {
        std::fs::create_dir_all(dir)?;
    }
    let file = std::fs::File::create(&tmp)?;
    let mut w = W(BufWriter::with_capacity(1 << 20, file), crc32fast::Hasher::new());
    w.bytes(MAGIC)?;
    w.text(store)?;
    w.u64(at.0 as u64)?;
    w.text(&at.1)?;
    // Families without rows are left out (one never given a row has no width, which a reader refuses).
    let held: Vec<(&String, &Family)> = families.iter().filter(|(_, f)| f.len() > 0).collect();
    w.u32(held.len() as u32)?;
    for (name, f) in held {
        w.text(name)?;
        w.u32(f.k as u32)?;
        w.u64(f.len() as u64)?;
        for id in &f.ids {
            w.bytes(&id.0)?;
        }
        w.f32s(&f.vals)?;
        w.f32s(&f.err)?;
        w.f32s(&[f.err_max])?;
        match &f.ivf {
            None => w.u32(0)?,
            Some(ivf) => {
                w.u32(ivf.cells() as u32)?;
                w.u64(ivf.trained_rows as u64)?;
                w.f64s(&[ivf.slack])?;
                w.f64s(&ivf.centroids)?;
                w.u32s(&ivf.row_cell)?;
            }
        }
    }
    w.u64(tags.by_shape.len() as u64)?;
    for (id, t) in &tags.by_shape {
        w.bytes(&id.0)?;
        w.u32(t.len() as u32)?;
        for tag in t {
            w.text(tag.as_str())?;
        }
    }
    w.bytes(END)?;
    let crc = w.1.clone().finalize();
    w.0.write_all(&crc.to_le_bytes())?;
    let file = w.0.into_inner().map_err(|e| e.into_error())?;
    file.sync_all()?;
    std::fs::rename(&tmp, path)?;
    if let Some(dir) = path.parent() {
        std::fs::File::open(dir)?.sync_all()?;
    }
    Ok(())
}

/// A reader that keeps the CRC-32 of every byte read.
struct R<T: Read>(T, crc32fast::Hasher);
impl<T: Read> R<T> {
    fn read_exact(&mut self, b: &mut [u8]) -> std::io::Result<()> {
        self.0.read_exact(b)?;
        self.1.update(b);
        Ok(())
    }
    fn array<const N: usize>(&mut self) -> std::io::Result<[u8; N]> {
        let mut b = [0u8; N];
        self.read_exact(&mut b)?;
        Ok(b)
    }
    fn u32(&mut self) -> std::io::Result<u32> {
        Ok(u32::from_le_bytes(self.array()?))
    }
    fn u64(&mut self) -> std::io::Result<u64> {
        Ok(u64::from_le_bytes(self.array()?))
    }
    /// `n` values of `W` bytes each, converted by `f`.
    fn many<const W: usize, V>(&mut self, n: usize, f: impl Fn([u8; W]) -> V) -> std::io::Result<Vec<V>> {
        let mut out = Vec::with_capacity(n);
        let mut buf = vec![0u8; W * 16384];
        let mut left = n;
        while left > 0 {
            let m = left.min(16384);
            self.read_exact(&mut buf[..m * W])?;
            out.extend(buf[..m * W].chunks_exact(W).map(|c| f(c.try_into().unwrap_or([0; W]))));
            left -= m;
        }
        Ok(out)
    }
    fn text(&mut self, max: usize) -> std::io::Result<String> {
        let n = self.u32()? as usize;
        if n > max {
            return Err(bad("a name longer than any the service writes"));
        }
        let mut b = vec![0u8; n];
        self.read_exact(&mut b)?;
        String::from_utf8(b).map_err(|_| bad("a name that is not UTF-8"))
    }
}

fn bad(what: &str) -> std::io::Error {
    std::io::Error::new(std::io::ErrorKind::InvalidData, format!("the search index snapshot is damaged: {what}"))
}

type Loaded = (HashMap<String, Family>, Tags, (i64, String));

/// The snapshot at `path` (None when there is none), refused when it is damaged (its checksum, its sizes, its
/// end), beyond the log's end `log_end`, or of another log (`entry`: the shape id of the store's log entry at a
/// position). Nothing read is returned before the checksum over the whole file has been checked.
pub(crate) fn read(
    path: &Path,
    store: &str,
    log_end: i64,
    entry: &dyn Fn(i64) -> std::io::Result<Option<String>>,
) -> std::io::Result<Option<Loaded>> {
    let file = match std::fs::File::open(path) {
        Ok(f) => f,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(e) => return Err(e),
    };
    let size = file.metadata()?.len();
    let mut r = R(BufReader::with_capacity(1 << 20, file), crc32fast::Hasher::new());
    if &r.array::<8>()? != MAGIC {
        return Err(bad("not a kac search index (or of another version)"));
    }
    let of = r.text(256)?;
    if of != store {
        return Err(std::io::Error::new(
            std::io::ErrorKind::InvalidData,
            format!("the search index snapshot is of store {of}, not of this one ({store})"),
        ));
    }
    let at = r.u64()? as i64;
    let at_id = r.text(64)?;
    if at > log_end {
        return Err(std::io::Error::new(
            std::io::ErrorKind::InvalidData,
            format!("the search index snapshot is at log position {at}, beyond the store's {log_end}: another store's"),
        ));
    }
    if at > 0 && entry(at)?.as_deref() != Some(at_id.as_str()) {
        return Err(std::io::Error::new(
            std::io::ErrorKind::InvalidData,
            format!(
                "the search index snapshot's log entry {at} is not the store's: another store's, or one rolled back"
            ),
        ));
    }
    let mut families = HashMap::new();
    let nfam = r.u32()?;
    for _ in 0..nfam {
        let name = r.text(256)?;
        let k = r.u32()? as usize;
        let n = r.u64()? as usize;
        // Sizes checked against the file before anything that large is allocated: a row is its id (32 bytes), its
        // values (4 k) and its rounding bound (4); its cell (4 more) comes only with cells.
        if k == 0 || (n as u64).saturating_mul(36 + 4 * k as u64) > size {
            return Err(bad("a family larger than the file"));
        }
        let ids: Vec<ShapeId> = r.many::<32, _>(n, ShapeId)?;
        let vals = r.many::<4, _>(n * k, f32::from_le_bytes)?;
        let err = r.many::<4, _>(n, f32::from_le_bytes)?;
        let err_max = f32::from_le_bytes(r.array()?);
        let cells = r.u32()? as usize;
        let ivf = if cells == 0 {
            None
        } else {
            let trained_rows = r.u64()? as usize;
            let slack = f64::from_le_bytes(r.array()?);
            if (cells as u64).saturating_mul(8 * k as u64) > size {
                return Err(bad("more cells than the file holds"));
            }
            let centroids = r.many::<8, _>(cells * k, f64::from_le_bytes)?;
            let row_cell = r.many::<4, _>(n, u32::from_le_bytes)?;
            let mut lists = vec![vec![]; cells];
            let mut row_pos = Vec::with_capacity(n);
            for (row, &c) in row_cell.iter().enumerate() {
                let list = lists.get_mut(c as usize).ok_or_else(|| bad("a row in a cell that does not exist"))?;
                row_pos.push(list.len() as u32);
                list.push(row as u32);
            }
            Some(Ivf { k, centroids, lists, row_cell, row_pos, slack, trained_rows, packed_rows: n, xmax: -1.0 })
        };
        let mut row = super::IdMap::with_capacity_and_hasher(n, Default::default());
        for (i, id) in ids.iter().enumerate() {
            row.insert(*id, i as u32);
        }
        if row.len() != n {
            return Err(bad("an id held twice"));
        }
        families.insert(name, Family { k, ids, row, vals, err, err_max, ivf, ..Default::default() });
    }
    let mut tags = Tags::default();
    let shapes = r.u64()?;
    if shapes.saturating_mul(36) > size {
        return Err(bad("more tagged shapes than the file holds"));
    }
    for _ in 0..shapes {
        let id = ShapeId(r.array()?);
        let count = r.u32()? as usize;
        if count > super::MAX_TAGS {
            return Err(bad("a shape with more tags than allowed"));
        }
        let mut t = Vec::with_capacity(count);
        for _ in 0..count {
            t.push(Tag::parse(&r.text(64)?).map_err(|e| bad(&e))?);
        }
        tags.set(id, t);
    }
    if &r.array::<8>()? != END {
        return Err(bad("its end is missing"));
    }
    let crc = r.1.clone().finalize();
    let mut stored = [0u8; 4];
    r.0.read_exact(&mut stored).map_err(|_| bad("its checksum is missing"))?;
    if u32::from_le_bytes(stored) != crc {
        return Err(bad("its checksum does not match its contents"));
    }
    if r.0.read(&mut [0u8; 1])? != 0 {
        return Err(bad("bytes after its end"));
    }
    Ok(Some((families, tags, (at, at_id))))
}
