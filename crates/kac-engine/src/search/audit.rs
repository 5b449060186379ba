//! The index checked row by row against the store (`GET /v1/search/audit`): what a search's `exact: true` proves
//! is exactness among the index's rows, and this is how one verifies that those rows are the store's.

use super::{rounding_bound, Family, Index, Tag};
use crate::ids::ShapeId;
use crate::store::FingerprintStore;
use serde::Serialize;
use std::collections::HashMap;

/// Differences kept by name (and checked again) per family; beyond them only counted.
const EXAMPLES: usize = 10_000;
/// Shape ids named in the report per family.
const NAMED: usize = 10;

/// One family's rows in the index against the store's.
#[derive(Debug, Serialize, utoipa::ToSchema)]
pub struct FamilyAudit {
    pub family: String,
    /// Fingerprints of the family in the store.
    pub store_rows: usize,
    /// Rows of the family in this replica's index.
    pub index_rows: usize,
    /// Stored fingerprints the index does not hold (these shapes could never be found).
    pub missing: usize,
    /// Rows the index holds that the store does not (shapes removed, or never stored).
    pub extra: usize,
    /// Rows whose single-precision values or rounding bound are not those of the stored fingerprint, or which
    /// no cell lists where the row says.
    pub differing: usize,
    /// Up to 10 shape ids of the rows counted above.
    pub examples: Vec<String>,
}

/// The index's tags against the store's.
#[derive(Debug, Serialize, utoipa::ToSchema)]
pub struct TagAudit {
    /// (shape, tag) pairs in the store.
    pub store: usize,
    /// (shape, tag) pairs in this replica's index.
    pub index: usize,
    /// Shapes whose tags differ.
    pub differing: usize,
    /// Up to 10 of them.
    pub examples: Vec<String>,
}

/// Every row and tag of this replica's search index compared with the store.
#[derive(Debug, Serialize, utoipa::ToSchema)]
pub struct AuditReport {
    /// Every row and every tag agree with the store.
    pub consistent: bool,
    /// The store's log position the index had applied when the comparison began.
    pub log_position: i64,
    pub families: Vec<FamilyAudit>,
    pub tags: TagAudit,
    /// Rows compared, over every family.
    pub rows: usize,
    pub seconds: f64,
}

/// Whether the index's row `r` of `fam` is the stored `values`: the same single-precision values, the same
/// rounding bound, and (with cells) listed in the cell its row says.
fn row_matches(fam: &Family, r: usize, values: &[f64]) -> bool {
    if values.len() != fam.k {
        return false;
    }
    let stored: Vec<f32> = values.iter().map(|&x| x as f32).collect();
    let same = fam.row_of(r).iter().zip(&stored).all(|(a, b)| a.to_bits() == b.to_bits());
    let bound = rounding_bound(values, &stored);
    let filed = fam.ivf.as_ref().is_none_or(|ivf| match (ivf.row_cell.get(r), ivf.row_pos.get(r)) {
        (Some(&c), Some(&p)) => {
            ivf.lists.get(c as usize).and_then(|l| l.get(p as usize)).is_some_and(|&x| x as usize == r)
        }
        _ => false,
    });
    same && fam.err[r].to_bits() == bound.to_bits() && filed
}

