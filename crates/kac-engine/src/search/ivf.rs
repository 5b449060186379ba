//! An inverted-file index (IVF) over one family's fingerprints: k-means centroids cut the fingerprints into
//! Voronoi cells ("lists"), and a query computes distances only to the rows of the cells nearest to it (Jégou,
//! Douze & Schmid 2011, §3.1, without their product quantization: the rows are scanned as they are stored).
//!
//! Every cell also gives a lower bound on the distance from the query to any of its rows: a row x of cell j is at
//! least as near to c_j as to the query's nearest centroid c₁, so it lies beyond the bisecting hyperplane of c₁
//! and c_j, whose distance from the query q is (‖q − c_j‖² − ‖q − c₁‖²) / (2‖c_j − c₁‖). A search that has
//! probed every cell whose bound is below its current k-th distance has provably found the exact neighbours
//! (for Euclidean distances, and for Manhattan ones, which are never shorter). Cells are probed in the order of
//! their bounds, so such a proof comes as early as it can.

use faer::linalg::matmul::matmul;
use faer::{Accum, Mat, Par};

/// Families below this many fingerprints are scanned whole: a scan of them is as fast as probing.
pub const MIN_ROWS: usize = 16_384;

/// The number of cells for `n` fingerprints: about √n (as many cells as rows in a cell), 64 to 2048.
pub fn cells_for(n: usize) -> usize {
    ((n as f64).sqrt().round() as usize).clamp(64, 2048)
}

/// The cells of one family.
pub struct Ivf {
    pub k: usize,
    /// `cells × k`, row-major.
    pub centroids: Vec<f64>,
    pub lists: Vec<Vec<u32>>,
    /// Each row's cell and its position in that cell's list.
    pub row_cell: Vec<u32>,
    pub row_pos: Vec<u32>,
    /// A bound on the rounding of an assignment, in squared distance: a row is no farther than this from being
    /// nearest to the centroid of its cell.
    pub slack: f64,
    /// How many rows the family held when the centroids were trained (they are trained again at four times as
    /// many).
    pub trained_rows: usize,
    /// How many rows the family held when its rows were last renumbered cell by cell.
    pub packed_rows: usize,
    /// The largest row norm the slack covers.
    pub xmax: f64,
}

/// A deterministic generator for sampling (xorshift64*).
struct Rng(u64);
impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }
    fn below(&mut self, n: usize) -> usize {
        (self.next() % n as u64) as usize
    }
}

fn row(vals: &[f32], k: usize, r: usize) -> &[f32] {
    &vals[r * k..(r + 1) * k]
}

/// The nearest centroid to each of `rows` (indices into `vals`), by ‖x‖² + ‖c‖² − 2 x·c with the products in one
/// matrix product a block; and the largest ‖x‖ seen.
pub(crate) fn assign(vals: &[f32], k: usize, rows: &[usize], centroids: &[f64], par: Par) -> (Vec<u32>, f64) {
    let cells = centroids.len() / k;
    let c = Mat::<f64>::from_fn(cells, k, |i, j| centroids[i * k + j]);
    let cnorm: Vec<f64> = (0..cells).map(|i| centroids[i * k..(i + 1) * k].iter().map(|v| v * v).sum()).collect();
    let mut out = Vec::with_capacity(rows.len());
    let mut xmax = 0.0f64;
    const BLOCK: usize = 2048;
    let mut g = Mat::<f64>::zeros(BLOCK.min(rows.len()), cells);
    for chunk in rows.chunks(BLOCK) {
        let x = Mat::<f64>::from_fn(chunk.len(), k, |i, j| vals[chunk[i] * k + j] as f64);
        let mut gb = g.as_mut().subrows_mut(0, chunk.len());
        matmul(gb.as_mut(), Accum::Replace, x.as_ref(), c.as_ref().transpose(), 1.0, par);
        for i in 0..chunk.len() {
            let xn: f64 = (0..k).map(|j| x[(i, j)] * x[(i, j)]).sum();
            xmax = xmax.max(xn.sqrt());
            let mut best = (f64::INFINITY, 0u32);
            for (j, cn) in cnorm.iter().enumerate() {
                let d = cn - 2.0 * gb[(i, j)];
                if d < best.0 {
                    best = (d, j as u32);
                }
            }
            out.push(best.1);
        }
    }
    (out, xmax)
}

