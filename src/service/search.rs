//! Search for retrieval back ends (`POST /v1/search`): the stored shapes nearest to a given shape or fingerprint
//! by shape-DNA. Every fingerprint a `shape-dna` job or a comparison computes is kept in the store (by family:
//! the parameters it was computed with) and in an in-memory index loaded at start, so a search scans contiguous
//! rows of one family (100,000 fingerprints of 50 values in a few milliseconds; `bench/search.py`).

use super::store::FingerprintStore;
use crate::analysis::{self, Fingerprint, OperatorSpec};
use kac_core::descriptors::shape_dna::{self, Metric, ShapeDnaOptions};
use serde::{Deserialize, Serialize};
use std::collections::HashMap;
use std::sync::RwLock;

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

/// The fingerprints of one family: ids and their rows of `k` values, contiguous.
#[derive(Default)]
struct Family {
    k: usize,
    ids: Vec<String>,
    row: HashMap<String, usize>,
    values: Vec<f64>,
}

impl Family {
    fn put(&mut self, id: &str, v: &[f64]) {
        if self.ids.is_empty() {
            self.k = v.len();
        }
        if v.len() != self.k {
            return;
        }
        match self.row.get(id) {
            Some(&r) => self.values[r * self.k..(r + 1) * self.k].copy_from_slice(v),
            None => {
                self.row.insert(id.to_string(), self.ids.len());
                self.ids.push(id.to_string());
                self.values.extend_from_slice(v);
            }
        }
    }
    fn remove(&mut self, id: &str) {
        let Some(r) = self.row.remove(id) else { return };
        // The last row moves into the hole.
        let last = self.ids.len() - 1;
        if r != last {
            let (k, moved) = (self.k, self.ids[last].clone());
            self.values.copy_within(last * k..(last + 1) * k, r * k);
            self.ids[r] = moved.clone();
            self.row.insert(moved, r);
        }
        self.ids.pop();
        self.values.truncate(last * self.k);
    }
}

/// The in-memory index of every stored fingerprint, by family, and how far it has followed the store's log of
/// fingerprint changes (which other replicas write too).
#[derive(Default)]
pub struct Index {
    families: RwLock<HashMap<String, Family>>,
    synced: std::sync::Mutex<i64>,
}

