//! Search for retrieval back ends (`POST /v1/search`): the stored shapes nearest to a given shape or fingerprint
//! by shape-DNA. Every fingerprint a `shape-dna` job or a comparison computes is kept in the store (by family:
//! the parameters it was computed with) and in an in-memory index loaded at start, so a search scans contiguous
//! rows of one family (100,000 fingerprints of 50 values in a few milliseconds; `bench/search.py`).

use super::ids::ShapeId;
use super::store::{FingerprintChange, FingerprintStore};
use crate::analysis::{self, Fingerprint, OperatorSpec};
use kac_core::descriptors::shape_dna::{self, Metric, ShapeDnaOptions};
use serde::{Deserialize, Serialize};
use std::collections::HashMap;
use std::sync::RwLock;

mod audit;
pub mod ivf;
mod snapshot;
pub use audit::{AuditReport, FamilyAudit, TagAudit};
use ivf::Ivf;

/// The nearest stored shapes to a shape or a fingerprint, by shape-DNA.
#[derive(Deserialize, Serialize, utoipa::ToSchema)]
#[serde(remote = "Self")]
pub struct SearchRequest {
    /// A stored shape to search from (its fingerprint is computed first, as a `shape-dna` job, when the store has
    /// none of this family); the shape itself is left out of the answer.
    pub shape_id: Option<String>,
    /// Or a fingerprint of `k` values computed elsewhere (with the same parameters).
    pub fingerprint: Option<Vec<f64>>,
    /// The shape-DNA's options (k, normalization, reweighting, include_zero) at the top level: one type and one
    /// set of defaults for every request and flag that fingerprints.
    #[serde(flatten)]
    pub dna: ShapeDnaOptions,
    #[serde(default)]
    pub metric: Metric,
    /// Nearest shapes returned (default 10, at most 1000).
    #[serde(default = "default_neighbours")]
    pub neighbours: usize,
    /// Only shapes carrying every one of these tags (at most 32).
    #[serde(default)]
    pub tags: Vec<String>,
    /// Compare every fingerprint of the family instead of probing the index's nearest cells (slower on large
    /// collections; the answer is then exact by construction).
    #[serde(default)]
    pub exact: bool,
    #[serde(default)]
    pub operator: OperatorSpec,
}

fn default_neighbours() -> usize {
    10
}

kac_core::object_only_serde!(SearchRequest);

impl SearchRequest {
    pub fn options(&self) -> ShapeDnaOptions {
        self.dna.clone()
    }
    pub fn family(&self) -> String {
        analysis::fingerprint_family(&self.options(), &self.operator)
    }
}

/// A tag: 1 to 64 characters of ASCII letters, digits and `-_.:/` (so a tag is the same in a URL, a JSON body and a
/// log line). Parsed at the boundary; what does not parse is refused.
#[derive(Clone, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize)]
pub struct Tag(String);

/// At most this many tags on one shape, and in one search's filter.
pub const MAX_TAGS: usize = 32;

impl Tag {
    pub fn parse(s: &str) -> Result<Tag, String> {
        let ok = |b: u8| b.is_ascii_alphanumeric() || matches!(b, b'-' | b'_' | b'.' | b':' | b'/');
        if s.is_empty() || s.len() > 64 || !s.bytes().all(ok) {
            let shown: String = s.chars().take(70).flat_map(char::escape_debug).collect();
            return Err(format!("tag '{shown}': a tag is 1 to 64 characters of ASCII letters, digits and - _ . : /"));
        }
        Ok(Tag(s.to_string()))
    }
    /// Tags given as a list: each parsed, repeats dropped, sorted; at most [`MAX_TAGS`].
    pub fn parse_all<S: AsRef<str>>(items: &[S]) -> Result<Vec<Tag>, String> {
        let mut tags = items.iter().map(|s| Tag::parse(s.as_ref())).collect::<Result<Vec<_>, _>>()?;
        tags.sort();
        tags.dedup();
        if tags.len() > MAX_TAGS {
            return Err(format!("{} tags: at most {MAX_TAGS}", tags.len()));
        }
        Ok(tags)
    }
    pub fn as_str(&self) -> &str {
        &self.0
    }
}

/// Hashing for shape ids, which are SHA-256 digests already: their four 8-byte words folded with a key drawn once
/// per process, then mixed (murmur3's finalizer), instead of SipHash, which the scans of a tag's shapes and the
/// loading of millions of ids spend most of their time in otherwise. The key keeps ids chosen to collide (whose
/// contents someone searched for) from being chosen once for every server.
#[derive(Clone, Copy)]
pub(crate) struct IdHasher(u64);

impl Default for IdHasher {
    fn default() -> Self {
        static KEY: std::sync::OnceLock<u64> = std::sync::OnceLock::new();
        IdHasher(*KEY.get_or_init(|| {
            use std::hash::{BuildHasher, Hasher};
            std::collections::hash_map::RandomState::new().build_hasher().finish()
        }))
    }
}

impl std::hash::Hasher for IdHasher {
    fn write(&mut self, bytes: &[u8]) {
        let mut x = self.0;
        for c in bytes.chunks(8) {
            let mut b = [0u8; 8];
            b[..c.len()].copy_from_slice(c);
            x = (x ^ u64::from_le_bytes(b)).wrapping_mul(0x9E37_79B9_7F4A_7C15).rotate_left(31);
        }
        self.0 = x;
    }
    fn write_usize(&mut self, n: usize) {
        self.0 ^= n as u64;
    }
    fn finish(&self) -> u64 {
        let mut h = self.0;
        h ^= h >> 33;
        h = h.wrapping_mul(0xff51_afd7_ed55_8ccd);
        h ^= h >> 33;
        h = h.wrapping_mul(0xc4ce_b9fe_1a85_ec53);
        h ^ (h >> 33)
    }
}

pub(crate) type Ids = std::hash::BuildHasherDefault<IdHasher>;
pub(crate) type IdMap<V> = HashMap<ShapeId, V, Ids>;
pub(crate) type IdSet = std::collections::HashSet<ShapeId, Ids>;

/// The rounding bound of one row stored in single precision: ‖x − x₃₂‖₁ ≤ 2⁻²⁴‖x‖₁ for values in single
/// precision's normal range (6.0·10⁻⁸ covers 2⁻²⁴ and the rounding of the sum), infinite when a value is outside it
/// (such a row is always re-ranked from its exact values).
fn rounding_bound(values: &[f64], stored: &[f32]) -> f32 {
    let normal =
        values.iter().all(|v| *v == 0.0 || (v.abs() >= f32::MIN_POSITIVE as f64 && v.abs() <= f32::MAX as f64));
    if !normal {
        return f32::INFINITY;
    }
    let l1: f64 = stored.iter().map(|v| v.abs() as f64).sum();
    (6.0e-8 * l1 * (1.0 + 1e-6)) as f32
}

/// The distance from a query to a row kept in single precision, computed in double precision (four partial sums,
/// so that the compiler may use vector lanes).
fn approx_distance(q: &[f64], x: &[f32], metric: Metric) -> f64 {
    let term = |a: f64, b: f32| -> f64 {
        let d = a - b as f64;
        match metric {
            Metric::Euclidean => d * d,
            Metric::Manhattan => d.abs(),
            Metric::Canberra => {
                let s = a.abs() + (b as f64).abs();
                if s > 0.0 {
                    d.abs() / s
                } else {
                    0.0
                }
            }
        }
    };
    let mut acc = [0.0f64; 4];
    let (qc, xc) = (q.chunks_exact(4), x.chunks_exact(4));
    let (qr, xr) = (qc.remainder(), xc.remainder());
    for (a, b) in qc.zip(xc) {
        for l in 0..4 {
            acc[l] += term(a[l], b[l]);
        }
    }
    let tail: f64 = qr.iter().zip(xr).map(|(a, &b)| term(*a, b)).sum();
    let sum = (acc[0] + acc[1]) + (acc[2] + acc[3]) + tail;
    if metric == Metric::Euclidean {
        sum.sqrt()
    } else {
        sum
    }
}

