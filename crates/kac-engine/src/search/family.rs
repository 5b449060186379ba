//! One family's fingerprints: contiguous rows, their cells, and the copies for small tags.

use super::*;

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
    /// Bumped by every change of a row (a put or a removal): the key of `spread`.
    pub(crate) generation: u64,
    /// The family's spread ([`Family::spread`]) at a generation.
    pub(crate) spread: std::sync::Mutex<Option<(u64, f64)>>,
}

/// Families up to this many rows train their cells again at once, under the lock (a fraction of a second); larger
/// ones on a thread of their own while searches go on.
pub const INLINE_TRAINING: usize = 1 << 17;

impl Family {
    /// The root-mean-square Euclidean distance between two fingerprints of the family drawn at random (with
    /// replacement): √(2 Σⱼ Var(xⱼ)) over its rows, computed from the single-precision rows in one pass and kept
    /// until a row changes. The fused distance divides each family's distance by it, so that families of
    /// different units and lengths weigh as the weights say. None for an empty family.
    pub(crate) fn spread(&self) -> Option<f64> {
        let n = self.len();
        if n == 0 {
            return None;
        }
        let mut cached = self.spread.lock().unwrap_or_else(|e| e.into_inner());
        if let Some((g, s)) = *cached {
            if g == self.generation {
                return Some(s);
            }
        }
        let k = self.k;
        let (mut sum, mut sq) = (vec![0.0f64; k], vec![0.0f64; k]);
        for r in 0..n {
            for (j, &x) in self.row_of(r).iter().enumerate() {
                sum[j] += x as f64;
                sq[j] += x as f64 * x as f64;
            }
        }
        let var: f64 = (0..k).map(|j| (sq[j] / n as f64 - (sum[j] / n as f64).powi(2)).max(0.0)).sum();
        let s = (2.0 * var).sqrt();
        *cached = Some((self.generation, s));
        Some(s)
    }
    pub(crate) fn len(&self) -> usize {
        self.ids.len()
    }
    pub(crate) fn row_of(&self, r: usize) -> &[f32] {
        &self.vals[r * self.k..(r + 1) * self.k]
    }
    /// Keeps a fingerprint (replacing the shape's earlier one); `train`: files it in a cell, training the cells
    /// when the family has grown enough (false while a whole table is loaded: [`Family::train`] comes after).
    pub(crate) fn put(&mut self, id: ShapeId, v: &[f64], train: bool) {
        let stored: Vec<f32> = v.iter().map(|&x| x as f32).collect();
        let err = rounding_bound(v, &stored);
        self.put_stored(id, &stored, err, train);
    }
    /// [`Family::put`] of values already rounded, with their rounding bound.
    pub(crate) fn put_stored(&mut self, id: ShapeId, stored: &[f32], err: f32, train: bool) {
        if self.ids.is_empty() {
            self.k = stored.len();
            self.vals.reserve_exact(self.expect * self.k);
        }
        if stored.len() != self.k || stored.is_empty() {
            return;
        }
        self.err_max = self.err_max.max(err);
        self.generation += 1;
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
    pub(crate) fn tag_add(&mut self, tag: &Tag, id: &ShapeId) {
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
    pub(crate) fn tag_remove(&mut self, tag: &Tag, id: &ShapeId) {
        if let Some(sub) = self.subs.get_mut(tag) {
            let before = sub.len();
            sub.remove(id, &[]);
            self.sub_rows -= before - sub.len();
        }
    }
    /// Records that row `r`'s contents changed, while the cells are trained again.
    pub(crate) fn note(&mut self, r: usize) {
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
    pub(crate) fn pack(&mut self) {
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
    pub(crate) fn remove(&mut self, id: &ShapeId, tags: &[Tag]) {
        for t in tags {
            self.tag_remove(t, id);
        }
        let Some(r) = self.row.remove(id) else { return };
        self.generation += 1;
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
