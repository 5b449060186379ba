//! Search for retrieval back ends (`POST /v1/search`): the stored shapes nearest to a given shape or fingerprint
//! by shape-DNA. Every fingerprint a `shape-dna` job or a comparison computes is kept in the store (by family:
//! the parameters it was computed with) and in an in-memory index loaded at start, so a search scans contiguous
//! rows of one family (100,000 fingerprints of 50 values in a few milliseconds; `bench/search.py`).

use super::ids::ShapeId;
use super::store::{FingerprintChange, FingerprintStore};
use crate::analysis::Fingerprint;
use kac_core::descriptors::shape_dna::{self, Metric};
use serde::Serialize;
use std::collections::HashMap;
use std::sync::RwLock;

mod audit;
mod bounds;
mod family;
mod fused;
mod idhash;
pub mod ivf;
mod query;
mod retrain;
mod snapshot;
mod tags;
pub use audit::{AuditReport, FamilyAudit, TagAudit};
use bounds::*;
use family::*;
pub use fused::{FusedFound, FusedQuery, Member};
use idhash::*;
use ivf::Ivf;
use query::Collector;
pub use query::{Fetch, Found, Method, Query, SearchError};
use retrain::*;
use tags::Tags;
pub use tags::{Tag, MAX_TAGS};

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
    pub(super) fn sid(i: usize) -> ShapeId {
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