/// The fingerprints of one family: ids and their rows of `k` values, contiguous, in single precision (the exact
/// values stay in the store, which the final ranking reads), and their cells once the family is large.
#[derive(Default)]
pub(crate) struct Family {
    pub(crate) k: usize,
    pub(crate) ids: Vec<ShapeId>,
    pub(crate) row: IdMap<u32>,
    pub(crate) vals: Vec<f32>,
    /// Each row's rounding bound ([`rounding_bound`]).
    pub(crate) err: Vec<f32>,
    /// The largest rounding bound held (it never shrinks: a removal leaves it, which only weakens proofs).
    pub(crate) err_max: f32,
    pub(crate) ivf: Option<Ivf>,
    /// The rows of the shapes carrying each small tag, copied contiguous, so that a search within the tag reads one
    /// stretch of memory ([`Family::tag_add`]).
    pub(crate) subs: HashMap<Tag, Family>,
    /// Tags held by too many of the family's shapes for a copy: searched through the cells with a filter.
    pub(crate) large: std::collections::HashSet<Tag>,
    /// Rows copied into `subs`, over every tag.
    pub(crate) sub_rows: usize,
    /// The rows a load announced (reserved once the values' length is known).
    pub(crate) expect: usize,
    /// While the cells are trained again off the lock ([`retrain`]): the rows whose contents changed since it began.
    pub(crate) journal: Option<Vec<u32>>,
    /// The family grew or shrank fourfold since its cells were trained, and is too large to train them again under
    /// its lock: [`retrain`] does it on a thread of its own.
    pub(crate) wants_training: bool,
}

/// Families up to this many rows train their cells again at once, under the lock (a fraction of a second); larger
/// ones on a thread of their own while searches go on.
pub const INLINE_TRAINING: usize = 1 << 17;

impl Family {
    pub(crate) fn len(&self) -> usize {
        self.ids.len()
    }
    fn row_of(&self, r: usize) -> &[f32] {
        &self.vals[r * self.k..(r + 1) * self.k]
    }
    /// Keeps a fingerprint (replacing the shape's earlier one); `train`: files it in a cell, training the cells
    /// when the family has grown enough (false while a whole table is loaded: [`Family::train`] comes after).
    fn put(&mut self, id: ShapeId, v: &[f64], train: bool) {
        let stored: Vec<f32> = v.iter().map(|&x| x as f32).collect();
        let err = rounding_bound(v, &stored);
        self.put_stored(id, &stored, err, train);
    }
    /// [`Family::put`] of values already rounded, with their rounding bound.
    fn put_stored(&mut self, id: ShapeId, stored: &[f32], err: f32, train: bool) {
        if self.ids.is_empty() {
            self.k = stored.len();
            self.vals.reserve_exact(self.expect * self.k);
        }
        if stored.len() != self.k || stored.is_empty() {
            return;
        }
        self.err_max = self.err_max.max(err);
        match self.row.get(&id) {
            Some(&r) => {
                let r = r as usize;
                self.vals[r * self.k..(r + 1) * self.k].copy_from_slice(stored);
                self.err[r] = err;
                if let Some(ivf) = &mut self.ivf {
                    ivf.refile(&self.vals, r);
                }
                self.note(r);
            }
            None => {
                self.row.insert(id, self.ids.len() as u32);
                self.ids.push(id);
                self.vals.extend_from_slice(stored);
                self.err.push(err);
                self.note(self.ids.len() - 1);
                if !train {
                    return;
                }
                let n = self.ids.len();
                let retraining = self.journal.is_some();
                match &mut self.ivf {
                    Some(ivf) if n < 4 * ivf.trained_rows || retraining || n > INLINE_TRAINING => {
                        ivf.push(&self.vals);
                        if n >= 4 * ivf.trained_rows && !retraining {
                            self.wants_training = true;
                        }
                        if 4 * n.saturating_sub(ivf.packed_rows) > n {
                            self.pack();
                        }
                    }
                    // Too few rows for cells: scanned whole.
                    None if n < ivf::MIN_ROWS => {}
                    _ => self.train(faer::Par::Seq),
                }
            }
        }
    }
    /// Copies a shape's row into its tag's contiguous copy, unless the tag is held by too many of the family's
    /// shapes (more than 16,384 and a sixteenth of them); when the copies together would hold more rows than the
    /// family, the largest are dropped. A tag without a copy is searched through the cells.
    fn tag_add(&mut self, tag: &Tag, id: &ShapeId) {
        if self.large.contains(tag) {
            return;
        }
        let Some(&r) = self.row.get(id) else { return };
        let r = r as usize;
        let (stored, err) = (self.row_of(r).to_vec(), self.err[r]);
        let (limit, total) = (ivf::MIN_ROWS.max(self.len() / 16), self.len().max(ivf::MIN_ROWS));
        let sub = self.subs.entry(tag.clone()).or_default();
        let before = sub.len();
        sub.put_stored(*id, &stored, err, false);
        self.sub_rows += sub.len() - before;
        if sub.len() > limit {
            self.sub_rows -= sub.len();
            self.subs.remove(tag);
            self.large.insert(tag.clone());
        }
        // Over the budget: the largest copies go first.
        while self.sub_rows > total {
            let Some(big) = self.subs.iter().max_by_key(|(_, s)| s.len()).map(|(t, _)| t.clone()) else { break };
            self.sub_rows -= self.subs.remove(&big).map_or(0, |s| s.len());
            self.large.insert(big);
        }
    }
    fn tag_remove(&mut self, tag: &Tag, id: &ShapeId) {
        if let Some(sub) = self.subs.get_mut(tag) {
            let before = sub.len();
            sub.remove(id, &[]);
            self.sub_rows -= before - sub.len();
        }
    }
    /// Records that row `r`'s contents changed, while the cells are trained again.
    fn note(&mut self, r: usize) {
        if let Some(j) = &mut self.journal {
            j.push(r as u32);
        }
    }
    /// Trains the family's cells afresh when it is large enough to have them (and drops them when it is not).
    pub(crate) fn train(&mut self, par: faer::Par) {
        if self.journal.is_some() {
            // A training off the lock is under way; its result replaces the cells.
            return;
        }
        self.ivf =
            (self.len() >= ivf::MIN_ROWS).then(|| Ivf::train(&self.vals, self.k, ivf::cells_for(self.len()), par));
        self.pack();
    }
    /// Renumbers the rows cell by cell, so that a probe reads each cell's rows from one stretch of memory (rows
    /// added later go at the end until the next packing: when they are a quarter of the family).
    fn pack(&mut self) {
        if self.journal.is_some() {
            // Rows keep their numbers while the cells are trained again.
            return;
        }
        let Some(ivf) = &mut self.ivf else { return };
        let order: Vec<u32> = ivf.lists.iter().flatten().copied().collect();
        let k = self.k;
        // In place, cycle by cycle (row j takes old row order[j]), so that the rows are never held twice.
        let mut done = vec![false; order.len()];
        let mut row = vec![0f32; k];
        for i in 0..order.len() {
            if done[i] {
                continue;
            }
            row.copy_from_slice(&self.vals[i * k..(i + 1) * k]);
            let (id, err) = (self.ids[i], self.err[i]);
            let mut j = i;
            loop {
                done[j] = true;
                let src = order[j] as usize;
                if src == i {
                    self.vals[j * k..(j + 1) * k].copy_from_slice(&row);
                    (self.ids[j], self.err[j]) = (id, err);
                    break;
                }
                self.vals.copy_within(src * k..(src + 1) * k, j * k);
                (self.ids[j], self.err[j]) = (self.ids[src], self.err[src]);
                j = src;
            }
        }
        let mut next = 0u32;
        for (c, list) in ivf.lists.iter_mut().enumerate() {
            for (p, r) in list.iter_mut().enumerate() {
                *r = next;
                ivf.row_cell[next as usize] = c as u32;
                ivf.row_pos[next as usize] = p as u32;
                next += 1;
            }
        }
        for (i, id) in self.ids.iter().enumerate() {
            self.row.insert(*id, i as u32);
        }
        ivf.packed_rows = self.ids.len();
    }
    fn remove(&mut self, id: &ShapeId, tags: &[Tag]) {
        for t in tags {
            self.tag_remove(t, id);
        }
        let Some(r) = self.row.remove(id) else { return };
        let (r, k) = (r as usize, self.k);
        // The last row moves into the hole.
        let last = self.ids.len() - 1;
        if let Some(ivf) = &mut self.ivf {
            ivf.swap_remove(r);
        }
        if r != last {
            self.vals.copy_within(last * k..(last + 1) * k, r * k);
            self.err[r] = self.err[last];
            self.ids[r] = self.ids[last];
            self.row.insert(self.ids[r], r as u32);
        }
        self.ids.pop();
        self.err.pop();
        self.vals.truncate(last * k);
        self.note(r);
        if self.ivf.as_ref().is_some_and(|i| self.len() < i.trained_rows / 4) {
            if self.len() > INLINE_TRAINING {
                self.wants_training = true;
            } else {
                self.train(faer::Par::Seq);
            }
        }
    }
}

