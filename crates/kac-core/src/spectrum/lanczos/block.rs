//! The block operations of one Lanczos iteration: the row-major work block, the context holding the pencil and the
//! deflation (M products, orthogonalization), and Ritz vectors formed in place.

use crate::operators::sparse::SparsePair;
use crate::spectrum::basis_products;
use crate::spectrum::null_space::Deflation;
use crate::spectrum::{Control, EigenError};
use faer::linalg::matmul::matmul;
use faer::reborrow::{Reborrow, ReborrowMut};
use faer::{Accum, Mat, MatMut, MatRef, Par};
use std::time::Instant;

/// An n × b block stored row-major (row i contiguous), the layout the sparse block products and the block solve
/// work in: kept that way, neither transposes its operand; faer's dense products take it as it is (measured as fast
/// as column-major for the Gram product, faster for the update).
pub(super) struct RowBlock {
    pub(super) data: Vec<f64>,
    pub(super) n: usize,
    pub(super) b: usize,
}

impl RowBlock {
    pub(super) fn zeros(n: usize, b: usize) -> Self {
        RowBlock { data: vec![0.0; n * b], n, b }
    }
    pub(super) fn as_ref(&self) -> MatRef<'_, f64> {
        MatRef::from_row_major_slice(&self.data, self.n, self.b)
    }
    pub(super) fn as_mut(&mut self) -> MatMut<'_, f64> {
        MatMut::from_row_major_slice_mut(&mut self.data, self.n, self.b)
    }
}

/// Rows per chunk of the in-place thick restart.
pub(super) const RESTART_ROWS: usize = 2048;

/// Deterministic pseudo-random numbers (SplitMix64), uniform in [−1, 1].
pub(super) struct Rng(pub(super) u64);

impl Rng {
    pub(super) fn next(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^= z >> 31;
        (z >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
    }
}

/// Seconds spent inside the iteration, by kind of work (reported in [`Timings`]).
#[derive(Default)]
pub(super) struct Clock {
    pub(super) solve: f64,
    pub(super) orthogonalize: f64,
    pub(super) rayleigh_ritz: f64,
    pub(super) restart: f64,
}

pub(super) fn lap(t: &mut Instant) -> f64 {
    let now = Instant::now();
    let d = now.duration_since(*t).as_secs_f64();
    *t = now;
    d
}

/// V[:, a0..a0 + p] = V[:, a0..a0 + ma] S for S (ma × p, p ≤ ma): Ritz vectors formed in place, by chunks of rows
/// (each chunk's product is taken before the chunk is overwritten), so no n × p copy is allocated. On several
/// threads each takes a contiguous range of whole chunks with a scratch of its own and runs its products on one
/// thread: the rows are disjoint, and faer's product splits a chunk's 2048 × ma × p product less evenly than whole chunks split between threads.
pub(crate) fn ritz_in_place(
    v: &mut Mat<f64>,
    a0: usize,
    ma: usize,
    s: MatRef<'_, f64>,
    par: Par,
    control: &Control<'_>,
) -> Result<(), EigenError> {
    let n = v.nrows();
    let chunks = n.div_ceil(RESTART_ROWS);
    let threads = par.degree().min(chunks).max(1);
    // Row ranges of whole chunks, one per thread.
    let mut parts: Vec<MatMut<'_, f64>> = Vec::with_capacity(threads);
    let mut rest = v.as_mut().subcols_mut(a0, ma);
    for t in 0..threads {
        let take = (chunks * (t + 1) / threads - chunks * t / threads) * RESTART_ROWS;
        let at = take.min(rest.nrows());
        let (head, tail) = rest.split_at_row_mut(at);
        parts.push(head);
        rest = tail;
    }
    let run = |mut part: MatMut<'_, f64>| -> Result<(), EigenError> {
        let (rows_all, p) = (part.nrows(), s.ncols());
        let mut x = Mat::<f64>::zeros(RESTART_ROWS.min(rows_all), p);
        for r0 in (0..rows_all).step_by(RESTART_ROWS) {
            // A chunk is RESTART_ROWS × ma × p multiply-adds: a stop is seen between chunks.
            control.check()?;
            let rows = RESTART_ROWS.min(rows_all - r0);
            let mut xc = x.as_mut().subrows_mut(0, rows);
            matmul(xc.rb_mut(), Accum::Replace, part.rb().subrows(r0, rows), s, 1.0, Par::Seq);
            part.rb_mut().subrows_mut(r0, rows).subcols_mut(0, p).copy_from(xc.rb());
        }
        Ok(())
    };
    if threads == 1 {
        return parts.into_iter().try_for_each(run);
    }
    use rayon::prelude::*;
    parts.into_par_iter().with_max_len(1).map(run).collect()
}

/// A Ritz pair of the current basis: a locked column, or an eigenvector of the active projected matrix.
#[derive(Clone, Copy)]
pub(super) enum Ritz {
    Locked(usize),
    Active(usize),
}

pub(super) struct Ctx<'a> {
    pub(super) pair: &'a SparsePair,
    /// Directions the basis stays M-orthogonal to (exact zero modes, pairs found before a repair).
    pub(super) deflation: &'a Deflation<'a>,
    pub(super) mdiag: Option<Vec<f64>>,
    pub(super) mean_mass: f64,
    /// Scratch of the sparse block product (grows once).
    pub(super) scratch: Vec<f64>,
    /// Threads for the basis products (1: this thread only).
    pub(super) threads: usize,
}