impl Index {
    /// Compares every fingerprint and tag of the store with this index (see [`AuditReport`]). Differences are
    /// checked again after the log's later changes are applied, so that a change made during the comparison (on
    /// this replica or another) is not reported; what still differs then is reported.
    pub fn audit(&self, store: &dyn FingerprintStore) -> std::io::Result<AuditReport> {
        let Ok(_one) = self.auditing.try_lock() else {
            return Err(std::io::Error::new(
                std::io::ErrorKind::WouldBlock,
                "an audit of the search index is running; ask again when it has answered",
            ));
        };
        let t = std::time::Instant::now();
        self.sync(store)?;
        let log_position = self.synced.lock().unwrap_or_else(|e| e.into_inner()).0;
        let mut store_rows: HashMap<String, usize> = HashMap::new();
        let mut seen: HashMap<String, Vec<bool>> = HashMap::new();
        let mut suspects: HashMap<String, Vec<ShapeId>> = HashMap::new();
        let mut overflow: HashMap<String, usize> = HashMap::new();
        let mut rows = 0;
        store.for_each_fingerprint(&mut |family, id, values| {
            rows += 1;
            *store_rows.entry(family.to_string()).or_default() += 1;
            let Some(id) = ShapeId::parse(id) else { return };
            let fams = self.families.read().unwrap_or_else(|e| e.into_inner());
            let ok = fams.get(family).and_then(|f| Some((f, *f.row.get(&id)? as usize))).is_some_and(|(f, r)| {
                let seen = seen.entry(family.to_string()).or_insert_with(|| vec![false; f.len()]);
                if let Some(s) = seen.get_mut(r) {
                    *s = true;
                }
                row_matches(f, r, values)
            });
            if !ok {
                let list = suspects.entry(family.to_string()).or_default();
                if list.len() < EXAMPLES {
                    list.push(id);
                } else {
                    *overflow.entry(family.to_string()).or_default() += 1;
                }
            }
        })?;
        // Rows of the index the store did not show.
        {
            let fams = self.families.read().unwrap_or_else(|e| e.into_inner());
            for (name, fam) in fams.iter() {
                let seen = seen.get(name);
                for (r, id) in fam.ids.iter().enumerate() {
                    if !seen.and_then(|s| s.get(r)).copied().unwrap_or(false) {
                        let list = suspects.entry(name.clone()).or_default();
                        if list.len() < EXAMPLES {
                            list.push(*id);
                        } else {
                            *overflow.entry(name.clone()).or_default() += 1;
                        }
                    }
                }
            }
        }
        let mut store_tags: HashMap<ShapeId, Vec<Tag>> = HashMap::new();
        let mut tag_pairs = 0;
        store.for_each_tag(&mut |id, tag| {
            tag_pairs += 1;
            if let (Some(id), Ok(tag)) = (ShapeId::parse(id), Tag::parse(tag)) {
                store_tags.entry(id).or_default().push(tag);
            }
        })?;
        let tag_suspects: Vec<ShapeId> = {
            let tags = self.tags.read().unwrap_or_else(|e| e.into_inner());
            let mut out: Vec<ShapeId> = vec![];
            for (id, t) in &store_tags {
                let mut a = t.clone();
                a.sort();
                let mut b = tags.by_shape.get(id).cloned().unwrap_or_default();
                b.sort();
                if a != b {
                    out.push(*id);
                }
            }
            out.extend(tags.by_shape.keys().filter(|id| !store_tags.contains_key(*id)));
            out
        };
        // Checked again, one by one, after the changes logged meanwhile.
        self.sync(store)?;
        let mut families = vec![];
        let index_rows: HashMap<String, usize> = {
            let fams = self.families.read().unwrap_or_else(|e| e.into_inner());
            fams.iter().map(|(n, f)| (n.clone(), f.len())).collect()
        };
        let mut names: Vec<&String> = store_rows.keys().chain(index_rows.keys()).collect();
        names.sort();
        names.dedup();
        for name in names {
            let mut audit = FamilyAudit {
                family: name.clone(),
                store_rows: store_rows.get(name).copied().unwrap_or(0),
                index_rows: index_rows.get(name).copied().unwrap_or(0),
                missing: 0,
                extra: 0,
                differing: overflow.get(name).copied().unwrap_or(0),
                examples: vec![],
            };
            if audit.store_rows == 0 && audit.index_rows == 0 {
                continue;
            }
            let list = suspects.remove(name).unwrap_or_default();
            let hex: Vec<String> = list.iter().map(ShapeId::hex).collect();
            for chunk in hex.chunks(512) {
                let stored = store.fingerprints_of(name, chunk)?;
                let fams = self.families.read().unwrap_or_else(|e| e.into_inner());
                let fam = fams.get(name);
                for id in chunk {
                    let row = fam.and_then(|f| Some((f, *f.row.get(&ShapeId::parse(id)?)? as usize)));
                    let verdict = match (stored.get(id), row) {
                        (Some(v), Some((f, r))) => (!row_matches(f, r, v)).then_some(&mut audit.differing),
                        (Some(_), None) => Some(&mut audit.missing),
                        (None, Some(_)) => Some(&mut audit.extra),
                        (None, None) => None,
                    };
                    if let Some(count) = verdict {
                        *count += 1;
                        if audit.examples.len() < NAMED {
                            audit.examples.push(id.clone());
                        }
                    }
                }
            }
            families.push(audit);
        }
        let mut tag_audit = TagAudit {
            store: tag_pairs,
            index: self.tags.read().unwrap_or_else(|e| e.into_inner()).by_shape.values().map(Vec::len).sum(),
            differing: 0,
            examples: vec![],
        };
        for id in tag_suspects {
            let mut a = store.tags_of(&id.hex())?;
            a.sort();
            let mut b: Vec<String> = self.tags_of(&id.hex());
            b.sort();
            if a != b {
                tag_audit.differing += 1;
                if tag_audit.examples.len() < NAMED {
                    tag_audit.examples.push(id.hex());
                }
            }
        }
        let consistent = tag_audit.differing == 0 && families.iter().all(|f| f.missing + f.extra + f.differing == 0);
        Ok(AuditReport {
            consistent,
            log_position,
            families,
            tags: tag_audit,
            rows,
            seconds: t.elapsed().as_secs_f64(),
        })
    }
}