type Families = RwLock<HashMap<String, Family>>;

/// A training of a family's cells under way, off its lock: new centroids from a sample, then every row assigned to
/// them a chunk at a time under the read lock, then the rows changed meanwhile assigned again and the cells swapped
/// in under the write lock.
pub(crate) struct Retraining {
    name: String,
    k: usize,
    centroids: Vec<f64>,
    cell: Vec<u32>,
    xmax: f64,
}

/// Starts a training of family `name`'s cells: opens its journal and trains centroids on a copy of a sample of its
/// rows (off the lock). None when the family is too small to have cells, or is being trained already.
pub(crate) fn begin_retraining(fams: &Families, name: &str, par: faer::Par) -> Option<Retraining> {
    let (k, sample, cells) = {
        let mut g = fams.write().unwrap_or_else(|e| e.into_inner());
        let fam = g.get_mut(name)?;
        fam.wants_training = false;
        if fam.journal.is_some() || fam.len() < ivf::MIN_ROWS {
            return None;
        }
        fam.journal = Some(vec![]);
        let cells = ivf::cells_for(fam.len());
        let mut sample = vec![];
        for r in ivf::sample_rows(fam.len(), cells) {
            sample.extend_from_slice(fam.row_of(r));
        }
        (fam.k, sample, cells)
    };
    let m = sample.len() / k;
    let centroids = ivf::centroids(&sample, k, &(0..m).collect::<Vec<_>>(), cells.min(m), par);
    Some(Retraining { name: name.to_string(), k, centroids, cell: vec![], xmax: 0.0 })
}

/// Assigns the next `chunk` rows to the new centroids under the read lock; false once every row has been.
pub(crate) fn retraining_step(fams: &Families, t: &mut Retraining, chunk: usize, par: faer::Par) -> bool {
    let g = fams.read().unwrap_or_else(|e| e.into_inner());
    let Some(fam) = g.get(&t.name) else { return false };
    let (from, len) = (t.cell.len(), fam.len());
    if from >= len {
        return false;
    }
    let rows: Vec<usize> = (from..(from + chunk).min(len)).collect();
    let (cell, xmax) = ivf::assign(&fam.vals, t.k, &rows, &t.centroids, par);
    t.cell.extend(cell);
    t.xmax = t.xmax.max(xmax);
    true
}

/// Swaps the new cells in under the write lock, once the rows that changed since the training began (the journal's)
/// and those added after the pass are assigned again; then renumbers the rows cell by cell.
pub(crate) fn finish_retraining(fams: &Families, t: Retraining, par: faer::Par) {
    let mut g = fams.write().unwrap_or_else(|e| e.into_inner());
    let Some(fam) = g.get_mut(&t.name) else { return };
    let journal = fam.journal.take().unwrap_or_default();
    let len = fam.len();
    if len < ivf::MIN_ROWS {
        fam.train(par);
        return;
    }
    let mut cell = t.cell;
    cell.truncate(len);
    let mut again: Vec<usize> = journal.into_iter().map(|r| r as usize).filter(|&r| r < cell.len()).collect();
    again.extend(cell.len()..len);
    again.sort_unstable();
    again.dedup();
    cell.resize(len, 0);
    let (cells, xmax) = ivf::assign(&fam.vals, t.k, &again, &t.centroids, par);
    for (&r, c) in again.iter().zip(cells) {
        cell[r] = c;
    }
    fam.ivf = Some(Ivf::from_assignment(t.k, t.centroids, cell, t.xmax.max(xmax), len));
    fam.pack();
}

/// A whole training off the lock (8,192 rows a step).
fn retrain(fams: &Families, name: &str, par: faer::Par) {
    if let Some(mut t) = begin_retraining(fams, name, par) {
        while retraining_step(fams, &mut t, 8192, par) {}
        finish_retraining(fams, t, par);
    }
}

/// The rows whose distance may be among the `count` smallest: each row offered with a lower and an upper bound
/// on its exact distance; kept while its lower bound is at most the `count`-th smallest upper bound seen.
struct Collector {
    count: usize,
    uppers: std::collections::BinaryHeap<u64>,
    kept: Vec<(f64, u32)>,
    /// When `kept` is next pruned (twice its size after the last pruning, so that many rows within rounding of the
    /// bound never make pruning quadratic).
    prune_at: usize,
    offered: usize,
}

impl Collector {
    fn new(count: usize) -> Self {
        Collector { count, uppers: Default::default(), kept: vec![], prune_at: 4 * count + 64, offered: 0 }
    }
    /// The `count`-th smallest upper bound so far (∞ before `count` rows).
    fn bound(&self) -> f64 {
        if self.uppers.len() < self.count {
            f64::INFINITY
        } else {
            self.uppers.peek().map_or(f64::INFINITY, |b| f64::from_bits(*b))
        }
    }
    fn offer(&mut self, approx: f64, err: f64, row: u32) {
        self.offered += 1;
        // Distances are never negative, so their bit patterns order as they do.
        let (lower, upper) = ((approx - err).max(0.0), approx + err + 1e-12 * approx);
        if lower > self.bound() {
            return;
        }
        if self.uppers.len() < self.count {
            self.uppers.push(upper.to_bits());
        } else if upper < self.bound() {
            self.uppers.pop();
            self.uppers.push(upper.to_bits());
        }
        self.kept.push((lower, row));
        if self.kept.len() > self.prune_at {
            let b = self.bound();
            self.kept.retain(|(l, _)| *l <= b);
            self.prune_at = (2 * self.kept.len()).max(4 * self.count + 64);
        }
    }
    fn rows(mut self) -> Vec<u32> {
        let b = self.bound();
        self.kept.retain(|(l, _)| *l <= b);
        self.kept.into_iter().map(|(_, r)| r).collect()
    }
}

/// How a search went.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, utoipa::ToSchema)]
#[serde(rename_all = "lowercase")]
pub enum Method {
    /// Every fingerprint of the family (or carrying the tags) was compared.
    Scan,
    /// The index's nearest cells were probed.
    Index,
}

/// One search.
pub struct Query<'a> {
    pub family: &'a str,
    pub values: &'a [f64],
    pub metric: Metric,
    pub count: usize,
    /// A shape left out of the answer (the query shape).
    pub exclude: Option<ShapeId>,
    /// Only shapes carrying every one of these tags.
    pub tags: &'a [Tag],
    /// Compare every fingerprint (no index).
    pub exact: bool,
    /// The most cells the index probes before it answers without a proof.
    pub max_cells: usize,
}

/// A search's answer.
#[derive(Debug)]
pub struct Found {
    /// Nearest first, ties by id: (shape id, exact distance).
    pub neighbours: Vec<(String, f64)>,
    /// Fingerprints the family holds.
    pub searched: usize,
    /// Fingerprints whose distance was computed.
    pub probed: usize,
    /// Whether the neighbours are proven to be the exact ones: a scan, or a probe whose unprobed cells all lie
    /// farther than the last neighbour.
    pub exact: bool,
    pub method: Method,
}

/// Why a search could not answer.
#[derive(Debug)]
pub enum SearchError {
    /// The query's length is not the family's.
    Length(String),
    /// The store could not give the candidates' exact values.
    Store(std::io::Error),
}

/// The exact values of some fingerprints of a family, by shape id (those still stored).
pub type Fetch<'a> = &'a dyn Fn(&str, &[String]) -> std::io::Result<HashMap<String, Vec<f64>>>;

/// Tags by shape and shapes by tag.
#[derive(Default)]
pub(crate) struct Tags {
    pub(crate) by_tag: HashMap<Tag, IdSet>,
    pub(crate) by_shape: IdMap<Vec<Tag>>,
}

impl Tags {
    fn set(&mut self, id: ShapeId, tags: Vec<Tag>) {
        for old in self.by_shape.remove(&id).unwrap_or_default() {
            if let Some(set) = self.by_tag.get_mut(&old) {
                set.remove(&id);
                if set.is_empty() {
                    self.by_tag.remove(&old);
                }
            }
        }
        for t in &tags {
            self.by_tag.entry(t.clone()).or_default().insert(id);
        }
        if !tags.is_empty() {
            self.by_shape.insert(id, tags);
        }
    }
}