impl Index {
    /// The index of everything the store holds.
    pub fn load(store: &dyn FingerprintStore) -> std::io::Result<Index> {
        let index = Index::default();
        // The log's end first: a change made while the table is read is applied again by the next sync, which is
        // harmless (a put replaces, a removal forgets).
        *index.synced.lock().unwrap_or_else(|e| e.into_inner()) = store.fingerprint_log_end()?;
        for (family, id, values) in store.load_fingerprints()? {
            index.insert(&Fingerprint { family, shape_id: id, values });
        }
        Ok(index)
    }
    /// Applies the changes the store logged since the last sync (fingerprints other replicas computed, shapes
    /// they removed); one indexed query when there are none.
    pub fn sync(&self, store: &dyn FingerprintStore) -> std::io::Result<()> {
        let mut synced = self.synced.lock().unwrap_or_else(|e| e.into_inner());
        let (changes, end) = store.fingerprint_changes(*synced)?;
        for (family, shape_id, values) in changes {
            match values {
                Some(values) => self.insert(&Fingerprint { family, shape_id, values }),
                None => self.remove_shape(&shape_id),
            }
        }
        *synced = end;
        Ok(())
    }
    fn insert(&self, f: &Fingerprint) {
        let mut fams = self.families.write().unwrap_or_else(|e| e.into_inner());
        fams.entry(f.family.clone()).or_default().put(&f.shape_id, &f.values);
    }
    /// Keeps a fingerprint: in the store, then in the index; not at all when its shape is no longer stored.
    pub fn record(&self, store: &dyn FingerprintStore, f: &Fingerprint) -> std::io::Result<()> {
        if store.put_fingerprint(&f.family, &f.shape_id, &f.values)? {
            self.insert(f);
        }
        Ok(())
    }
    /// Forgets a deleted shape in every family (the store drops its rows with the shape).
    pub fn remove_shape(&self, id: &str) {
        for fam in self.families.write().unwrap_or_else(|e| e.into_inner()).values_mut() {
            fam.remove(id);
        }
    }
    /// A shape's fingerprint in a family, if the store holds one.
    pub fn get(&self, family: &str, id: &str) -> Option<Vec<f64>> {
        let fams = self.families.read().unwrap_or_else(|e| e.into_inner());
        let fam = fams.get(family)?;
        let r = *fam.row.get(id)?;
        Some(fam.values[r * fam.k..(r + 1) * fam.k].to_vec())
    }
    /// The `count` nearest fingerprints of a family to `query` (nearest first, ties by id), leaving out
    /// `exclude`; and how many fingerprints the family holds. `Err` when the query's length is not the family's.
    pub fn nearest(
        &self,
        family: &str,
        query: &[f64],
        metric: Metric,
        count: usize,
        exclude: Option<&str>,
    ) -> Result<(Vec<(String, f64)>, usize), String> {
        let fams = self.families.read().unwrap_or_else(|e| e.into_inner());
        let Some(fam) = fams.get(family).filter(|f| !f.ids.is_empty()) else { return Ok((vec![], 0)) };
        if query.len() != fam.k {
            return Err(format!("the fingerprint has {} values; this family's have {}", query.len(), fam.k));
        }
        let mut scored: Vec<(f64, usize)> = fam
            .values
            .chunks_exact(fam.k)
            .enumerate()
            .filter(|(r, _)| exclude != Some(fam.ids[*r].as_str()))
            .map(|(r, row)| (shape_dna::distance(query, row, metric).unwrap_or(f64::INFINITY), r))
            .collect();
        let order = |a: &(f64, usize), b: &(f64, usize)| a.0.total_cmp(&b.0).then(fam.ids[a.1].cmp(&fam.ids[b.1]));
        let count = count.min(scored.len());
        if count < scored.len() && count > 0 {
            scored.select_nth_unstable_by(count - 1, order);
        }
        scored.truncate(count);
        scored.sort_by(order);
        Ok((scored.into_iter().map(|(d, r)| (fam.ids[r].clone(), d)).collect(), fam.ids.len()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn fp(family: &str, id: &str, values: Vec<f64>) -> Fingerprint {
        Fingerprint { family: family.into(), shape_id: id.into(), values }
    }

    /// Nearest first by the metric, ties by id, the excluded shape left out, other families apart, a replaced or
    /// removed fingerprint gone; against a plain sort of every distance.
    #[test]
    fn nearest_agrees_with_sorting_every_distance() {
        let index = Index::default();
        let mut rows = vec![];
        for i in 0..500 {
            let v: Vec<f64> = (0..8).map(|j| ((i * 7 + j * 13) % 97) as f64 / 10.0).collect();
            index.insert(&fp("a", &format!("s{i:03}"), v.clone()));
            rows.push((format!("s{i:03}"), v));
        }
        index.insert(&fp("b", "other", vec![0.0; 8]));
        index.remove_shape("s007");
        rows.retain(|r| r.0 != "s007");
        index.insert(&fp("a", "s010", vec![1.0; 8]));
        rows.iter_mut().find(|r| r.0 == "s010").unwrap().1 = vec![1.0; 8];
        let q = vec![1.0; 8];
        for metric in [Metric::Euclidean, Metric::Manhattan, Metric::Canberra] {
            let (got, total) = index.nearest("a", &q, metric, 20, Some("s011")).unwrap();
            assert_eq!(total, 499);
            let mut all: Vec<(String, f64)> = rows
                .iter()
                .filter(|r| r.0 != "s011")
                .map(|r| (r.0.clone(), shape_dna::distance(&q, &r.1, metric).unwrap()))
                .collect();
            all.sort_by(|a, b| a.1.total_cmp(&b.1).then(a.0.cmp(&b.0)));
            all.truncate(20);
            assert_eq!(got, all);
            assert_eq!(got[0].0, "s010");
        }
        assert!(index.nearest("a", &[1.0; 3], Metric::Euclidean, 5, None).is_err());
        assert_eq!(index.nearest("c", &q, Metric::Euclidean, 5, None).unwrap(), (vec![], 0));
        assert_eq!(index.get("b", "other"), Some(vec![0.0; 8]));
    }
}
