//! Training a large family's cells again off its lock while searches go on.

use super::*;

pub(crate) type Families = RwLock<HashMap<String, Family>>;

/// A training of a family's cells under way, off its lock: new centroids from a sample, then every row assigned to
/// them a chunk at a time under the read lock, then the rows changed meanwhile assigned again and the cells swapped
/// in under the write lock.
pub(crate) struct Retraining {
    pub(crate) name: String,
    pub(crate) k: usize,
    pub(crate) centroids: Vec<f64>,
    pub(crate) cell: Vec<u32>,
    pub(crate) xmax: f64,
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
pub(crate) fn retrain(fams: &Families, name: &str, par: faer::Par) {
    if let Some(mut t) = begin_retraining(fams, name, par) {
        while retraining_step(fams, &mut t, 8192, par) {}
        finish_retraining(fams, t, par);
    }
}