impl Ctx<'_> {
    /// out = M x
    pub(super) fn apply_m(&mut self, x: MatRef<'_, f64>, mut out: MatMut<'_, f64>) {
        match &self.mdiag {
            Some(d) => {
                for c in 0..x.ncols() {
                    for i in 0..x.nrows() {
                        out[(i, c)] = d[i] * x[(i, c)];
                    }
                }
            }
            None => crate::operators::sparse::spmm(
                &self.pair.pattern,
                &self.pair.mass,
                x,
                out,
                &mut self.scratch,
                self.threads,
            ),
        }
    }

    /// Classical Gram–Schmidt of the row-major n × b block `w` against the M-orthonormal columns of `v`, with a
    /// second pass only where the first removed more than half of some column's M-norm² (DGKS). `mw` holds M w on
    /// entry and on exit; the coefficients Vᵀ M w are added to `coef` (rows of `v`).
    pub(super) fn project_out(&mut self, v: MatRef<'_, f64>, w: &mut [f64], mw: &mut [f64], mut coef: MatMut<'_, f64>) {
        let (n, m) = (v.nrows(), v.ncols());
        let b = w.len() / n.max(1);
        if m == 0 {
            return;
        }
        for pass in 0..3 {
            let before = basis_products::col_dots_par(w, mw, b, self.threads);
            let c = basis_products::gram_par(v, mw, b, self.threads);
            basis_products::update_par(w, b, v, c.as_ref(), -1.0, self.threads);
            for col in 0..b {
                for r in 0..m {
                    coef[(r, col)] += c[(r, col)];
                }
            }
            self.apply_m(MatRef::from_row_major_slice(w, n, b), MatMut::from_row_major_slice_mut(mw, n, b));
            // ‖w − Vc‖²_M = ‖w‖²_M − ‖c‖² for M-orthonormal V.
            let lost = (0..b).any(|col| {
                let c2: f64 = (0..m).map(|r| c[(r, col)] * c[(r, col)]).sum();
                c2 > 0.5 * before[col]
            });
            if !lost || pass == 2 {
                break;
            }
        }
    }

    /// M-orthonormalizes the block `w` (already M-orthogonal to `v[:, ..lead]`), W = Q B, writing Q into
    /// `v[:, lead..lead + b]` and M Q into `mq`; `mw` holds M w. Directions that vanished (rank deficiency: an
    /// invariant subspace was found) are replaced by random vectors orthogonal to everything before them; their
    /// rows of B are zero. `scale` holds each column's norm² before orthogonalization (the rank test's reference).
    #[allow(clippy::too_many_arguments)]
    pub(super) fn normalize(
        &mut self,
        mut v: MatMut<'_, f64>,
        lead: usize,
        w: &RowBlock,
        mw: &RowBlock,
        mut mq: MatMut<'_, f64>,
        rng: &mut Rng,
        scale: &[f64],
    ) -> Mat<f64> {
        let (n, b) = (w.n, w.b);
        let g = basis_products::gram_par(w.as_ref(), &mw.data, b, self.threads);
        let g = Mat::from_fn(b, b, |i, j| 0.5 * (g[(i, j)] + g[(j, i)]));
        let (s, u) = crate::spectrum::small_dense::symmetric_eigen(g.as_ref(), Par::Seq)
            .expect("symmetric eigen of a small Gram matrix");
        let ref_scale = scale.iter().cloned().fold(0.0, f64::max).max(f64::MIN_POSITIVE);
        // Largest directions first: Q = W U_kept R⁻¹, B = R U_keptᵀ.
        let kept_idx: Vec<usize> = (0..b).rev().filter(|&idx| s[idx] > 1e-24 * ref_scale).collect();
        let kept = kept_idx.len();
        let mut transform = Mat::<f64>::zeros(b, kept);
        let mut bmat = Mat::<f64>::zeros(b, b);
        for (j, &idx) in kept_idx.iter().enumerate() {
            let r = s[idx].sqrt();
            for c in 0..b {
                transform[(c, j)] = u[(c, idx)] / r;
                bmat[(j, c)] = r * u[(c, idx)];
            }
        }
        basis_products::block_times_par(
            &w.data,
            b,
            transform.as_ref(),
            v.rb_mut().subcols_mut(lead, kept),
            self.threads,
        );
        basis_products::block_times_par(
            &mw.data,
            b,
            transform.as_ref(),
            mq.rb_mut().subcols_mut(0, kept),
            self.threads,
        );
        // Refill vanished directions with random vectors.
        for j in kept..b {
            let mut x: Vec<f64> = (0..n).map(|_| rng.next()).collect();
            let mut mx = vec![0.0; n];
            for _attempt in 0..3 {
                self.apply_m(MatRef::from_row_major_slice(&x, n, 1), MatMut::from_row_major_slice_mut(&mut mx, n, 1));
                self.deflation.project(&mut x, &mut mx, 1, self.threads);
                let mut sink = Mat::<f64>::zeros(lead + j, 1);
                self.project_out(v.rb().subcols(0, lead + j), &mut x, &mut mx, sink.as_mut());
                let nrm = basis_products::col_dots_par(&x, &mx, 1, self.threads)[0].sqrt();
                if nrm > 1e-8 {
                    for i in 0..n {
                        v[(i, lead + j)] = x[i] / nrm;
                        mq[(i, j)] = mx[i] / nrm;
                    }
                    break;
                }
                x = (0..n).map(|_| rng.next()).collect();
            }
        }
        bmat
    }
}
