//! Thick-restart block Lanczos in the M-inner product for T = (L − σM)⁻¹M (see the module docs of
//! [`super`]). Notation: V holds M-orthonormal basis columns; the first `m` are "expanded" (T applied), the next
//! `b` form the block Q waiting for expansion. H = Vᵀ M T V on the expanded part; E = Qᵀ M T V couples Q to it.
//! A Ritz pair (θ, V s) has residual ‖T x − θ x‖_M = ‖E s‖₂.

use super::basis_products;
use super::factor::{Cholesky, Symbolic};
use super::null_space::Deflation;
use super::numeric::FactorError;
use super::{Control, EigenError, EigenOptions, Spectrum, Stats, Timings};
use crate::operators::sparse::SparsePair;
use faer::linalg::matmul::matmul;
use faer::reborrow::{Reborrow, ReborrowMut};
use faer::{Accum, Mat, MatMut, MatRef, Par};
use std::time::Instant;

/// The default shift: σ = −mean_j(L_jj / M_jj) / n. The mean diagonal ratio scales like the top of the
/// spectrum (≈ c/h² ≈ c·n/area on a surface), so σ lands near the bottom of the spectrum (about λ₁/4 on a
/// unit sphere), far from the null space: a shift much closer to 0 makes the null modes dominate T and costs
/// the small Ritz values digits (measured: 10⁻⁸ relative with σ = −10⁻⁶·mean, 10⁻¹³ with this σ).
pub fn default_sigma(pair: &SparsePair) -> f64 {
    let n = pair.n();
    let mut s = 0.0;
    for j in 0..n {
        let d = pair.pattern.diag_pos(j);
        if pair.mass[d] > 0.0 {
            s += pair.stiffness[d].abs() / pair.mass[d];
        }
    }
    let scale = s / n.max(1) as f64;
    -(if scale > 0.0 && scale.is_finite() { scale } else { 1.0 }) / n.max(1) as f64
}

/// An n × b block stored row-major (row i contiguous), the layout the sparse block products and the block solve
/// work in: kept that way, neither transposes its operand; faer's dense products take it as it is (measured as fast
/// as column-major for the Gram product, faster for the update).
struct RowBlock {
    data: Vec<f64>,
    n: usize,
    b: usize,
}

impl RowBlock {
    fn zeros(n: usize, b: usize) -> Self {
        RowBlock { data: vec![0.0; n * b], n, b }
    }
    fn as_ref(&self) -> MatRef<'_, f64> {
        MatRef::from_row_major_slice(&self.data, self.n, self.b)
    }
    fn as_mut(&mut self) -> MatMut<'_, f64> {
        MatMut::from_row_major_slice_mut(&mut self.data, self.n, self.b)
    }
}

/// Rows per chunk of the in-place thick restart.
const RESTART_ROWS: usize = 2048;

/// Deterministic pseudo-random numbers (SplitMix64), uniform in [−1, 1].
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> f64 {
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
struct Clock {
    solve: f64,
    orthogonalize: f64,
    rayleigh_ritz: f64,
    restart: f64,
}

fn lap(t: &mut Instant) -> f64 {
    let now = Instant::now();
    let d = now.duration_since(*t).as_secs_f64();
    *t = now;
    d
}

/// V[:, a0..a0 + p] = V[:, a0..a0 + ma] S for S (ma × p, p ≤ ma): Ritz vectors formed in place, by chunks of rows
/// (each chunk's product is taken before the chunk is overwritten), so no n × p copy is allocated. On several
/// threads each takes a contiguous range of whole chunks with a scratch of its own and runs its products on one
/// thread: the rows are disjoint, and faer's product splits a chunk's 2048 × ma × p product less evenly (restarts
/// and Ritz vectors at 164k vertices, k = 200, two threads: 1.3× the one-thread speed split inside each product).
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
            // A chunk is RESTART_ROWS × ma × p multiply-adds (≈ 0.1 s at ma = 1000, p = 500).
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
enum Ritz {
    Locked(usize),
    Active(usize),
}

struct Ctx<'a> {
    pair: &'a SparsePair,
    /// Directions the basis stays M-orthogonal to (exact zero modes, pairs found before a repair).
    deflation: &'a Deflation<'a>,
    mdiag: Option<Vec<f64>>,
    mean_mass: f64,
    /// Scratch of the sparse block product (grows once).
    scratch: Vec<f64>,
    /// Threads for the basis products (1: this thread only).
    threads: usize,
}