/// The rows k-means trains on: every row, or 40 a cell drawn (seeded by `n`, so the same rows give the same cells).
pub(crate) fn sample_rows(n: usize, cells: usize) -> Vec<usize> {
    let mut rng = Rng(0x9E37_79B9_7F4A_7C15 ^ n as u64);
    if n <= 40 * cells {
        (0..n).collect()
    } else {
        (0..40 * cells).map(|_| rng.below(n)).collect()
    }
}

/// `cells` centroids by Lloyd's k-means (10 rounds) over the `sample` rows of `vals`, started from distinct sample
/// rows; an emptied cell starts again from a random sample row.
pub(crate) fn centroids(vals: &[f32], k: usize, sample: &[usize], cells: usize, par: Par) -> Vec<f64> {
    let mut rng = Rng(0x2545_F491_4F6C_DD1D ^ sample.len() as u64);
    let mut centroids = Vec::with_capacity(cells * k);
    for i in 0..cells {
        let r = sample[(i * sample.len()) / cells];
        centroids.extend(row(vals, k, r).iter().map(|&v| v as f64));
    }
    for _ in 0..10 {
        let (cell, _) = assign(vals, k, sample, &centroids, par);
        let mut sum = vec![0.0f64; cells * k];
        let mut count = vec![0usize; cells];
        for (&r, &c) in sample.iter().zip(&cell) {
            count[c as usize] += 1;
            for (s, &v) in sum[c as usize * k..(c as usize + 1) * k].iter_mut().zip(row(vals, k, r)) {
                *s += v as f64;
            }
        }
        for c in 0..cells {
            let target = &mut centroids[c * k..(c + 1) * k];
            if count[c] == 0 {
                let r = sample[rng.below(sample.len())];
                for (t, &v) in target.iter_mut().zip(row(vals, k, r)) {
                    *t = v as f64;
                }
            } else {
                for (t, s) in target.iter_mut().zip(&sum[c * k..(c + 1) * k]) {
                    *t = s / count[c] as f64;
                }
            }
        }
    }
    centroids
}

impl Ivf {
    /// Trains `cells` centroids by Lloyd's k-means on a sample of the rows (40 a cell, seeded, so the same rows
    /// give the same cells) and assigns every row.
    pub fn train(vals: &[f32], k: usize, cells: usize, par: Par) -> Ivf {
        let n = vals.len() / k;
        let cells = cells.clamp(1, n.max(1));
        let sample = sample_rows(n, cells);
        let centroids = centroids(vals, k, &sample, cells, par);
        let all: Vec<usize> = (0..n).collect();
        let (cell, xmax) = assign(vals, k, &all, &centroids, par);
        Ivf::from_assignment(k, centroids, cell, xmax, n)
    }

    /// The cells of `cell.len()` rows, each row's cell given; `xmax`: the largest row norm assigned.
    pub fn from_assignment(k: usize, centroids: Vec<f64>, cell: Vec<u32>, xmax: f64, trained_rows: usize) -> Ivf {
        let cells = centroids.len() / k;
        let n = cell.len();
        let mut ivf = Ivf {
            k,
            centroids,
            lists: vec![vec![]; cells],
            row_cell: cell,
            row_pos: vec![0; n],
            slack: 0.0,
            trained_rows,
            packed_rows: 0,
            xmax: -1.0,
        };
        ivf.widen_slack(xmax);
        for r in 0..n {
            let c = ivf.row_cell[r] as usize;
            ivf.row_pos[r] = ivf.lists[c].len() as u32;
            ivf.lists[c].push(r as u32);
        }
        ivf
    }

    pub fn cells(&self) -> usize {
        self.lists.len()
    }

    /// Grows the assignment slack to cover a row of norm `xmax`: the rounding of ‖c‖² − 2x·c in double precision
    /// over k terms, at most 2(k + 2)ε(‖c‖² + 2‖x‖‖c‖) between two centroids.
    fn widen_slack(&mut self, xmax: f64) {
        if xmax <= self.xmax {
            return;
        }
        self.xmax = xmax;
        let k = self.k;
        let cmax =
            self.centroids.chunks_exact(k).map(|c| c.iter().map(|v| v * v).sum::<f64>().sqrt()).fold(0.0, f64::max);
        // Also covers the direct distances of one row (k differences squared and summed: at most (k + 2)ε of the
        // same terms).
        let s = 4.0 * (k as f64 + 2.0) * f64::EPSILON * (cmax * cmax + 2.0 * xmax * cmax + xmax * xmax);
        self.slack = self.slack.max(s);
    }