/// The in-memory index of every stored fingerprint, by family, with the shapes' tags, and how far it has followed
/// the store's log of changes (which other replicas write too).
#[derive(Default)]
pub struct Index {
    pub(crate) families: std::sync::Arc<RwLock<HashMap<String, Family>>>,
    /// A training off the lock is running (one at a time).
    retraining: std::sync::Arc<std::sync::atomic::AtomicBool>,
    pub(crate) tags: RwLock<Tags>,
    /// The log position applied, and the shape id of the entry there.
    synced: std::sync::Mutex<(i64, String)>,
    /// Where the index is snapshotted (the embedded store's data directory), and changes since the last snapshot.
    snapshot: Option<std::path::PathBuf>,
    /// The store's identity, written in the snapshot.
    store_id: String,
    changed: std::sync::atomic::AtomicUsize,
    /// Held while a snapshot is written: one writer at a time.
    writing: std::sync::Mutex<()>,
    /// Held while the index is audited against the store ([`Index::audit`]): one audit at a time, since it reads
    /// every fingerprint of the store.
    pub(crate) auditing: std::sync::Mutex<()>,
}

/// What loading the index did, for the start-up log and the benchmark.
#[derive(Debug, Default, Serialize)]
pub struct LoadReport {
    /// `snapshot` or `store`.
    pub from: &'static str,
    pub fingerprints: usize,
    pub seconds: f64,
    /// Why a snapshot present was not used.
    pub snapshot_refused: Option<String>,
}

impl Index {
    /// The index of everything the store holds: from the snapshot at `snapshot` when there is a usable one (then
    /// the log's changes after it), else from the store's tables (then a snapshot is written).
    pub fn load(
        store: &dyn FingerprintStore,
        snapshot: Option<std::path::PathBuf>,
    ) -> std::io::Result<(Index, LoadReport)> {
        let t = std::time::Instant::now();
        let mut report = LoadReport::default();
        let end = store.fingerprint_log_end()?;
        let store_id = store.store_identity()?;
        if let Some(path) = &snapshot {
            let entry = |seq: i64| store.fingerprint_log_entry(seq);
            match snapshot::read(path, &store_id, end, &entry) {
                Ok(Some((families, tags, at))) => {
                    let index = Index {
                        families: std::sync::Arc::new(RwLock::new(families)),
                        retraining: Default::default(),
                        tags: RwLock::new(tags),
                        synced: std::sync::Mutex::new(at),
                        snapshot: snapshot.clone(),
                        store_id: store_id.clone(),
                        changed: Default::default(),
                        writing: Default::default(),
                        auditing: Default::default(),
                    };
                    index.copy_tags();
                    // The log's later changes applied, the snapshot must hold what the store holds.
                    match index.check_counts(store)? {
                        Ok(()) => {
                            report.from = "snapshot";
                            report.fingerprints = index.len();
                            report.seconds = t.elapsed().as_secs_f64();
                            return Ok((index, report));
                        }
                        Err(why) => report.snapshot_refused = Some(why),
                    }
                }
                Ok(None) => {}
                Err(e) => report.snapshot_refused = Some(e.to_string()),
            }
        }
        let mut index = Index { snapshot, store_id, ..Default::default() };
        // The log's end first: a change made while the tables are read is applied again by the next sync, which
        // is harmless (a put replaces, a removal forgets, tags are set whole).
        *index.synced.get_mut().unwrap_or_else(|e| e.into_inner()) =
            (end, store.fingerprint_log_entry(end)?.unwrap_or_default());
        {
            let mut fams = index.families.write().unwrap_or_else(|e| e.into_inner());
            // Each family's arrays reserved at their final size: grown by doubling they would be held twice while
            // copied.
            for (family, n) in store.fingerprint_counts()? {
                let fam = fams.entry(family).or_default();
                fam.expect = n;
                fam.ids.reserve_exact(n);
                fam.err.reserve_exact(n);
                fam.row.reserve(n);
            }
            store.for_each_fingerprint(&mut |family, id, values| {
                if let Some(id) = ShapeId::parse(id) {
                    fams.entry(family.to_string()).or_default().put(id, values, false);
                }
            })?;
            for fam in fams.values_mut() {
                fam.train(faer::Par::rayon(0));
            }
            drop(fams);
            let tags = index.tags.get_mut().unwrap_or_else(|e| e.into_inner());
            let mut by_shape: HashMap<ShapeId, Vec<Tag>> = HashMap::new();
            store.for_each_tag(&mut |id, tag| {
                if let (Some(id), Ok(tag)) = (ShapeId::parse(id), Tag::parse(tag)) {
                    by_shape.entry(id).or_default().push(tag);
                }
            })?;
            for (id, t) in by_shape {
                tags.set(id, t);
            }
        }
        index.copy_tags();
        index.sync(store)?;
        report.from = "store";
        report.fingerprints = index.len();
        if index.snapshot.is_some() && report.fingerprints > 0 {
            index.write_snapshot(store)?;
        }
        report.seconds = t.elapsed().as_secs_f64();
        Ok((index, report))
    }

    /// Whether the index holds no fingerprint.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// Builds every family's copies of its small tags' rows from the tags (after a load: the copies are not in the
    /// snapshot).
    fn copy_tags(&self) {
        let mut fams = self.families.write().unwrap_or_else(|e| e.into_inner());
        let tags = self.tags.read().unwrap_or_else(|e| e.into_inner());
        for fam in fams.values_mut() {
            for (tag, ids) in &tags.by_tag {
                for id in ids {
                    fam.tag_add(tag, id);
                }
            }
        }
    }
    /// Starts, on a thread of its own, the training of a family's cells that one wants (one at a time).
    fn maybe_retrain(&self) {
        use std::sync::atomic::Ordering::SeqCst;
        let name = {
            let fams = self.families.read().unwrap_or_else(|e| e.into_inner());
            fams.iter().find(|(_, f)| f.wants_training && f.journal.is_none()).map(|(n, _)| n.clone())
        };
        let Some(name) = name else { return };
        if self.retraining.swap(true, SeqCst) {
            return;
        }
        let (fams, running) = (self.families.clone(), self.retraining.clone());
        let started = std::thread::Builder::new().name("kac-index-training".into()).spawn(move || {
            let t = std::time::Instant::now();
            retrain(&fams, &name, faer::Par::Seq);
            tracing::info!(family = %name, seconds = t.elapsed().as_secs_f64(), "search index cells trained again");
            running.store(false, SeqCst);
        });
        if started.is_err() {
            self.retraining.store(false, SeqCst);
        }
    }
    /// Fingerprints held, over every family.
    pub fn len(&self) -> usize {
        self.families.read().unwrap_or_else(|e| e.into_inner()).values().map(Family::len).sum()
    }

    /// Whether the index, after applying the log's changes, holds as many rows in each family and as many tags as
    /// the store: `Err` with the first difference. The counts and the log's end are read between two reads of the
    /// log's end that agree, so that a change made meanwhile (by another replica) is not taken for a difference;
    /// a store that keeps changing through three tries is a doubt too.
    fn check_counts(&self, store: &dyn FingerprintStore) -> std::io::Result<Result<(), String>> {
        for _ in 0..3 {
            let before = store.fingerprint_log_end()?;
            self.apply_log(store)?;
            let counts = store.fingerprint_counts()?;
            let tag_count = store.tag_count()?;
            let after = store.fingerprint_log_end()?;
            let synced = self.synced.lock().unwrap_or_else(|e| e.into_inner()).0;
            if before != after || synced != after {
                continue;
            }
            let fams = self.families.read().unwrap_or_else(|e| e.into_inner());
            let held: HashMap<&str, usize> =
                fams.iter().filter(|(_, f)| f.len() > 0).map(|(n, f)| (n.as_str(), f.len())).collect();
            let stored: HashMap<&str, usize> =
                counts.iter().filter(|(_, n)| *n > 0).map(|(f, n)| (f.as_str(), *n)).collect();
            for (family, n) in &stored {
                let h = held.get(family).copied().unwrap_or(0);
                if h != *n {
                    return Ok(Err(format!(
                        "the search index snapshot holds {h} fingerprints of family {family} after the log's \
                         changes, the store {n}: it diverged from this store"
                    )));
                }
            }
            if let Some((family, h)) = held.iter().find(|(f, _)| !stored.contains_key(*f)) {
                return Ok(Err(format!(
                    "the search index snapshot holds {h} fingerprints of family {family}, which the store does not \
                     hold: it diverged from this store"
                )));
            }
            let tags: usize = self.tags.read().unwrap_or_else(|e| e.into_inner()).by_shape.values().map(Vec::len).sum();
            if tags != tag_count {
                return Ok(Err(format!(
                    "the search index snapshot holds {tags} tags after the log's changes, the store {tag_count}: it \
                     diverged from this store"
                )));
            }
            return Ok(Ok(()));
        }
        Ok(Err("the store changed while the search index snapshot was checked against it, three times".into()))
    }