impl Ctx<'_> {
    /// out = M x
    fn apply_m(&mut self, x: MatRef<'_, f64>, mut out: MatMut<'_, f64>) {
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
    fn project_out(&mut self, v: MatRef<'_, f64>, w: &mut [f64], mw: &mut [f64], mut coef: MatMut<'_, f64>) {
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
    fn normalize(
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
        let (s, u) =
            super::dense::symmetric_eigen(g.as_ref(), Par::Seq).expect("symmetric eigen of a small Gram matrix");
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

/// Where the shift goes, as a fraction of Weyl's estimate of λ_k: the wanted eigenvalues below σ become the most
/// negative θ = 1/(λ − σ) and those above it the largest positive ones, so the unwanted rest (above λ_k) is squeezed
/// into (0, 1/(λ_{k+1} − σ)], far from both ends. Measured on the unit icosphere (10k vertices, k = 50, λ_50 = 56):
/// 38 block steps at σ < 0, 28 at σ = 30, 24 at σ = 40, 26 at σ = 45, 30 at σ = 50; balancing the two ends'
/// relative gaps puts the optimum near 0.7 λ_k. Weyl's leading term is 50 there (σ = 35, 26 steps); it
/// overestimates λ_k where a free boundary adds eigenvalues (N(λ) gains |∂Ω|√λ/4π under Neumann conditions: the
/// unit square's λ_50 is 484 against 628), which is why the fraction is not taken higher.
pub const WEYL_FRACTION: f64 = 0.7;

/// Below this k the shift stays below the spectrum (a handful of pairs converge in a few steps either way).
const INTERIOR_MIN_K: usize = 8;

/// The largest backward error ‖K x − b‖ / (‖K‖_∞ ‖x‖ + ‖b‖) accepted from a test solve with an LDLᵀ factor (no
/// pivoting): solves with LDLᵀ factors at the Weyl shift measure 10⁻¹⁶–10⁻¹⁴ on 2.5k–164k-vertex spheres; above
/// this the factor grew and the default shift below the spectrum (Cholesky) is used instead.
const LDLT_BACKWARD_ERROR: f64 = 1e-12;

/// Where else in a slice's window [lo, hi] σ is tried, as fractions of the window, when the factor at its planned
/// shift is not backward stable.
const WINDOW_SHIFTS: [f64; 4] = [0.4, 0.6, 0.3, 0.7];

/// The shift inside the spectrum from Weyl's law, σ = 0.7·λ̂_k with λ̂_k = (2π)² (k / (ω_d |Ω|))^{2/d} and |Ω| = 1ᵀM1
/// (see [`WEYL_FRACTION`]); `None` for operators without a dimension (graphs) or small k.
pub fn weyl_shift(pair: &SparsePair, k: usize) -> Option<f64> {
    let d = pair.dimension?;
    let measure: f64 = pair.mass.iter().sum();
    if k < INTERIOR_MIN_K || !(measure > 0.0) || !measure.is_finite() {
        return None;
    }
    let s = WEYL_FRACTION * super::weyl_law::weyl_eigenvalue(d, measure, k as f64);
    (s > 0.0 && s.is_finite()).then_some(s)
}

/// What one block-Lanczos run is asked beyond [`EigenOptions`] (whose `k` counts the pairs this run finds).
pub struct Run<'a> {
    /// Directions the basis stays M-orthogonal to: exact zero modes, and pairs found before a repair.
    pub deflation: &'a Deflation<'a>,
    /// Their eigenvalues (each deflated direction's), to count them against the inertia of L − σM.
    pub deflated_values: &'a [f64],
    /// Whether σ may go inside the spectrum by Weyl's law (counting the deflated pairs as found): yes for a first
    /// solve; a repair looks for pairs lying among others it does not count, and keeps σ below the spectrum.
    pub interior_shift: bool,
    /// A slice of the spectrum ([`super::slicing`]): the run factors at the window's shift and returns the pairs in
    /// the window instead of the `k` smallest (`k` then sizes the subspace: the pairs the window is expected to hold).
    pub window: Option<Window>,
    /// Pairs the result starts with, ahead of the run's own (the known zero modes): written into the eigenvector
    /// matrix as it is allocated, so that no second n × k copy is made to put them in front (at 164k vertices,
    /// k = 1000, that copy held the process' peak, two 1.3 GB matrices, for 0.8 s).
    pub head: Option<&'a Spectrum>,
}

/// The part of the spectrum one slice returns: the pairs with λ in [lo, hi), found by shift-invert around `sigma`.
/// In JSON (a slice solved on another machine) an open end is null, since JSON has no infinities.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Window {
    /// −∞ for the lowest slice.
    #[serde(serialize_with = "open_end", deserialize_with = "from_below")]
    pub lo: f64,
    /// +∞ for the top slice, which returns pairs up to a count instead (`total`).
    #[serde(serialize_with = "open_end", deserialize_with = "from_above")]
    pub hi: f64,
    pub sigma: f64,
    /// Top slice: the pairs wanted counted from the bottom of the spectrum (deflated ones included, guards too):
    /// the slice returns its pairs from `lo` up to the `total`-th eigenvalue, Sylvester's inertia at σ telling how
    /// many lie below σ.
    pub total: Option<usize>,
    /// The eigenvalues in [lo, hi) when known (Sylvester's inertia at both ends): the slice is done once that many
    /// converged pairs lie in the window, without guards beyond it.
    pub count: Option<usize>,
    /// The eigenvalues below `lo` (deflated ones included; Sylvester's inertia at `lo`): the top slice checks that it
    /// holds every eigenvalue in [lo, σ) against its own inertia at σ.
    pub below_lo: usize,
}

/// A window's end as JSON: null where it is open (infinite).
fn open_end<S: serde::Serializer>(x: &f64, s: S) -> Result<S::Ok, S::Error> {
    serde::Serialize::serialize(&x.is_finite().then_some(*x), s)
}

/// A lower end back from JSON: null is −∞.
fn from_below<'de, D: serde::Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
    Ok(<Option<f64> as serde::Deserialize>::deserialize(d)?.unwrap_or(f64::NEG_INFINITY))
}