    /// The cell of one row: its nearest centroid, by ‖x − c‖² directly (a product of one row is dominated by its
    /// set-up); and the row's norm, for the slack.
    fn nearest_cell(&self, x: &[f32]) -> (usize, f64) {
        let k = self.k;
        let mut best = (f64::INFINITY, 0usize);
        for (j, c) in self.centroids.chunks_exact(k).enumerate() {
            let d: f64 = c.iter().zip(x).map(|(a, &b)| (a - b as f64) * (a - b as f64)).sum();
            if d < best.0 {
                best = (d, j);
            }
        }
        (best.1, x.iter().map(|&v| v as f64 * v as f64).sum::<f64>().sqrt())
    }

    /// Files a new row (the last of `vals`) in its nearest cell.
    pub fn push(&mut self, vals: &[f32]) {
        let r = vals.len() / self.k - 1;
        let (c, xmax) = self.nearest_cell(&vals[r * self.k..]);
        self.widen_slack(xmax);
        self.row_cell.push(c as u32);
        self.row_pos.push(self.lists[c].len() as u32);
        self.lists[c].push(r as u32);
    }

    /// Files row `r` again after its values changed.
    pub fn refile(&mut self, vals: &[f32], r: usize) {
        self.unlist(r);
        let (c, xmax) = self.nearest_cell(&vals[r * self.k..(r + 1) * self.k]);
        self.widen_slack(xmax);
        self.row_cell[r] = c as u32;
        self.row_pos[r] = self.lists[c].len() as u32;
        self.lists[c].push(r as u32);
    }

    fn unlist(&mut self, r: usize) {
        let (c, p) = (self.row_cell[r] as usize, self.row_pos[r] as usize);
        let list = &mut self.lists[c];
        list.swap_remove(p);
        if let Some(&moved) = list.get(p) {
            self.row_pos[moved as usize] = p as u32;
        }
    }

    /// Forgets row `r`, whose place the last row takes (as the family's arrays do).
    pub fn swap_remove(&mut self, r: usize) {
        self.unlist(r);
        let last = self.row_cell.len() - 1;
        if r != last {
            let (c, p) = (self.row_cell[last] as usize, self.row_pos[last] as usize);
            self.lists[c][p] = r as u32;
            self.row_cell[r] = self.row_cell[last];
            self.row_pos[r] = self.row_pos[last];
        }
        self.row_cell.pop();
        self.row_pos.pop();
    }

    /// The cells in the order to probe them for `query`, each with its lower bound on the Euclidean distance from
    /// the query to any of its rows.
    pub fn plan(&self, query: &[f64]) -> Vec<(f64, u32)> {
        let k = self.k;
        let d2: Vec<f64> =
            self.centroids.chunks_exact(k).map(|c| c.iter().zip(query).map(|(a, b)| (a - b) * (a - b)).sum()).collect();
        let Some(nearest) = (0..d2.len()).min_by(|&a, &b| d2[a].total_cmp(&d2[b])) else { return vec![] };
        let c1 = &self.centroids[nearest * k..(nearest + 1) * k];
        let mut plan: Vec<(f64, u32)> = self
            .centroids
            .chunks_exact(k)
            .enumerate()
            .map(|(j, cj)| {
                if j == nearest {
                    return (0.0, j as u32);
                }
                let sep: f64 = cj.iter().zip(c1).map(|(a, b)| (a - b) * (a - b)).sum::<f64>().sqrt();
                let bound = if sep > 0.0 { (d2[j] - d2[nearest] - self.slack) / (2.0 * sep) } else { 0.0 };
                (bound.max(0.0), j as u32)
            })
            .collect();
        plan.sort_by(|a, b| a.0.total_cmp(&b.0).then(d2[a.1 as usize].total_cmp(&d2[b.1 as usize])));
        plan
    }
}