    /// Writes the snapshot (when the index has a place for one): the log's changes applied first, so that the
    /// position written covers every change the rows hold that the store had logged; then the position, every
    /// family and the tags, atomically (a temporary file renamed).
    pub fn write_snapshot(&self, store: &dyn FingerprintStore) -> std::io::Result<()> {
        let Some(path) = &self.snapshot else { return Ok(()) };
        // Another thread writing one already: this one's changes go into the next.
        let Ok(_writing) = self.writing.try_lock() else { return Ok(()) };
        self.apply_log(store)?;
        // The position and the read locks under the sync lock, so that no change at or below the position is
        // missing from what is written; the sync lock is let go before the (long) write, so that searches, which
        // read the log first, go on while it is written. A change the index holds beyond the position (applied by
        // this replica as it made it, before its log entry is read back) is applied again from the log at the next
        // start, which is harmless (a put replaces, a removal forgets, tags are set whole).
        let synced = self.synced.lock().unwrap_or_else(|e| e.into_inner());
        let fams = self.families.read().unwrap_or_else(|e| e.into_inner());
        let tags = self.tags.read().unwrap_or_else(|e| e.into_inner());
        let at = synced.clone();
        drop(synced);
        self.changed.store(0, std::sync::atomic::Ordering::Relaxed);
        snapshot::write(path, &self.store_id, &at, &fams, &tags)
    }

    /// Writes the snapshot if anything changed since the last one.
    pub fn persist(&self, store: &dyn FingerprintStore) -> std::io::Result<()> {
        if self.changed.load(std::sync::atomic::Ordering::Relaxed) > 0 {
            self.write_snapshot(store)?;
        }
        Ok(())
    }

    /// Writes a snapshot when a tenth of the index (at least 10,000 fingerprints) changed since the last one.
    fn maybe_snapshot(&self, store: &dyn FingerprintStore) {
        let changed = self.changed.load(std::sync::atomic::Ordering::Relaxed);
        if self.snapshot.is_some() && changed >= 10_000 && changed >= self.len() / 10 {
            if let Err(e) = self.write_snapshot(store) {
                tracing::warn!(error = %e, "the search index snapshot could not be written");
            }
        }
    }

    /// Applies the changes the store logged since the last sync (fingerprints other replicas computed, shapes
    /// they removed, tags they set); one indexed query when there are none.
    pub fn sync(&self, store: &dyn FingerprintStore) -> std::io::Result<()> {
        if self.apply_log(store)? > 0 {
            self.maybe_snapshot(store);
        }
        Ok(())
    }
    /// [`Index::sync`] without a snapshot: the number of changes applied.
    fn apply_log(&self, store: &dyn FingerprintStore) -> std::io::Result<usize> {
        let mut synced = self.synced.lock().unwrap_or_else(|e| e.into_inner());
        let (changes, end) = store.fingerprint_changes(synced.0)?;
        let last = changes.last().map(|c| c.shape_id().to_string());
        let n = changes.len();
        for change in changes {
            match change {
                FingerprintChange::Kept { family, shape_id, values } => {
                    self.insert(&Fingerprint { family, shape_id, values })
                }
                FingerprintChange::Removed { shape_id } => self.remove_shape(&shape_id),
                FingerprintChange::Tagged { shape_id, tags } => self.set_tags(&shape_id, &tags),
            }
        }
        if let Some(last) = last {
            *synced = (end, last);
        }
        Ok(n)
    }
    fn insert(&self, f: &Fingerprint) {
        let Some(id) = ShapeId::parse(&f.shape_id) else { return };
        let mut fams = self.families.write().unwrap_or_else(|e| e.into_inner());
        let fam = fams.entry(f.family.clone()).or_default();
        fam.put(id, &f.values, true);
        let wants = fam.wants_training;
        let tags = self.tags.read().unwrap_or_else(|e| e.into_inner());
        for t in tags.by_shape.get(&id).into_iter().flatten() {
            fam.tag_add(t, &id);
        }
        self.changed.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        drop(tags);
        drop(fams);
        if wants {
            self.maybe_retrain();
        }
    }
    /// Keeps a fingerprint: in the store, then in the index; not at all when its shape is no longer stored.
    pub fn record(&self, store: &dyn FingerprintStore, f: &Fingerprint) -> std::io::Result<()> {
        if store.put_fingerprint(&f.family, &f.shape_id, &f.values)? {
            self.insert(f);
            self.maybe_snapshot(store);
        }
        Ok(())
    }
    /// Forgets a deleted shape in every family and its tags (the store drops its rows with the shape).
    pub fn remove_shape(&self, id: &str) {
        let Some(id) = ShapeId::parse(id) else { return };
        let mut fams = self.families.write().unwrap_or_else(|e| e.into_inner());
        let mut tags = self.tags.write().unwrap_or_else(|e| e.into_inner());
        let held = tags.by_shape.get(&id).cloned().unwrap_or_default();
        let mut wants = false;
        for fam in fams.values_mut() {
            fam.remove(&id, &held);
            wants |= fam.wants_training;
        }
        tags.set(id, vec![]);
        self.changed.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        drop(tags);
        drop(fams);
        if wants {
            self.maybe_retrain();
        }
    }
    /// Sets a shape's tags in the index (the store already holds them).
    pub fn set_tags(&self, id: &str, tags: &[String]) {
        let Some(id) = ShapeId::parse(id) else { return };
        let new: Vec<Tag> = tags.iter().filter_map(|t| Tag::parse(t).ok()).collect();
        let mut fams = self.families.write().unwrap_or_else(|e| e.into_inner());
        let mut tags = self.tags.write().unwrap_or_else(|e| e.into_inner());
        let old = tags.by_shape.get(&id).cloned().unwrap_or_default();
        for fam in fams.values_mut() {
            for t in old.iter().filter(|t| !new.contains(t)) {
                fam.tag_remove(t, &id);
            }
            for t in new.iter().filter(|t| !old.contains(t)) {
                fam.tag_add(t, &id);
            }
        }
        tags.set(id, new);
        self.changed.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    }
    /// A shape's tags as this replica's index holds them (sorted).
    pub fn tags_of(&self, id: &str) -> Vec<String> {
        let Some(id) = ShapeId::parse(id) else { return vec![] };
        let tags = self.tags.read().unwrap_or_else(|e| e.into_inner());
        tags.by_shape.get(&id).map(|t| t.iter().map(|t| t.as_str().to_string()).collect()).unwrap_or_default()
    }