/// An upper end back from JSON: null is +∞.
fn from_above<'de, D: serde::Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
    Ok(<Option<f64> as serde::Deserialize>::deserialize(d)?.unwrap_or(f64::INFINITY))
}

/// Where a run's wanted pairs lie among the Ritz candidates sorted by ascending λ: the pairs returned are
/// `start..end`; those that must have converged (with a guard on each side of a window) are `req_start..req_end`.
struct Selection {
    start: usize,
    end: usize,
    req_start: usize,
    req_end: usize,
    /// Whether the candidates reach as far as the window asks.
    enough: bool,
}

fn select(
    cand: &[(f64, Ritz, f64)],
    sigma: f64,
    want: usize,
    window: Option<&Window>,
    below: Option<usize>,
) -> Selection {
    let len = cand.len();
    let Some(w) = window else {
        let end = want.min(len);
        return Selection { start: 0, end, req_start: 0, req_end: end, enough: want <= len };
    };
    let lam = |c: &(f64, Ritz, f64)| sigma + 1.0 / c.0;
    let start = if w.lo == f64::NEG_INFINITY { 0 } else { cand.partition_point(|c| lam(c) < w.lo) };
    let (end, req_end, enough) = match w.total {
        Some(total) => {
            // λ < σ exactly where θ < 0, which the ascending order puts first; the `total`-th eigenvalue may lie below
            // σ as well as above it.
            let at_sigma = cand.partition_point(|c| c.0 < 0.0);
            let end = (at_sigma as isize + total as isize - below.unwrap_or(0) as isize).max(start as isize) as usize;
            // Every eigenvalue in [lo, σ) must be among the candidates (a cluster member not met yet would let the
            // pair past the `total`-th take its place).
            let all_below = below.is_some_and(|b| at_sigma.checked_sub(start) == b.checked_sub(w.below_lo));
            (end.min(len), end.min(len), end <= len && all_below)
        }
        None => {
            let end = cand.partition_point(|c| lam(c) < w.hi).max(start);
            match w.count {
                Some(count) => (end, end, end - start == count),
                None => (end, (end + 1).min(len), end < len),
            }
        }
    };
    let req_start = if w.lo == f64::NEG_INFINITY || w.count.is_some() { start } else { start.saturating_sub(1) };
    Selection { start, end, req_start, req_end, enough }
}

impl Run<'_> {
    /// Deflated pairs with eigenvalues below σ (they are among those the inertia of L − σM counts).
    fn deflated_below(&self, sigma: f64) -> usize {
        self.deflated_values.iter().filter(|&&v| v < sigma).count()
    }
}

/// K = L − σM factored, with what the factorization says about the spectrum.
struct Shifted {
    sigma: f64,
    factor: Cholesky,
    /// Eigenvalues below σ (the LDLᵀ inertia); `None` for a Cholesky factor (σ below the spectrum).
    below_sigma: Option<usize>,
}

/// Chooses σ and factors L − σM. An explicit σ is used as given (Cholesky when negative, LDLᵀ otherwise). Else,
/// where the operator has a dimension, σ goes inside the spectrum by Weyl's law ([`weyl_shift`]) and L − σM is
/// factored as LDLᵀ: accepted when its inertia puts at most k eigenvalues below σ and a test solve is backward
/// stable; with more than k below, σ is lowered once as if N(λ) grew like √λ (thin shapes, whose low spectrum is
/// one-dimensional, are what Weyl's two- or three-dimensional law overestimates). Otherwise, and as the last
/// resort, σ = [`default_sigma`] below the spectrum with a Cholesky factor, multiplied by 100 while a pivot fails.
fn factor_shift(
    pair: &SparsePair,
    o: &EigenOptions,
    sym: &Symbolic,
    par: Par,
    run: &Run<'_>,
    control: &Control<'_>,
) -> Result<Shifted, EigenError> {
    // A stop ends the solve; any other failure of a factorization names its shift.
    let failed = |sigma: f64, e: FactorError| match e {
        FactorError::Stopped => EigenError::Canceled,
        FactorError::Failed(message) => EigenError::Factorization { message: format!("σ = {sigma:e}: {message}") },
    };
    let stop = control.stop;
    if let Some(w) = &run.window {
        // σ at the window's planned shift, else elsewhere inside the window: whether an LDLᵀ factor is backward
        // stable depends on σ and on the elimination order (one vertex numbering of a mesh is stable where another
        // is not), and any σ inside the window serves the slice.
        let a = if w.lo.is_finite() { w.lo } else { 0.0 };
        let b = if w.hi.is_finite() { w.hi } else { 2.0 * w.sigma - a };
        let mut tries: Vec<f64> = vec![];
        for sigma in std::iter::once(w.sigma).chain(WINDOW_SHIFTS.iter().map(|f| a + f * (b - a))) {
            // Each shift once (the first slice's planned shift is one of the fractions).
            if sigma.is_finite() && sigma > a && sigma < b && tries.iter().all(|t| (t - sigma).abs() > 1e-12 * b.abs())
            {
                tries.push(sigma);
            }
        }
        let mut last = None;
        for sigma in tries {
            control.check()?;
            let values = pair.shifted(sigma);
            // A failed factorization (a zero pivot) is tried elsewhere too; only a stop ends the search.
            let (factor, below) = match Cholesky::factor_ldlt_stoppable(sym, &values, par, stop) {
                Ok(f) => f,
                Err(FactorError::Stopped) => return Err(EigenError::Canceled),
                Err(FactorError::Failed(message)) => {
                    last = Some(format!("σ = {sigma:e}: {message}"));
                    continue;
                }
            };
            let e = solve_backward_error(pair, &values, &factor, par);
            if e <= LDLT_BACKWARD_ERROR {
                return Ok(Shifted { sigma, factor, below_sigma: Some(below) });
            }
            last = Some(format!("σ = {sigma:e}: the LDLᵀ factor is not backward stable ({e:.1e})"));
        }
        return Err(EigenError::Factorization {
            message: last.unwrap_or_else(|| format!("σ = {:e} lies outside its window", w.sigma)),
        });
    }
    if let Some(sigma) = o.sigma {
        if sigma < 0.0 {
            let factor =
                Cholesky::factor_stoppable(sym, &pair.shifted(sigma), par, stop).map_err(|e| failed(sigma, e))?;
            return Ok(Shifted { sigma, factor, below_sigma: None });
        }
        let (factor, below) =
            Cholesky::factor_ldlt_stoppable(sym, &pair.shifted(sigma), par, stop).map_err(|e| failed(sigma, e))?;
        return Ok(Shifted { sigma, factor, below_sigma: Some(below) });
    }
    let interior = if run.interior_shift { weyl_shift(pair, o.k + run.deflated_values.len()) } else { None };
    if let Some(mut sigma) = interior {
        for _attempt in 0..2 {
            control.check()?;
            let values = pair.shifted(sigma);
            let (factor, below) = match Cholesky::factor_ldlt_stoppable(sym, &values, par, stop) {
                Ok(f) => f,
                Err(FactorError::Stopped) => return Err(EigenError::Canceled),
                Err(FactorError::Failed(_)) => break,
            };
            let undeflated = below.saturating_sub(run.deflated_below(sigma));
            if undeflated > o.k {
                sigma *= WEYL_FRACTION * (o.k as f64 / undeflated as f64).powi(2);
                continue;
            }
            if solve_backward_error(pair, &values, &factor, par) <= LDLT_BACKWARD_ERROR {
                return Ok(Shifted { sigma, factor, below_sigma: Some(below) });
            }
            break;
        }
    }
    let mut sigma = default_sigma(pair);
    let mut attempt = 0;
    loop {
        control.check()?;
        match Cholesky::factor_stoppable(sym, &pair.shifted(sigma), par, stop) {
            Ok(factor) => return Ok(Shifted { sigma, factor, below_sigma: None }),
            Err(FactorError::Stopped) => return Err(EigenError::Canceled),
            Err(message) => {
                attempt += 1;
                if attempt >= 4 {
                    return Err(failed(sigma, message));
                }
                sigma *= 100.0;
            }
        }
    }
}

/// Backward error ‖K x − b‖₂ / (‖K‖_∞ ‖x‖₂ + ‖b‖₂) of one solve with `factor` (K's values on the pair's pattern)
/// for a fixed pseudo-random b.
pub(crate) fn solve_backward_error(pair: &SparsePair, values: &[f64], factor: &Cholesky, par: Par) -> f64 {
    let n = pair.n();
    let mut rng = Rng(0x5eed);
    let rhs: Vec<f64> = (0..n).map(|_| rng.next()).collect();
    let mut x = rhs.clone();
    factor.solve_in_place(MatMut::from_column_major_slice_mut(&mut x, n, 1), par);
    let mut kx = vec![0.0; n];
    crate::operators::sparse::matvec_on(&pair.pattern, values, &x, &mut kx, par.degree());
    let norm = |v: &[f64]| v.iter().map(|a| a * a).sum::<f64>().sqrt();
    let r: Vec<f64> = kx.iter().zip(&rhs).map(|(a, b)| a - b).collect();
    let k_inf = (0..n)
        .map(|j| (pair.pattern.col_ptr[j]..pair.pattern.col_ptr[j + 1]).map(|p| values[p].abs()).sum::<f64>())
        .fold(0.0, f64::max);
    let e = norm(&r) / (k_inf * norm(&x) + norm(&rhs));
    if e.is_finite() {
        e
    } else {
        f64::INFINITY
    }
}

/// The block size and subspace a run with these options would use on `n` unknowns of which `deflated` are
/// deflated, or `None` when the problem is too small for the Krylov method (the caller solves it densely).
pub fn plan(n: usize, deflated: usize, o: &EigenOptions) -> Option<(usize, usize, usize)> {
    // The iteration lives in the M-orthogonal complement of the deflated directions.
    let n = n.saturating_sub(deflated);
    if n < 2 || o.k + 1 > n {
        return None;
    }
    // Block 8 and a subspace of about 3w for w up to ~50 (2w beyond): measured best on 10k–41k icospheres for
    // k = 10…200 with one thread (block 16 cost 1.4× at k = 50: more solves per converged pair, bigger GEMMs).
    let b = o.block.unwrap_or(8).clamp(1, n - 1);
    let guard = (b / 2).max(2);
    let want = (o.k + guard).min(n - 1);
    let default_m = (2 * want).max(want + 6 * b).max((3 * want).min(want + 100));
    let msize = o.subspace.unwrap_or(default_m).max(want + 2 * b).min(n);
    // Room for the wanted pairs, one expanded and one waiting block (a thick restart keeps the wanted pairs and
    // appends the waiting block).
    (msize >= want + 2 * b).then_some((b, want, msize))
}