    /// The `count` nearest fingerprints of a family to a query (nearest first, ties by id), with exact distances:
    /// candidates by the single-precision rows (every row, the rows carrying the tags, or the index's nearest
    /// cells), then every candidate that may be among the nearest re-ranked by its exact values from `fetch`.
    pub fn nearest(&self, q: &Query, fetch: Fetch) -> Result<Found, SearchError> {
        let fams = self.families.read().unwrap_or_else(|e| e.into_inner());
        let Some(fam) = fams.get(q.family).filter(|f| f.len() > 0 && q.count > 0) else {
            return Ok(Found { neighbours: vec![], searched: 0, probed: 0, exact: true, method: Method::Scan });
        };
        if q.values.len() != fam.k {
            return Err(SearchError::Length(format!(
                "the fingerprint has {} values; this family's have {}",
                q.values.len(),
                fam.k
            )));
        }
        let tags = self.tags.read().unwrap_or_else(|e| e.into_inner());
        let sets: Option<Vec<&IdSet>> = q.tags.iter().map(|t| tags.by_tag.get(t)).collect();
        let Some(mut sets) = sets else {
            // A tag no shape carries.
            return Ok(Found { neighbours: vec![], searched: fam.len(), probed: 0, exact: true, method: Method::Scan });
        };
        sets.sort_by_key(|s| s.len());
        let admits = |id: &ShapeId| Some(id) != q.exclude.as_ref() && sets.iter().all(|s| s.contains(id));
        let sub_err = |table: &Family, r: usize| match q.metric {
            // Each term changes by at most 2·2⁻²⁴ under a relative rounding of 2⁻²⁴.
            Metric::Canberra if table.err[r].is_finite() => 1.3e-7 * table.k as f64,
            _ => table.err[r] as f64,
        };
        let err = |r: usize| sub_err(fam, r);
        let mut c = Collector::new(q.count);
        let copy = q.tags.iter().filter_map(|t| fam.subs.get(t)).min_by_key(|s| s.len());
        let (method, exact) = if let Some(sub) = copy {
            // A small tag's rows, contiguous.
            for r in 0..sub.len() {
                if admits(&sub.ids[r]) {
                    c.offer(approx_distance(q.values, sub.row_of(r), q.metric), sub_err(sub, r), r as u32);
                }
            }
            (Method::Scan, true)
        } else if let Some(few) = sets.first().filter(|s| s.len() <= ivf::MIN_ROWS.max(fam.len() / 16)) {
            // A small filter: its members' rows, every one, in memory order.
            let mut rows: Vec<u32> = few
                .iter()
                .filter(|id| Some(*id) != q.exclude.as_ref() && sets[1..].iter().all(|s| s.contains(id)))
                .filter_map(|id| fam.row.get(id).copied())
                .collect();
            rows.sort_unstable();
            for r in rows {
                let r = r as usize;
                c.offer(approx_distance(q.values, fam.row_of(r), q.metric), err(r), r as u32);
            }
            (Method::Scan, true)
        } else if let (Some(ivf), false, false) = (&fam.ivf, q.exact, q.metric == Metric::Canberra) {
            let mut probed_cells = 0;
            let mut proven = false;
            for (bound, cell) in ivf.plan(q.values) {
                if bound - fam.err_max as f64 > c.bound() {
                    proven = true;
                    break;
                }
                if probed_cells >= q.max_cells {
                    break;
                }
                probed_cells += 1;
                for &r in &ivf.lists[cell as usize] {
                    let r = r as usize;
                    if admits(&fam.ids[r]) {
                        c.offer(approx_distance(q.values, fam.row_of(r), q.metric), err(r), r as u32);
                    }
                }
            }
            // Every cell probed is a proof too.
            (Method::Index, proven || probed_cells == ivf.cells())
        } else {
            for r in 0..fam.len() {
                if admits(&fam.ids[r]) {
                    c.offer(approx_distance(q.values, fam.row_of(r), q.metric), err(r), r as u32);
                }
            }
            (Method::Scan, true)
        };
        let probed = c.offered;
        let table = copy.unwrap_or(fam);
        let ids: Vec<String> = c.rows().into_iter().map(|r| table.ids[r as usize].hex()).collect();
        let searched = fam.len();
        drop(tags);
        drop(fams);
        let exact_values = fetch(q.family, &ids).map_err(SearchError::Store)?;
        let n_candidates = ids.len();
        let mut scored: Vec<(String, f64)> = ids
            .into_iter()
            .filter_map(|id| {
                let v = exact_values.get(&id)?;
                let d = shape_dna::distance(q.values, v, q.metric).ok()?;
                Some((id, d))
            })
            .collect();
        // A candidate the store no longer holds (removed on another replica, or a fingerprint kept in the index as
        // its shape was deleted) may have crowded out another: the answer is then not proven.
        let exact = exact && scored.len() == n_candidates;
        scored.sort_by(|a, b| a.1.total_cmp(&b.1).then(a.0.cmp(&b.0)));
        scored.truncate(q.count);
        Ok(Found { neighbours: scored, searched, probed, exact, method })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A shape id made from a number.
    fn sid(i: usize) -> ShapeId {
        let mut b = [0u8; 32];
        b[..8].copy_from_slice(&(i as u64).to_be_bytes());
        ShapeId(b)
    }

    /// Clustered rows like shape-DNA: ascending values around a few hundred centres.
    fn rows(n: usize, k: usize, seed: u64) -> Vec<Vec<f64>> {
        let mut x = seed | 1;
        let mut rnd = move || {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            (x >> 11) as f64 / (1u64 << 53) as f64
        };
        let centres: Vec<Vec<f64>> = (0..300)
            .map(|_| {
                let s = 0.5 + rnd();
                (0..k).map(|j| s * (j + 1) as f64 * (1.0 + 0.2 * rnd())).collect()
            })
            .collect();
        (0..n)
            .map(|i| {
                let c = &centres[(i * 7919) % centres.len()];
                let w = 0.02 * rnd();
                c.iter().map(|v| v * (1.0 + w * (rnd() - 0.5))).collect()
            })
            .collect()
    }

    fn brute(
        all: &HashMap<String, Vec<f64>>,
        q: &[f64],
        metric: Metric,
        count: usize,
        admit: impl Fn(&str) -> bool,
    ) -> Vec<(String, f64)> {
        let mut v: Vec<(String, f64)> = all
            .iter()
            .filter(|(id, _)| admit(id))
            .map(|(id, x)| (id.clone(), shape_dna::distance(q, x, metric).unwrap()))
            .collect();
        v.sort_by(|a, b| a.1.total_cmp(&b.1).then(a.0.cmp(&b.0)));
        v.truncate(count);
        v
    }

    fn query<'a>(values: &'a [f64], metric: Metric, tags: &'a [Tag], exact: bool, cells: usize) -> Query<'a> {
        Query { family: "a", values, metric, count: 10, exclude: Some(sid(3)), tags, exact, max_cells: cells }
    }

    /// Nearest first with exact distances, ties by id, the excluded shape left out, tags honoured, replaced and
    /// removed rows seen at once: against sorting every exact distance, by scan and through the cells; and every
    /// answer the index calls exact is the exact one.
    #[test]
    fn searches_agree_with_sorting_every_distance() {
        let k = 12;
        let n = ivf::MIN_ROWS + 4000;
        let index = Index::default();
        let mut all = HashMap::new();
        for (i, v) in rows(n, k, 7).into_iter().enumerate() {
            index.insert(&Fingerprint { family: "a".into(), shape_id: sid(i).hex(), values: v.clone() });
            all.insert(sid(i).hex(), v);
        }
        assert!(index.families.read().unwrap()["a"].ivf.is_some(), "the family has cells");
        // Tags: a small one (every 50th shape), a larger one (those and the odd ones), both copied contiguous; and
        // one on nine shapes in ten, too many for a copy (searched through the cells with a filter).
        let tags_of = |i: usize| {
            let mut t: Vec<String> = vec![];
            if i.is_multiple_of(50) {
                t.push("few".into());
            }
            if i.is_multiple_of(50) || !i.is_multiple_of(2) {
                t.push("half".into());
            }
            if !i.is_multiple_of(10) {
                t.push("most".into());
            }
            t
        };
        for i in 0..n {
            index.set_tags(&sid(i).hex(), &tags_of(i));
        }
        {
            let fams = index.families.read().unwrap();
            let (a, t) = (&fams["a"], |s: &str| Tag::parse(s).unwrap());
            assert!(a.subs.contains_key(&t("few")) && a.subs.contains_key(&t("half")), "small tags are copied");
            assert!(a.large.contains(&t("most")), "too many for a copy");
        }
        // A replaced row (tagged: its copies follow), a removed one, another family apart.
        let moved = rows(1, k, 99).remove(0);
        index.insert(&Fingerprint { family: "a".into(), shape_id: sid(50).hex(), values: moved.clone() });
        all.insert(sid(50).hex(), moved.clone());
        index.remove_shape(&sid(51).hex());
        all.remove(&sid(51).hex());
        index.insert(&Fingerprint { family: "b".into(), shape_id: sid(1).hex(), values: vec![0.0; k] });
        // A shape moved out of two tags, another into all three.
        index.set_tags(&sid(100).hex(), &["half".to_string()]);
        index.set_tags(&sid(7).hex(), &["few".to_string(), "half".to_string(), "most".to_string()]);
        let tagged = |id: &str, tag: &str| {
            let i = u64::from_be_bytes(ShapeId::parse(id).unwrap().0[..8].try_into().unwrap()) as usize;
            match i {
                100 => tag == "half",
                7 => true,
                _ => tags_of(i).iter().any(|t| t == tag),
            }
        };
        let fetch =
            |_: &str, ids: &[String]| Ok(ids.iter().filter_map(|i| Some((i.clone(), all.get(i)?.clone()))).collect());
        let not3 = |id: &str| id != sid(3).hex();
        let queries = rows(40, k, 1234);
        let (few, half, most) =
            ([Tag::parse("few").unwrap()], [Tag::parse("half").unwrap()], [Tag::parse("most").unwrap()]);
        let mut proven = 0;
        for (qi, q) in queries.iter().enumerate() {
            for metric in [Metric::Euclidean, Metric::Manhattan, Metric::Canberra] {
                let want = brute(&all, q, metric, 10, not3);
                let scan = index.nearest(&query(q, metric, &[], true, 8), &fetch).unwrap();
                assert_eq!((scan.neighbours.clone(), scan.exact, scan.method), (want.clone(), true, Method::Scan));
                let got = index.nearest(&query(q, metric, &[], false, 8), &fetch).unwrap();
                if got.exact {
                    proven += 1;
                    assert_eq!(got.neighbours, want, "query {qi}, {metric}: called exact");
                }
                assert_eq!(got.searched, n - 1);
                // All cells: exact, whatever the bounds.
                let every = index.nearest(&query(q, metric, &[], false, usize::MAX), &fetch).unwrap();
                assert_eq!((every.neighbours, every.exact), (want, true));
                let small = index.nearest(&query(q, metric, &few, false, 8), &fetch).unwrap();
                let want = brute(&all, q, metric, 10, |id| not3(id) && tagged(id, "few"));
                assert_eq!((small.neighbours, small.exact, small.method), (want, true, Method::Scan));
                let larger = index.nearest(&query(q, metric, &half, false, 8), &fetch).unwrap();
                let want = brute(&all, q, metric, 10, |id| not3(id) && tagged(id, "half"));
                assert_eq!((larger.neighbours, larger.exact), (want, true));
                let large = index.nearest(&query(q, metric, &most, false, usize::MAX), &fetch).unwrap();
                let want = brute(&all, q, metric, 10, |id| not3(id) && tagged(id, "most"));
                assert_eq!(large.neighbours, want);
                let two = [few[0].clone(), most[0].clone()];
                let both = index.nearest(&query(q, metric, &two, false, 8), &fetch).unwrap();
                let want = brute(&all, q, metric, 10, |id| not3(id) && tagged(id, "few") && tagged(id, "most"));
                assert_eq!(both.neighbours, want);
            }
        }
        assert!(proven > 0, "some answers are proven exact by the cells' bounds");
        let q = &queries[0];
        assert!(matches!(
            index.nearest(&query(&q[..3], Metric::Euclidean, &[], false, 8), &fetch),
            Err(SearchError::Length(_))
        ));
        let none = index.nearest(&query(q, Metric::Euclidean, &[Tag::parse("nobody").unwrap()], false, 8), &fetch);
        assert!(none.unwrap().neighbours.is_empty());
    }

    /// A snapshot read back answers as the index it was written from; one beyond the store's log, or cut short,
    /// is refused.
    #[test]
    fn a_snapshot_reads_back_as_it_was_written() {
        let k = 6;
        let index = Index::default();
        let mut all = HashMap::new();
        for (i, v) in rows(ivf::MIN_ROWS + 100, k, 3).into_iter().enumerate() {
            index.insert(&Fingerprint { family: "a".into(), shape_id: sid(i).hex(), values: v.clone() });
            all.insert(sid(i).hex(), v);
        }
        index.set_tags(&sid(5).hex(), &["x".into()]);
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("search-index.bin");
        let fams = index.families.read().unwrap();
        let log = |seq: i64| Ok((seq == 42).then(|| sid(9).hex()));
        snapshot::write(&path, "store-a", &(42, sid(9).hex()), &fams, &index.tags.read().unwrap()).unwrap();
        assert!(snapshot::read(&path, "store-b", 42, &log).is_err(), "another store's snapshot is refused");
        let (families, tags, at) = snapshot::read(&path, "store-a", 42, &log).unwrap().unwrap();
        assert_eq!(at, (42, sid(9).hex()));
        let back = Index {
            families: std::sync::Arc::new(RwLock::new(families)),
            tags: RwLock::new(tags),
            ..Default::default()
        };
        let fetch =
            |_: &str, ids: &[String]| Ok(ids.iter().filter_map(|i| Some((i.clone(), all.get(i)?.clone()))).collect());
        for q in rows(5, k, 77) {
            for cells in [4, usize::MAX] {
                let (a, b) = (
                    index.nearest(&query(&q, Metric::Euclidean, &[], false, cells), &fetch).unwrap(),
                    back.nearest(&query(&q, Metric::Euclidean, &[], false, cells), &fetch).unwrap(),
                );
                assert_eq!((a.neighbours, a.probed, a.exact), (b.neighbours, b.probed, b.exact));
            }
        }
        assert_eq!(back.tags.read().unwrap().by_shape[&sid(5)], vec![Tag::parse("x").unwrap()]);
        assert!(snapshot::read(&path, "store-a", 41, &log).is_err(), "a snapshot beyond the log is refused");
        let other = |_: i64| Ok(Some(sid(8).hex()));
        assert!(snapshot::read(&path, "store-a", 50, &other).is_err(), "a snapshot of another store's log is refused");
        let bytes = std::fs::read(&path).unwrap();
        std::fs::write(&path, &bytes[..bytes.len() - 9]).unwrap();
        assert!(snapshot::read(&path, "store-a", 42, &log).is_err(), "a snapshot cut short is refused");
        assert!(snapshot::read(&dir.path().join("none"), "store-a", 42, &log).unwrap().is_none());
    }

    /// One bit flipped in any region of a snapshot (its header, ids, rows, rounding bounds, cells, tags, end or
    /// checksum) is refused, never read as an index; a small family without cells (the shutdown snapshot of a
    /// small store) reads back.
    #[test]
    fn a_snapshot_with_a_bit_flipped_anywhere_is_refused() {
        let (k, n) = (6, ivf::MIN_ROWS + 100);
        let index = Index::default();
        for (i, v) in rows(n, k, 5).into_iter().enumerate() {
            index.insert(&Fingerprint { family: "a".into(), shape_id: sid(i).hex(), values: v });
        }
        index.set_tags(&sid(5).hex(), &["x".into(), "yy".into()]);
        index.set_tags(&sid(7).hex(), &["x".into()]);
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("search-index.bin");
        let at = (42, sid(9).hex());
        let log = |seq: i64| Ok((seq == 42).then(|| sid(9).hex()));
        let cells = {
            let fams = index.families.read().unwrap();
            snapshot::write(&path, "store-a", &at, &fams, &index.tags.read().unwrap()).unwrap();
            fams["a"].ivf.as_ref().expect("a family this large has cells").cells()
        };
        assert!(snapshot::read(&path, "store-a", 42, &log).unwrap().is_some());
        let bytes = std::fs::read(&path).unwrap();
        // The layout, region by region.
        let header = 8 + (4 + 7) + 8 + (4 + 64) + 4;
        let ids = header + (4 + 1) + 4 + 8;
        let vals = ids + 32 * n;
        let bounds = vals + 4 * n * k;
        let ivf_at = bounds + 4 * n + 4;
        let centroids = ivf_at + 4 + 8 + 8;
        let row_cell = centroids + 8 * cells * k;
        let tags = row_cell + 4 * n;
        let end = bytes.len() - 12;
        assert_eq!(end - tags, 8 + (32 + 4 + 5 + 6) + (32 + 4 + 5), "the tags region as laid out");
        let regions = [
            ("magic", 0, 8),
            ("store id", 8, 19),
            ("log position", 19, header - 4),
            ("family count", header - 4, header),
            ("family name and sizes", header, ids),
            ("ids", ids, vals),
            ("rows", vals, bounds),
            ("rounding bounds", bounds, ivf_at),
            ("cells' sizes and slack", ivf_at, centroids),
            ("centroids", centroids, row_cell),
            ("rows' cells", row_cell, tags),
            ("tags", tags, end),
            ("end", end, end + 8),
            ("checksum", end + 8, bytes.len()),
        ];
        let mut bit = 0;
        for (name, from, to) in regions {
            assert!(from < to && to <= bytes.len(), "{name}: {from}..{to}");
            for at in [from, (from + to) / 2, to - 1] {
                bit = (bit + 3) % 8;
                let mut flipped = bytes.clone();
                flipped[at] ^= 1 << bit;
                std::fs::write(&path, &flipped).unwrap();
                assert!(
                    snapshot::read(&path, "store-a", 42, &log).is_err(),
                    "a bit flipped in the {name} (byte {at}, bit {bit}) is refused"
                );
            }
        }
        // Bytes after the checksum too.
        let mut longer = bytes.clone();
        longer.push(0);
        std::fs::write(&path, &longer).unwrap();
        assert!(snapshot::read(&path, "store-a", 42, &log).is_err(), "bytes after the end are refused");
        // A small family without cells and without tags: the file is barely larger than its rows.
        let small = Index::default();
        for (i, v) in rows(50, 10, 6).into_iter().enumerate() {
            small.insert(&Fingerprint { family: "b".into(), shape_id: sid(i).hex(), values: v });
        }
        snapshot::write(&path, "store-a", &at, &small.families.read().unwrap(), &small.tags.read().unwrap()).unwrap();
        let (families, _, _) = snapshot::read(&path, "store-a", 42, &log).unwrap().expect("the small snapshot loads");
        assert_eq!(families["b"].len(), 50);
    }

    /// A fuzz pass over the snapshot reader: 2,000 snapshots mutated at random (bits flipped, bytes overwritten,
    /// cut short, extended, stretches moved), each refused with an error, never a panic, never read as an index.
    #[test]
    fn mutated_snapshots_are_refused_without_panicking() {
        let index = Index::default();
        for (i, v) in rows(300, 5, 9).into_iter().enumerate() {
            index.insert(&Fingerprint { family: format!("f{}", i % 3), shape_id: sid(i).hex(), values: v });
        }
        index.set_tags(&sid(1).hex(), &["t".into()]);
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("search-index.bin");
        let log = |seq: i64| Ok((seq == 7).then(|| sid(2).hex()));
        snapshot::write(&path, "s", &(7, sid(2).hex()), &index.families.read().unwrap(), &index.tags.read().unwrap())
            .unwrap();
        let bytes = std::fs::read(&path).unwrap();
        let mut x = 0x9E37_79B9_7F4A_7C15u64;
        let mut rnd = move |n: usize| {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            (x >> 11) as usize % n.max(1)
        };
        for round in 0..2_000 {
            let mut m = bytes.clone();
            match round % 5 {
                0 => {
                    let at = rnd(m.len());
                    m[at] ^= 1 << rnd(8);
                }
                1 => {
                    for _ in 0..1 + rnd(8) {
                        let at = rnd(m.len());
                        m[at] = rnd(256) as u8;
                    }
                }
                2 => m.truncate(rnd(m.len())),
                3 => m.extend((0..1 + rnd(64)).map(|_| rnd(256) as u8)),
                _ => {
                    let (a, b) = (rnd(m.len()), rnd(m.len()));
                    let len = rnd(64).min(m.len() - a.max(b));
                    m.copy_within(a..a + len, b);
                }
            }
            if m == bytes {
                continue;
            }
            std::fs::write(&path, &m).unwrap();
            assert!(snapshot::read(&path, "s", 7, &log).is_err(), "mutation {round} refused");
        }
    }

    /// Cells trained again off the lock follow every change made while they were trained (rows added, replaced,
    /// removed before and after the pass reached them, and after it ended): each row in one cell, its nearest
    /// centroid's, and searches exact against sorting every distance.
    #[test]
    fn cells_trained_again_off_the_lock_follow_the_changes_made_meanwhile() {
        let k = 8;
        let index = Index::default();
        let mut all = HashMap::new();
        let put = |index: &Index, all: &mut HashMap<String, Vec<f64>>, i: usize, v: Vec<f64>| {
            index.insert(&Fingerprint { family: "a".into(), shape_id: sid(i).hex(), values: v.clone() });
            all.insert(sid(i).hex(), v);
        };
        let drop_row = |index: &Index, all: &mut HashMap<String, Vec<f64>>, i: usize| {
            index.remove_shape(&sid(i).hex());
            all.remove(&sid(i).hex());
        };
        let base = rows(ivf::MIN_ROWS + 3000, k, 11);
        for (i, v) in base.iter().enumerate() {
            put(&index, &mut all, i, v.clone());
        }
        let extra = rows(3000, k, 12);
        let fams = index.families.clone();
        let mut t = begin_retraining(&fams, "a", faer::Par::Seq).expect("a family with cells");
        assert!(begin_retraining(&fams, "a", faer::Par::Seq).is_none(), "one training at a time");
        // Before the pass: added, replaced and removed rows at both ends.
        for (j, v) in extra.iter().take(500).enumerate() {
            put(&index, &mut all, 100_000 + j, v.clone());
        }
        for i in [0, 1, 5000, ivf::MIN_ROWS + 2990] {
            put(&index, &mut all, i, extra[2000 + i % 1000].clone());
        }
        for i in [2, 3, 4, 7000] {
            drop_row(&index, &mut all, i);
        }
        // During the pass.
        let mut step = 0;
        while retraining_step(&fams, &mut t, 2048, faer::Par::Seq) {
            step += 1;
            put(&index, &mut all, 200_000 + step, extra[1000 + step].clone());
            drop_row(&index, &mut all, 10 * step + 1);
            put(&index, &mut all, 20 * step, extra[1500 + step].clone());
        }
        // After it.
        for (j, v) in extra[2500..2800].iter().enumerate() {
            put(&index, &mut all, 300_000 + j, v.clone());
        }
        drop_row(&index, &mut all, 12_000);
        finish_retraining(&fams, t, faer::Par::Seq);
        {
            let g = fams.read().unwrap();
            let fam = &g["a"];
            let ivf = fam.ivf.as_ref().unwrap();
            assert!(fam.journal.is_none());
            assert_eq!((ivf.row_cell.len(), fam.len(), all.len()), (fam.len(), all.len(), all.len()));
            let mut seen = vec![0; fam.len()];
            for (c, list) in ivf.lists.iter().enumerate() {
                for (p, &r) in list.iter().enumerate() {
                    seen[r as usize] += 1;
                    assert_eq!((ivf.row_cell[r as usize] as usize, ivf.row_pos[r as usize] as usize), (c, p));
                }
            }
            assert!(seen.iter().all(|&s| s == 1), "each row in one cell");
            for r in 0..fam.len() {
                let x: Vec<f64> = fam.row_of(r).iter().map(|&v| v as f64).collect();
                let d = |c: usize| -> f64 {
                    ivf.centroids[c * k..(c + 1) * k].iter().zip(&x).map(|(a, b)| (a - b) * (a - b)).sum()
                };
                let own = d(ivf.row_cell[r] as usize);
                let best = (0..ivf.cells()).map(d).fold(f64::INFINITY, f64::min);
                assert!(
                    own <= best + ivf.slack + 1e-9 * best.max(1.0),
                    "row {r}: its cell is not its nearest centroid's"
                );
            }
        }
        let fetch =
            |_: &str, ids: &[String]| Ok(ids.iter().filter_map(|i| Some((i.clone(), all.get(i)?.clone()))).collect());
        for q in rows(20, k, 13) {
            let want = brute(&all, &q, Metric::Euclidean, 10, |id| id != sid(3).hex());
            let every = index.nearest(&query(&q, Metric::Euclidean, &[], false, usize::MAX), &fetch).unwrap();
            assert_eq!(every.neighbours, want);
            let some = index.nearest(&query(&q, Metric::Euclidean, &[], false, 8), &fetch).unwrap();
            if some.exact {
                assert_eq!(some.neighbours, want);
            }
        }
    }

    #[test]
    fn tags_parse_at_the_boundary() {
        assert_eq!(Tag::parse_all(&["b", "a", "b"]).unwrap(), vec![Tag::parse("a").unwrap(), Tag::parse("b").unwrap()]);
        for bad in ["", "a b", "é", "x\n", &"y".repeat(65)] {
            assert!(Tag::parse(bad).is_err(), "{bad:?}");
        }
        assert!(Tag::parse_all(&(0..33).map(|i| i.to_string()).collect::<Vec<_>>()).is_err());
    }
}