/// The `o.k` smallest eigenpairs of the problem deflated by `run.deflation`, and the converged guard pairs above
/// them (the result holds `want` ≥ k pairs, ascending, for the completeness check to place its shift above λ_k).
/// `Ok(None)` when the problem is too small for the Krylov method (see [`plan`]).
pub fn eigs_block_lanczos(
    pair: &SparsePair,
    o: &EigenOptions,
    symbolic: Option<&Symbolic>,
    control: Control<'_>,
    run: &Run<'_>,
) -> Result<Option<Spectrum>, EigenError> {
    let t_start = Instant::now();
    let n = pair.n();
    let k = o.k;
    let par = o.par();
    let Some((b, want, msize)) = plan(n, run.deflation.len(), o) else { return Ok(None) };
    // The basis is the solve's widest array: refused before anything is factored or allocated.
    let basis = n.saturating_mul(msize);
    if basis > o.max_values {
        return Err(EigenError::TooLarge {
            what: format!("the Krylov basis ({n} unknowns × {msize} columns)"),
            values: basis,
            limit: o.max_values,
        });
    }
    // Factor L − σM (symbolic analysis reused when given).
    let t0 = Instant::now();
    let (sym, reused) = match symbolic {
        Some(s) if s.fits(pair) => (s.clone(), true),
        _ => (Symbolic::analyze(&pair.pattern).map_err(|message| EigenError::Factorization { message })?, false),
    };
    let symbolic_s = t0.elapsed().as_secs_f64();
    control.phase("factorization", 0, k)?;
    let t1 = Instant::now();
    let threads = o.thread_count();
    // V: the basis. It is the largest allocation (1.3 GB at 164k × 1006): filled column group by column group, so
    // that a stop during its first touch of memory (about a second there) takes effect. On more than one thread it
    // is made on one of them beside the numeric factorization on the others, which gains little from a second
    // thread (164k vertices: 0.20 s on two threads against 0.23 s on one). If the factorization fails, the basis
    // was made for nothing: the solve ends with the factorization's error.
    let (shifted, made) = if threads > 1 {
        let fpar = if threads > 2 { Par::rayon(threads - 1) } else { Par::Seq };
        let (shifted, v) = rayon::join(
            || factor_shift(pair, o, &sym, fpar, run, &control),
            || super::zeros_checked(n, msize, &control, 1),
        );
        (shifted?, Some(v?))
    } else {
        (factor_shift(pair, o, &sym, par, run, &control)?, None)
    };
    let Shifted { sigma, factor: chol, below_sigma } = shifted;
    control.check()?;
    // Eigenvalues below σ the iteration must find itself (the inertia less the deflated ones).
    let below_undeflated = below_sigma.map(|nu| nu.saturating_sub(run.deflated_below(sigma)));
    let numeric_s = t1.elapsed().as_secs_f64();
    // A slice whose window holds far more pairs than it was planned for (Weyl's law misjudged the spectrum's
    // density: thin shapes) gives up at once; the caller solves in one run.
    if let Some(w) = &run.window {
        // The pairs the slice must hold: from lo to the `total`-th eigenvalue or to σ, whichever is further (top
        // slice); every one below σ (lowest slice).
        let over = match (w.total, below_sigma, below_undeflated) {
            (Some(total), Some(b), _) => b.max(total).saturating_sub(w.below_lo) > k + k / 2 + 8,
            (None, _, Some(nu)) => w.lo == f64::NEG_INFINITY && nu > k,
            _ => false,
        };
        if over {
            return Err(EigenError::NoConvergence { converged: 0, wanted: k, steps: 0 });
        }
    }
    let t2 = Instant::now();
    let mut clock = Clock::default();
    let mdiag = pair.mass_diagonal();
    let mean_mass = mdiag.iter().sum::<f64>() / n as f64;
    let mut ctx = Ctx {
        pair,
        deflation: run.deflation,
        mdiag: pair.mass_is_diagonal.then_some(mdiag),
        mean_mass,
        scratch: Vec::new(),
        threads,
    };
    let mut rng = Rng(o.seed);

    // V: the basis (expanded columns, then the waiting block Q); MQ = M Q; H = Vᵀ M T V on the expanded part;
    // E: Q's coupling, T V_exp = V_exp H + Q E, nonzero from column `e_lo` on.
    let mut v = match made {
        Some(v) => v,
        None => super::zeros_checked(n, msize, &control, ctx.threads)?,
    };
    let mut mq = RowBlock::zeros(n, b);
    let mut h = Mat::<f64>::zeros(msize, msize);
    let mut w = RowBlock::zeros(n, b);
    let mut mw = RowBlock::zeros(n, b);
    {
        let mut q0 = RowBlock::zeros(n, b);
        q0.data.iter_mut().for_each(|x| *x = rng.next());
        ctx.apply_m(q0.as_ref(), mw.as_mut());
        run.deflation.project(&mut q0.data, &mut mw.data, b, ctx.threads);
        ctx.normalize(v.as_mut(), 0, &q0, &mw, mq.as_mut(), &mut rng, &[1.0]);
    }
    let mut m = 0usize; // expanded columns
    let mut locked = 0usize;
    let mut e = Mat::<f64>::zeros(b, 0);
    let mut e_lo = 0usize;
    let (mut steps, mut restarts, mut solves) = (0usize, 0usize, 0usize);
    let mut best_converged = 0;
    // The next block step after which the projected problem is solved to test convergence (see `far` below).
    let mut next_test = 0usize;
    control.report("iterating", 0, k);
    loop {
        if control.stopped() {
            return Err(EigenError::Canceled);
        }
        let mut t = Instant::now();
        // Expand the waiting block while it fits.
        if m + 2 * b <= msize {
            basis_products::copy_par(&mut w.data, &mq.data, b, ctx.threads);
            chol.solve_in_place(w.as_mut(), par);
            clock.solve += lap(&mut t);
            solves += b;
            steps += 1;
            // Scale for the rank test: Euclidean norms² times the mean mass (no extra M-product).
            let gram: Vec<f64> = basis_products::col_dots_par(&w.data, &w.data, b, ctx.threads)
                .iter()
                .map(|g| g * ctx.mean_mass)
                .collect();
            let mut coef = Mat::<f64>::zeros(m + b, b);
            {
                let (basis, _) = v.as_ref().split_at_col(m + b);
                // The recurrence: Vᵀ M T Q = Eᵀ on the expanded part (exact arithmetic), Qᵀ M T Q = A.
                if e_lo < m {
                    let et = e.as_ref().subcols(e_lo, m - e_lo).transpose();
                    basis_products::update_par(&mut w.data, b, basis.subcols(e_lo, m - e_lo), et, -1.0, ctx.threads);
                    coef.as_mut().subrows_mut(e_lo, m - e_lo).copy_from(et);
                }
                let a = basis_products::gram_par(mq.as_ref(), &w.data, b, ctx.threads);
                basis_products::update_par(&mut w.data, b, basis.subcols(m, b), a.as_ref(), -1.0, ctx.threads);
                coef.as_mut().subrows_mut(m, b).copy_from(a.as_ref());
                // Full reorthogonalization against the whole basis (locked vectors included), after the deflated
                // directions (T keeps their complement, so this removes rounding only).
                ctx.apply_m(w.as_ref(), mw.as_mut());
                run.deflation.project(&mut w.data, &mut mw.data, b, ctx.threads);
                ctx.project_out(basis, &mut w.data, &mut mw.data, coef.as_mut());
            }
            for r in locked..m + b {
                for c in 0..b {
                    h[(r, m + c)] = coef[(r, c)];
                    h[(m + c, r)] = coef[(r, c)];
                }
            }
            for r in 0..locked {
                for c in 0..b {
                    h[(r, m + c)] = 0.0;
                    h[(m + c, r)] = 0.0;
                }
            }
            let bm = ctx.normalize(v.as_mut(), m + b, &w, &mw, mq.as_mut(), &mut rng, &gram);
            m += b;
            e = Mat::<f64>::zeros(b, m);
            e.as_mut().subcols_mut(m - b, b).copy_from(bm.as_ref());
            e_lo = m - b;
            clock.orthogonalize += lap(&mut t);
            if m < want || (m + 2 * b <= msize && steps < next_test) {
                continue;
            }
        }
        // Rayleigh–Ritz on the active (unlocked) part of the expanded basis; locked columns are Ritz vectors
        // already, with H = diag(θ) there and no coupling (deflated).
        control.check()?;
        let a0 = locked;
        let ma = m - a0;
        let hs = Mat::from_fn(ma, ma, |i, j| 0.5 * (h[(a0 + i, a0 + j)] + h[(a0 + j, a0 + i)]));
        // On the solve's threads (faer's `self_adjoint_eigen` would take the whole pool).
        let (theta_a, s_a) = super::dense::symmetric_eigen(hs.as_ref(), par)
            .map_err(|err| EigenError::Factorization { message: format!("projected eigenproblem: {err:?}") })?;
        let s_a = s_a.as_ref();
        let mut es = Mat::<f64>::zeros(b, ma);
        matmul(es.as_mut(), Accum::Replace, e.as_ref().subcols(a0, ma), s_a, 1.0, Par::Seq);
        // Candidates: (θ, locked column or active Ritz index, residual ‖E s‖₂; zero for locked pairs).
        let mut cand: Vec<(f64, Ritz, f64)> = (0..a0).map(|i| (h[(i, i)], Ritz::Locked(i), 0.0)).collect();
        for c in 0..ma {
            let r = (0..b).map(|rr| es[(rr, c)] * es[(rr, c)]).sum::<f64>().sqrt();
            cand.push((theta_a[c], Ritz::Active(c), r));
        }
        let converged = |c: &(f64, Ritz, f64)| c.2 <= o.tol * c.0.abs();
        // Ascending λ = σ + 1/θ: descending θ when σ is below the spectrum (every θ > 0); with σ inside it the
        // negative θ (λ < σ) come first, then the positive ones from the largest down.
        cand.sort_by(|x, y| (sigma + 1.0 / x.0).total_cmp(&(sigma + 1.0 / y.0)));
        let pick = select(&cand, sigma, want, run.window.as_ref(), below_sigma);
        let req = &cand[pick.req_start..pick.req_end];
        let leading = cand.iter().take_while(|c| converged(c)).count();
        // How far the wanted pairs are from the tolerance: the largest ratio of residual to tol·|θ| among the
        // candidates that must converge. Residuals fall by at most ~10–15× per block step in measured runs (10k–41k
        // spheres, k = 50…200), so at 100× per step the test cannot succeed in fewer than log₁₀₀ of that ratio steps.
        let far = req.iter().map(|c| c.2 / (o.tol * c.0.abs())).fold(0.0, f64::max);
        next_test = steps + ((far.max(1.0).log10() / 2.0) as usize).max(1);
        clock.rayleigh_ritz += lap(&mut t);
        let progress = if run.window.is_some() { req.iter().filter(|c| converged(c)).count() } else { leading };
        if progress.min(k) > best_converged {
            best_converged = progress.min(k);
            control.report("iterating", best_converged, k);
        }
        // With σ inside the spectrum, the inertia says how many eigenvalues lie below it: all of them must be among
        // the pairs returned (a cluster member the Krylov space has not met yet would otherwise go unnoticed). A
        // slice above the bottom returns only part of them; the check of the whole result counts the rest.
        let done = match &run.window {
            None => {
                let inertia_met =
                    below_undeflated.is_none_or(|nu| cand.iter().take(k).filter(|c| c.0 < 0.0).count() == nu);
                leading >= want && inertia_met
            }
            Some(w) => {
                let inertia_met = w.lo != f64::NEG_INFINITY
                    || below_undeflated.is_none_or(|nu| cand.partition_point(|c| c.0 < 0.0) == nu);
                // More converged pairs in an interior window than its inertia counts cannot be, unless an eigenvalue
                // lies within rounding of an edge and a slice beside this one claims it too: that count can never be
                // met, so the slice gives up (the caller solves in one run) instead of iterating to `max_steps`.
                let inside = cand[pick.start..pick.end].iter().filter(|c| converged(c)).count();
                if w.count.is_some_and(|count| inside > count) {
                    return Err(EigenError::NoConvergence { converged: inside, wanted: k, steps });
                }
                pick.enough && req.iter().all(converged) && inertia_met
            }
        };
        let full = m + 2 * b > msize;
        if !done && !full {
            continue;
        }
        if !done && steps >= o.max_steps {
            return Err(EigenError::NoConvergence { converged: leading.min(k), wanted: k, steps });
        }
        if done {
            // The k smallest λ: locked columns as they are, active ones as V_active S; written in ascending λ
            // (the candidates' order already; sorted defensively).
            // The k wanted pairs and the converged guard pairs above them (for the completeness check's shift).
            let top = &cand[pick.start..pick.end];
            let want = top.len();
            let act: Vec<usize> =
                top.iter().filter_map(|c| if let Ritz::Active(j) = c.1 { Some(j) } else { None }).collect();
            let s_sel = Mat::from_fn(ma, act.len(), |i, j| s_a[(i, act[j])]);
            control.report("ritz-vectors", k, k);
            ritz_in_place(&mut v, a0, ma, s_sel.as_ref(), par, &control)?;
            // Column of each candidate in V: locked ones where they are, active ones from a0 on in `top` order.
            let mut next_active = a0;
            let src: Vec<usize> = top
                .iter()
                .map(|c| match c.1 {
                    Ritz::Locked(i) => i,
                    Ritz::Active(_) => {
                        next_active += 1;
                        next_active - 1
                    }
                })
                .collect();
            let raw: Vec<f64> = top.iter().map(|c| sigma + 1.0 / c.0).collect();
            let mut idx: Vec<usize> = (0..want).collect();
            idx.sort_by(|&x, &y| raw[x].total_cmp(&raw[y]));
            let head_values = run.head.map_or(&[][..], |h| &h.values[..]);
            let h = head_values.len();
            let values: Vec<f64> = head_values.iter().copied().chain(idx.iter().map(|&j| raw[j])).collect();
            // The factor is no longer needed: freed before the eigenvectors are allocated beside the basis (at 10⁶
            // vertices, k = 100, the basis is 1.6 GB, the factor 0.5 GB and the eigenvectors 0.8 GB).
            let (factor_nnz, ldlt) = (chol.factor_nnz(), chol.is_ldlt());
            drop(chol);
            // So are the basis columns past the last one copied out (about half the basis).
            super::release_columns(&mut v, src.iter().map(|&c| c + 1).max().unwrap_or(0));
            let vectors = super::columns_checked(n, h + want, &control, ctx.threads, |j, col| {
                let from = match run.head {
                    Some(head) if j < h => head.vectors.col(j),
                    _ => v.col(src[idx[j - h]]),
                };
                for (x, y) in col.iter_mut().zip(from.iter()) {
                    *x = *y;
                }
            })?;
            clock.restart += lap(&mut t);
            control.report("converged", k, k);
            let iteration_s = t2.elapsed().as_secs_f64();
            return Ok(Some(Spectrum {
                values,
                vectors,
                residuals: vec![],
                stats: Stats {
                    method: "block-lanczos",
                    sigma,
                    block: b,
                    subspace: msize,
                    restarts,
                    block_steps: steps,
                    solves,
                    factor_nnz,
                    factorization: if ldlt { "ldlt" } else { "cholesky" },
                    below_sigma,
                    symbolic_reused: reused,
                    timings: Timings {
                        symbolic_s,
                        numeric_s,
                        iteration_s,
                        solve_s: clock.solve,
                        orthogonalize_s: clock.orthogonalize,
                        rayleigh_ritz_s: clock.rayleigh_ritz,
                        restart_s: clock.restart,
                        total_s: t_start.elapsed().as_secs_f64(),
                        ..Default::default()
                    },
                    ..Default::default()
                },
            }));
        }
        // Thick restart: [locked | kept active Ritz vectors | Q], H = diag(θ), E ← E S. Locked columns stay in
        // place (never recomputed); active pairs in the converged leading prefix are locked now (E columns zero:
        // deflated) and come first. Q and M Q stay as they are.
        restarts += 1;
        let keep = (want + msize.saturating_sub(want + 2 * b) / 2).min(m - b).max(want.min(m - b)).max(a0 + 1);
        let mut lock_now: Vec<usize> = Vec::new();
        let mut rest: Vec<usize> = Vec::new();
        // A slice keeps the candidates nearest its window (the standard run: ascending λ, as sorted).
        let order: Vec<usize> = match &run.window {
            None => (0..cand.len()).collect(),
            Some(w) => {
                let lam = |c: &(f64, Ritz, f64)| sigma + 1.0 / c.0;
                let hi = match w.total {
                    Some(_) if pick.enough && pick.end > pick.start => lam(&cand[pick.end - 1]),
                    Some(_) => f64::INFINITY,
                    None => w.hi,
                };
                let dist = |c: &(f64, Ritz, f64)| (w.lo - lam(c)).max(lam(c) - hi).max(0.0);
                let mut order: Vec<usize> = (0..cand.len()).collect();
                order.sort_by(|&x, &y| dist(&cand[x]).total_cmp(&dist(&cand[y])));
                order
            }
        };
        let lockable = |pos: usize| match run.window {
            None => pos < leading,
            Some(_) => (pick.req_start..pick.req_end).contains(&pos) && converged(&cand[pos]),
        };
        for &pos in &order {
            let c = &cand[pos];
            if let Ritz::Active(j) = c.1 {
                if lockable(pos) {
                    lock_now.push(j);
                } else if a0 + lock_now.len() + rest.len() < keep {
                    rest.push(j);
                }
            }
        }
        if run.window.is_some() && a0 + lock_now.len() + 3 * b > msize {
            // The window holds more pairs than its subspace was sized for: the caller solves without slicing.
            return Err(EigenError::NoConvergence { converged: a0 + lock_now.len(), wanted: k, steps });
        }
        let sel: Vec<usize> = lock_now.iter().chain(&rest).copied().collect();
        let keep = a0 + sel.len();
        let s_keep = Mat::from_fn(ma, sel.len(), |i, j| s_a[(i, sel[j])]);
        // V[:, a0..keep] = V[:, a0..m] S_keep in place, then Q moved to keep..keep + b (keep + b ≤ m: Q's columns
        // are not among those overwritten, and every read of the product is done before the move).
        ritz_in_place(&mut v, a0, ma, s_keep.as_ref(), par, &control)?;
        {
            let (mut left, right) = v.as_mut().split_at_col_mut(m);
            left.rb_mut().subcols_mut(keep, b).copy_from(right.subcols(0, b));
        }
        let locked_theta: Vec<f64> = (0..a0).map(|i| h[(i, i)]).collect();
        h.fill(0.0);
        for (i, &th) in locked_theta.iter().enumerate() {
            h[(i, i)] = th;
        }
        locked = a0 + lock_now.len();
        let mut e_new = Mat::<f64>::zeros(b, keep);
        for (j, &c) in sel.iter().enumerate() {
            h[(a0 + j, a0 + j)] = theta_a[c];
            if a0 + j >= locked {
                for r in 0..b {
                    e_new[(r, a0 + j)] = es[(r, c)];
                }
            }
        }
        e = e_new;
        e_lo = locked;
        m = keep;
        clock.restart += lap(&mut t);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::{generate, Shape};
    use crate::operators;

    /// The stability test of an LDLᵀ factor can fail: the factor of a nearby matrix (standing in for a factor
    /// whose entries grew without pivoting) shows a large backward error, the matrix's own factor a tiny one.
    #[test]
    fn backward_error_tells_a_good_solve_from_a_bad_one() {
        let shape = Shape::TriangleMesh(generate::icosphere(4));
        let pair = operators::build(&shape, &Default::default()).unwrap().pair;
        let sym = Symbolic::analyze(&pair.pattern).unwrap();
        let k = pair.shifted(7.0);
        let (good, _) = Cholesky::factor_ldlt(&sym, &k, Par::Seq).unwrap();
        let (other, _) = Cholesky::factor_ldlt(&sym, &pair.shifted(7.5), Par::Seq).unwrap();
        let e_good = solve_backward_error(&pair, &k, &good, Par::Seq);
        let e_other = solve_backward_error(&pair, &k, &other, Par::Seq);
        assert!(e_good < 1e-15, "{e_good}");
        assert!(e_other > LDLT_BACKWARD_ERROR, "{e_other}");
    }
}
