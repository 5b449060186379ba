//! Generalized symmetric eigensolvers for L φ = λ M φ: the k smallest eigenpairs (or all in a band), complete.
//!
//! - [`null_space`]: the zero modes the operator knows (one per connected component for Laplacians whose
//!   constants lie in the kernel) are put in the result exactly, eigenvalue 0, M-orthonormal; everything else is
//!   solved on their M-orthogonal complement. A shape in 100 parts then costs what its largest part costs, and no
//!   multiplicity of 0 can exceed the block.
//! - [`dense`]: small problems or k close to n: M = RRᵀ (Cholesky), eigen-decomposition of R⁻¹LR⁻ᵀ.
//! - [`lanczos`]: the sparse path, shift-invert with K = L − σM. The operator T = K⁻¹M is self-adjoint in the
//!   M-inner product with eigenvalues θ = 1/(λ − σ); the wanted pairs are the k smallest λ = σ + 1/θ. Where the
//!   operator has a dimension (surfaces, curves, volumes, point clouds) and k ≥ 8, σ goes inside the spectrum at
//!   0.7 × Weyl's estimate of λ_k ([`lanczos::weyl_shift`]): the wanted eigenvalues become both ends of T's
//!   spectrum and the unwanted ones are squeezed between, which cuts the block steps by about a third (38 → 26 on
//!   a 10k-vertex sphere, k = 50). K is then indefinite and factored as LDLᵀ without pivoting; its inertia counts
//!   the eigenvalues below σ (at most k, else σ is lowered once), every one of which the solver must return, and a
//!   test solve must be backward stable. Otherwise σ = −mean_j(L_jj / M_jj) / n < 0 (K positive definite: Cholesky;
//!   see [`lanczos::default_sigma`]), multiplied by 100 and retried if a pivot fails.
//!   A thick-restart block Lanczos method finds them: every step solves b right-hand sides at once (kac's own
//!   supernodal triangular solve on faer's factor, right-hand sides row-major), subtracts the recurrence's known
//!   couplings and then makes one classical Gram–Schmidt pass in the M-inner product against the whole basis
//!   (a second one only when DGKS asks), converged pairs are locked (deflated from the Krylov decomposition and
//!   never recomputed), rank-deficient blocks (invariant
//!   subspaces: several components, high multiplicities) are refilled with random vectors, and the start block
//!   comes from a fixed seed, so results are deterministic.
//! - **Completeness, checked and repaired** (on by default, [`EigenOptions::verify`]): Sylvester's inertia of
//!   L − τM, τ in the first gap above λ_k among the converged pairs (one more LDLᵀ on the same symbolic analysis),
//!   counts the eigenvalues below τ. When the count exceeds the pairs found, the found pairs are deflated and the
//!   iteration runs again for the missing ones, until the count matches ([`Completeness`]); a spectrum that stays
//!   incomplete is an error ([`EigenError::Incomplete`]), never a silent result.
//!
//! Output: eigenvalues ascending (exact zeros for the known zero modes, then the Rayleigh quotients
//! φᵀLφ / φᵀMφ of the returned vectors), M-orthonormal eigenvectors with the largest-magnitude entry positive, and
//! per pair the relative residual ‖Lφ − λMφ‖₂ / (max(|λ|, |σ|) · ‖Mφ‖₂).

// The sparse Cholesky factor lives below the solvers (`crate::cholesky`); re-exported where the eigensolver uses it.
pub use crate::cholesky::{factor, numeric, tree};

pub mod basis_products;
mod blocks;
mod completeness;
pub mod dense;
pub mod extrapolate;
pub mod lanczos;
pub mod null_space;
mod options;
mod result;
pub mod slicing;
mod small_dense;
pub mod weyl_law;

pub use options::*;
pub use result::*;

use crate::operators::sparse::SparsePair;
pub use blocks::use_dense;
use blocks::*;
pub use completeness::check_completeness;
use completeness::*;
use faer::{Mat, MatRef};
use null_space::{Deflation, ZeroModes};
use serde::Serialize;
use std::time::Instant;

/// The k smallest eigenpairs of L φ = λ M φ, complete (see [`Completeness`]).
pub fn eigs(
    pair: &SparsePair,
    options: &EigenOptions,
    symbolic: Option<&factor::Symbolic>,
    control: Control<'_>,
) -> Result<Spectrum, EigenError> {
    let t0 = Instant::now();
    let n = pair.n();
    let k = options.k;
    options.check()?;
    control.phase("null-space", 0, k)?;
    let threads = options.thread_count();
    let kernel = || {
        let zeros = if options.deflate_null_space { null_space::zero_modes(pair) } else { ZeroModes::default() };
        (zeros, Blocks::of(pair))
    };
    // The symbolic analysis (a serial AMD ordering) runs beside the null space on more
    // than one thread where the solve is almost surely sparse: past 8,000 unknowns, which the automatic choice
    // solves densely only where the shape falls apart into small components or k nearly reaches the unknowns (then
    // the analysis is dropped unused). Both are serial: two threads.
    let analyze = || {
        let t = Instant::now();
        (factor::Symbolic::analyze(&pair.pattern), t.elapsed().as_secs_f64())
    };
    let ahead = threads > 1 && options.method != Method::Dense && n > 8000 && !symbolic.is_some_and(|s| s.fits(pair));
    let ((zeros, blocks), mut analyzed) = if ahead {
        let (kernel, analyzed) = rayon::join(kernel, analyze);
        (kernel, Some(analyzed))
    } else {
        (kernel(), None)
    };
    let z = zeros.len();
    control.check()?;
    let dense = use_dense(options.method, blocks.as_ref().map_or(n, |b| b.largest), n - z, k.saturating_sub(z));
    let max = if dense { n } else { n.saturating_sub(1) };
    if k == 0 || k > max {
        return Err(EigenError::InvalidK { k, n, max });
    }
    if control.stopped() {
        return Err(EigenError::Canceled);
    }
    let components = matches!(pair.kernel, crate::operators::sparse::Kernel::Components { .. })
        .then_some(zeros.components)
        .filter(|_| options.deflate_null_space);
    let mut s = if k <= z {
        // Every pair asked for is a known zero mode.
        zero_mode_spectrum(pair, &zeros, k)
    } else if dense {
        dense_with_zero_modes(pair, &zeros, blocks.as_ref(), k, threads, control)?
    } else {
        control.phase("symbolic", 0, k)?;
        let owned;
        let (sym, reused, symbolic_s) = match symbolic {
            Some(s) if s.fits(pair) => (s, true, 0.0),
            _ => {
                let (result, seconds) = analyzed.take().unwrap_or_else(analyze);
                owned = result.map_err(|message| EigenError::Factorization { message })?;
                (&owned, false, seconds)
            }
        };
        if sym.inner.len_val() > options.max_values {
            return Err(EigenError::TooLarge {
                what: "the factor of L − σM (the symbolic analysis' fill)".into(),
                values: sym.inner.len_val(),
                limit: options.max_values,
            });
        }
        let deflation = Deflation { sparse: &zeros.vectors, dense: None };
        let zero_values = vec![0.0; z];
        // The zero modes come first in the result, written there as the eigenvectors are allocated.
        let head = (z > 0).then(|| zero_mode_spectrum(pair, &zeros, z));
        let run = lanczos::Run {
            deflation: &deflation,
            deflated_values: &zero_values,
            interior_shift: true,
            window: None,
            head: head.as_ref(),
        };
        let o = EigenOptions { k: k - z, ..options.clone() };
        let (single, mut plan) = match slicing::solve(pair, &o, sym, control, &deflation, &zero_values, head.as_ref())?
        {
            slicing::Sliced::Solved(s) => (Some(*s), None),
            slicing::Sliced::NotPlanned => (lanczos::eigs_block_lanczos(pair, &o, Some(sym), control, &run)?, None),
            slicing::Sliced::GivenUp(reason) => (
                lanczos::eigs_block_lanczos(pair, &o, Some(sym), control, &run)?,
                Some(PlanChange { planned: "slices", taken: "one-run", reason }),
            ),
        };
        drop(head);
        let mut s = match single {
            Some(s) => s,
            None => {
                let reason = "too few unknowns beyond the known zero modes for the Krylov basis".to_string();
                plan = Some(match plan {
                    Some(p) => PlanChange { taken: "dense", reason: format!("{}; then {reason}", p.reason), ..p },
                    None => PlanChange { planned: "block-lanczos", taken: "dense", reason },
                });
                dense_with_zero_modes(pair, &zeros, blocks.as_ref(), k, threads, control)?
            }
        };
        s.stats.plan = plan;
        control.check()?;
        s.stats.symbolic_reused = reused;
        s.stats.timings.symbolic_s = symbolic_s;
        let verify = options.verify && s.stats.method == "block-lanczos";
        // On more than one thread the check's first factorization runs beside `finish` (neither keeps two cores
        // busy on its own), on one of the threads given and
        // `finish` on the others. `finish` then holds at most one run's three n × 8 blocks per 24 basis columns the
        // solve held, so that with the check's factor beside them the phase stays below the iteration's memory.
        let early = if verify && threads > 1 {
            let values = s.values.clone();
            let runs = (s.stats.subspace / 24).max(1);
            let (done, early) = rayon::join(
                || finish(pair, &mut s, z, threads - 1, runs, control),
                || completeness::early_count(sym, pair, &values, k, &control, faer::Par::Seq),
            );
            done?;
            Some(early)
        } else {
            finish(pair, &mut s, z, threads, usize::MAX, control)?;
            None
        };
        if verify {
            verify_and_repair(pair, sym, options, control, (&zeros, blocks.as_ref()), &mut s, k, early)?;
        }
        s
    };
    if s.stats.method != "block-lanczos" {
        finish(pair, &mut s, z.min(k), threads, usize::MAX, control)?;
        if options.verify {
            s.stats.completeness =
                Some(Completeness::by(if s.stats.method == "dense" { "dense" } else { "null-space" }));
        }
    }
    truncate(&mut s, k);
    s.stats.components = components;
    s.stats.zero_modes = z.min(k);
    s.stats.timings.total_s = t0.elapsed().as_secs_f64();
    Ok(s)
}

/// The first k known zero modes as a spectrum (nothing solved).
pub(crate) fn zero_mode_spectrum(pair: &SparsePair, zeros: &ZeroModes, k: usize) -> Spectrum {
    let n = pair.n();
    let mut vectors = Mat::<f64>::zeros(n, k);
    for (j, z) in zeros.vectors.iter().take(k).enumerate() {
        for (&i, &v) in z.rows.iter().zip(&z.values) {
            vectors[(i as usize, j)] = v;
        }
    }
    Spectrum {
        values: vec![0.0; k],
        vectors,
        residuals: vec![],
        stats: Stats {
            method: "null-space",
            factorization: "none",
            sigma: lanczos::default_sigma(pair),
            ..Default::default()
        },
    }
}

/// Gives the memory of columns `from..` of `m` back to the system where it can (Linux: the whole pages inside those
/// columns, by `madvise(MADV_DONTNEED)`); their values then read as zeros, or keep what they held where a page is
/// shared with column `from − 1`. Columns before `from` are untouched. For a basis at the end of a solve: its
/// columns past the last eigenvector copied out are dead, and the eigenvectors' allocation would otherwise come on
/// top of the whole basis (the process' peak at 10⁶ vertices).
pub(crate) fn release_columns(m: &mut Mat<f64>, from: usize) {
    #[cfg(target_os = "linux")]
    {
        let (n, cols) = (m.nrows(), m.ncols());
        let stride = m.col_stride();
        if from >= cols || n == 0 || stride < n as isize {
            return;
        }
        // SAFETY: sysconf has no preconditions.
        let page = unsafe { libc::sysconf(libc::_SC_PAGESIZE) };
        let page = if page > 0 { page as usize } else { 4096 };
        let base = m.as_ptr_mut() as usize;
        let size = std::mem::size_of::<f64>();
        let start = base + from * stride as usize * size;
        let end = base + ((cols - 1) * stride as usize + n) * size;
        let (lo, hi) = (start.next_multiple_of(page), end / page * page);
        if hi > lo {
            // SAFETY: [lo, hi) is whole pages inside the elements of columns from.. of `m`, memory `m` owns and this
            // function holds exclusively. MADV_DONTNEED on the allocator's private anonymous memory only replaces
            // those pages' contents with zeros (valid f64 values) when next touched; the mapping stays valid and
            // the allocator frees it as before. A failure leaves the pages as they were.
            unsafe {
                libc::madvise(lo as *mut libc::c_void, hi - lo, libc::MADV_DONTNEED);
            }
        }
    }
    #[cfg(not(target_os = "linux"))]
    let _ = (m, from);
}

/// An n × m matrix of zeros, filled 64 columns at a time with a stop check between: a basis or a set of
/// eigenvectors of a large problem is gigabytes, whose first touch takes about a second.
pub(crate) fn zeros_checked(n: usize, m: usize, control: &Control<'_>, threads: usize) -> Result<Mat<f64>, EigenError> {
    columns_checked(n, m, control, threads, |_, _| {})
}

/// An n × m matrix whose column c is written by `fill(c, column)` (the column holds zeros when `fill` sees it), 64
/// columns at a time with a stop check between. With `threads` > 1 (0: the current pool's) the column groups are made
/// on the current rayon pool: the page faults of the first touch of a large matrix (gigabytes, about a second) are
/// shared out, and each column is filled while it is still in cache.
pub(crate) fn columns_checked(
    n: usize,
    m: usize,
    control: &Control<'_>,
    threads: usize,
    fill: impl Fn(usize, &mut [f64]) + Sync,
) -> Result<Mat<f64>, EigenError> {
    let mut out = Columns::new(n, m);
    out.append(m, control, threads, fill)?;
    Ok(out.done())
}

/// An n-row matrix of at most `capacity` columns, made by appending columns ([`Columns::append`]).
pub(crate) struct Columns {
    mat: Mat<f64>,
    n: usize,
    capacity: usize,
    stride: usize,
}

impl Columns {
    pub(crate) fn new(n: usize, capacity: usize) -> Self {
        // One row and one column more than needed: faer's `set_dims` asks for dimensions strictly below the
        // capacities.
        let mat = Mat::<f64>::with_capacity(n + 1, capacity + 1);
        let stride = usize::try_from(mat.col_stride()).expect("a column stride");
        // faer documents `with_capacity` as reserving at least n + 1 rows (the column stride) and capacity + 1
        // columns.
        assert!(stride > n, "row capacity for n rows");
        Columns { mat, n, capacity, stride }
    }

    /// Appends `count` columns, the j-th of them written by `fill(j, column)` (zeros when `fill` sees it), 64 at a
    /// time with a stop check between, on the current rayon pool when `threads` > 1 (0: the pool's threads).
    pub(crate) fn append(
        &mut self,
        count: usize,
        control: &Control<'_>,
        threads: usize,
        fill: impl Fn(usize, &mut [f64]) + Sync,
    ) -> Result<(), EigenError> {
        use rayon::prelude::*;
        const GROUP: usize = 64;
        let (n, first) = (self.n, self.mat.ncols());
        assert!(count <= self.capacity - first, "{count} columns past the capacity");
        #[derive(Clone, Copy)]
        struct Base(*mut f64);
        // SAFETY: the groups below write disjoint columns of the allocation through this pointer, and nothing else
        // touches it until they are done.
        unsafe impl Send for Base {}
        // SAFETY: as above.
        unsafe impl Sync for Base {}
        impl Base {
            /// The pointer (a method, so that closures capture the `Base`, not its field).
            fn get(self) -> *mut f64 {
                self.0
            }
        }
        let (base, stride) = (Base(self.mat.as_ptr_mut()), self.stride);
        let group = |g: usize| -> Result<(), EigenError> {
            control.check()?;
            for j in g * GROUP..((g + 1) * GROUP).min(count) {
                // SAFETY: column first + j (< the capacity, asserted above, within the column capacity `new`
                // reserved) starts at (first + j)·stride and holds n < stride values, inside that allocation, past
                // the matrix's current columns; it is zeroed before the slice over it is made, and each column is
                // written by one group only.
                let column = unsafe {
                    let p = base.get().add((first + j) * stride);
                    std::ptr::write_bytes(p, 0, n);
                    std::slice::from_raw_parts_mut(p, n)
                };
                fill(j, column);
            }
            Ok(())
        };
        let groups = count.div_ceil(GROUP);
        let threads = if threads == 0 { rayon::current_num_threads() } else { threads };
        if threads > 1 && groups > 1 {
            // One contiguous run of groups per thread given: a pool shared with other jobs (the service's) lends
            // this solve no more threads than it was given.
            let runs = threads.min(groups);
            (0..runs)
                .into_par_iter()
                .with_max_len(1)
                .try_for_each(|t| (groups * t / runs..groups * (t + 1) / runs).try_for_each(group))?;
        } else {
            (0..groups).try_for_each(group)?;
        }
        // SAFETY: n and first + count are below the capacities `new` reserved (n + 1 rows, capacity + 1 columns), the
        // first `first` columns were written before, and the groups above wrote every entry of the new ones.
        unsafe { self.mat.set_dims(n, first + count) };
        Ok(())
    }

    pub(crate) fn done(self) -> Mat<f64> {
        self.mat
    }
}

/// Keeps the first k pairs.
pub(crate) fn truncate(s: &mut Spectrum, k: usize) {
    if s.values.len() > k {
        s.values.truncate(k);
        s.residuals.truncate(k);
        // In place: the columns past k stay allocated (guard pairs, a few), nothing is copied.
        let n = s.vectors.nrows();
        s.vectors.truncate(n, k);
    }
}

/// Fixes signs (largest-magnitude entry positive), replaces each eigenvalue by the Rayleigh quotient φᵀLφ / φᵀMφ
/// of its vector and computes true residuals (block products with L and M, eight columns at a time), then keeps
/// the pairs in ascending order. The first `exact` pairs are known zero modes: their eigenvalue stays exactly 0.
/// The Rayleigh quotient's error is quadratic in the vector's, and it does not
/// depend on the shift: a solver's λ = σ + 1/θ carries θ's rounding error magnified by (λ − σ)², which with σ
/// inside the spectrum reached 10⁻¹¹ relative on the lowest eigenvalues of a 41k-vertex sphere (10⁻¹⁴ with the
/// quotient). It runs on `threads` threads (0: the pool's) in at most `most_runs` runs of column blocks.
pub(crate) fn finish(
    pair: &SparsePair,
    s: &mut Spectrum,
    exact: usize,
    threads: usize,
    most_runs: usize,
    control: Control<'_>,
) -> Result<(), EigenError> {
    let n = pair.n();
    let k = s.values.len();
    let sigma_floor = s.stats.sigma.abs().max(f64::MIN_POSITIVE);
    s.residuals = vec![0.0; k];
    // Eight columns at a time as one row-major block: the block products take it without transposing. The blocks
    // are split into runs of consecutive blocks, one per thread up to four (or `most_runs`), side by side, and the
    // threads beyond the runs share the runs' sparse products (the sparse products split their rows over the whole
    // pool, so one run on two threads goes as fast as two runs).
    const B: usize = 8;
    let blocks: Vec<usize> = (0..k).step_by(B).collect();
    let vectors = s.vectors.as_ref();
    let values = &s.values;
    // Each pair: (column, Rayleigh quotient, residual, whether its largest-magnitude entry is negative). The sign is
    // found as the column is copied for the products (rather than in a serial pass of its own over every
    // vector); the quotient and the residual do not depend on it.
    let block_run = |run: &[usize], product_threads: usize| -> Result<Vec<(usize, f64, f64, bool)>, EigenError> {
        let mut scratch = Vec::new();
        let (mut xr, mut lr, mut mr) = (vec![0.0; n * B], vec![0.0; n * B], vec![0.0; n * B]);
        let mut out = Vec::with_capacity(run.len() * B);
        for &j0 in run {
            control.check()?;
            let bw = B.min(k - j0);
            let mut negative = [false; B];
            for c in 0..bw {
                let mut big = 0.0f64;
                for (i, &x) in vectors.col(j0 + c).iter().enumerate() {
                    xr[i * bw + c] = x;
                    if x.abs() > big {
                        (big, negative[c]) = (x.abs(), x < 0.0);
                    }
                }
            }
            let x = faer::MatRef::from_row_major_slice(&xr[..n * bw], n, bw);
            let product = |values: &[f64], out: &mut [f64], scratch: &mut Vec<f64>| {
                let y = faer::MatMut::from_row_major_slice_mut(&mut out[..n * bw], n, bw);
                crate::operators::sparse::spmm(&pair.pattern, values, x, y, scratch, product_threads);
            };
            product(&pair.stiffness, &mut lr, &mut scratch);
            product(&pair.mass, &mut mr, &mut scratch);
            let (mut xlx, mut xmx) = ([0.0f64; B], [0.0f64; B]);
            let (xb, lb, mb) = (&xr[..n * bw], &lr[..n * bw], &mr[..n * bw]);
            for ((xi, li), mi) in xb.chunks_exact(bw).zip(lb.chunks_exact(bw)).zip(mb.chunks_exact(bw)) {
                for c in 0..bw {
                    xlx[c] += xi[c] * li[c];
                    xmx[c] += xi[c] * mi[c];
                }
            }
            let mut lam = [0.0f64; B];
            for c in 0..bw {
                lam[c] = if j0 + c < exact {
                    0.0
                } else if xmx[c] > 0.0 {
                    xlx[c] / xmx[c]
                } else {
                    values[j0 + c]
                };
            }
            let (mut r, mut mnorm) = ([0.0f64; B], [0.0f64; B]);
            for (li, mi) in lb.chunks_exact(bw).zip(mb.chunks_exact(bw)) {
                for c in 0..bw {
                    r[c] += (li[c] - lam[c] * mi[c]).powi(2);
                    mnorm[c] += mi[c] * mi[c];
                }
            }
            for c in 0..bw {
                let res = r[c].sqrt() / (lam[c].abs().max(sigma_floor) * mnorm[c].sqrt());
                out.push((j0 + c, lam[c], res, negative[c]));
            }
        }
        Ok(out)
    };
    // At most four runs: each holds three n × 8 buffers (192 MB at 10⁶ unknowns).
    let given = if threads == 0 { rayon::current_num_threads() } else { threads }.max(1);
    let threads = given.clamp(1, blocks.len().clamp(1, 4).min(most_runs.max(1)));
    let runs: Vec<&[usize]> = blocks.chunks(blocks.len().div_ceil(threads).max(1)).collect();
    // Run r's sparse products on its share of the threads: the first `given % runs` runs one more.
    let share = |r: usize| (given / runs.len().max(1) + usize::from(r < given % runs.len().max(1))).max(1);
    type Rows = Vec<(usize, f64, f64, bool)>;
    let results: Vec<Result<Rows, EigenError>> = if runs.len() > 1 {
        use rayon::prelude::*;
        runs.par_iter().enumerate().with_max_len(1).map(|(r, run)| block_run(run, share(r))).collect()
    } else {
        runs.iter().map(|run| block_run(run, share(0))).collect()
    };
    let mut flip = vec![false; k];
    for r in results {
        for (j, lam, res, negative) in r? {
            s.values[j] = lam;
            s.residuals[j] = res;
            flip[j] = negative;
        }
    }
    // Signs fixed: the largest-magnitude entry of each vector positive (in as many pieces as runs above).
    let negate = |(j, col): (usize, faer::ColMut<'_, f64>)| {
        if flip[j] {
            col.iter_mut().for_each(|x| *x = -*x);
        }
    };
    if threads > 1 {
        use rayon::prelude::*;
        s.vectors.par_col_iter_mut().enumerate().with_min_len(k.div_ceil(threads)).for_each(negate);
    } else {
        s.vectors.col_iter_mut().enumerate().for_each(negate);
    }
    // Members of a cluster may trade places by rounding.
    if s.values.windows(2).any(|w| w[0] > w[1]) {
        let mut idx: Vec<usize> = (0..k).collect();
        idx.sort_by(|&a, &b| s.values[a].total_cmp(&s.values[b]));
        s.values = idx.iter().map(|&j| s.values[j]).collect();
        s.residuals = idx.iter().map(|&j| s.residuals[j]).collect();
        permute_columns(&mut s.vectors, &idx);
    }
    Ok(())
}

/// New column j of `m` is old column idx[j] (`idx` a permutation), moved in place along the permutation's cycles with
/// one column of scratch (a sorted copy was another n × k matrix beside the first).
fn permute_columns(m: &mut Mat<f64>, idx: &[usize]) {
    let mut placed = vec![false; idx.len()];
    let mut held = vec![0.0; m.nrows()];
    for start in 0..idx.len() {
        if placed[start] || idx[start] == start {
            continue;
        }
        held.iter_mut().zip(m.col(start).iter()).for_each(|(h, &x)| *h = x);
        let mut j = start;
        while idx[j] != start {
            copy_column(m, idx[j], j);
            placed[j] = true;
            j = idx[j];
        }
        m.col_mut(j).iter_mut().zip(&held).for_each(|(x, &h)| *x = h);
        placed[j] = true;
    }
}

/// Column `from` of `m` copied over column `to`.
pub(crate) fn copy_column(m: &mut Mat<f64>, from: usize, to: usize) {
    use faer::reborrow::Reborrow;
    if from == to {
        return;
    }
    let (left, right) = m.as_mut().split_at_col_mut(from.max(to));
    if from < to {
        right.col_mut(0).copy_from(left.rb().col(from));
    } else {
        left.col_mut(to).copy_from(right.rb().col(0));
    }
}

/// All eigenpairs with λ in [a, b]. This asks for the smallest k pairs with k doubling (from 16) until the
/// largest found exceeds b or k reaches the solver's limit; the symbolic analysis is done once and reused, and only
/// every solve is checked for completeness, the last one's shift lying above b, so the check covers the band. Efficient for
/// bands near the bottom of the spectrum, which is where shape analysis looks. At most `max_pairs` pairs are
/// solved for (every pair below b is, to reach the band): a band that needs more is refused (`invalid-option`).
pub fn eigs_band(
    pair: &SparsePair,
    a: f64,
    b: f64,
    max_pairs: usize,
    options: &EigenOptions,
    control: Control<'_>,
) -> Result<Spectrum, EigenError> {
    if !(a <= b) || !a.is_finite() || !b.is_finite() {
        return Err(EigenError::InvalidOption { name: "band", message: format!("[{a}, {b}] is not an interval") });
    }
    let n = pair.n();
    let symbolic = factor::Symbolic::analyze(&pair.pattern).map_err(|message| EigenError::Factorization { message })?;
    let max_pairs = max_pairs.max(1);
    let mut k = 16usize.min(n.saturating_sub(1)).min(max_pairs).max(1);
    loop {
        let s = eigs(pair, &EigenOptions { k, ..options.clone() }, Some(&symbolic), control)?;
        let top = s.values.last().copied().unwrap_or(f64::INFINITY);
        let limit = if s.stats.method == "dense" { n } else { n - 1 };
        if top > b || k >= limit {
            let keep: Vec<usize> = (0..s.values.len()).filter(|&j| s.values[j] >= a && s.values[j] <= b).collect();
            let vectors = Mat::from_fn(n, keep.len(), |i, j| s.vectors[(i, keep[j])]);
            let below = s.values.iter().filter(|&&v| v < a).count();
            return Ok(Spectrum {
                values: keep.iter().map(|&j| s.values[j]).collect(),
                residuals: keep.iter().map(|&j| s.residuals[j]).collect(),
                vectors,
                stats: Stats { below_band: Some(below), ..s.stats },
            });
        }
        if k >= max_pairs {
            return Err(EigenError::InvalidOption {
                name: "band",
                message: format!(
                    "the {k} smallest eigenvalues all lie at or below {top:.6e} ≤ b = {b}: reaching the band \
                     [{a}, {b}] takes more than the limit of {max_pairs} eigenpairs; narrow it or lower b"
                ),
            });
        }
        k = (2 * k).min(limit).min(max_pairs);
    }
}

#[cfg(test)]
mod tests {
    /// New column j is old column idx[j], across cycles of several lengths.
    #[test]
    fn columns_are_permuted_in_place() {
        let (n, k) = (5, 9);
        let original = faer::Mat::from_fn(n, k, |i, j| (10 * j + i) as f64);
        // Cycles of length 1, 2 and 6.
        let idx = [0, 2, 1, 4, 5, 6, 7, 8, 3];
        let mut m = original.clone();
        super::permute_columns(&mut m, &idx);
        for (j, &from) in idx.iter().enumerate() {
            assert_eq!(m.col(j), original.col(from), "column {j}");
        }
    }

    /// On several threads, the zeros come out with the asked shape, every entry zero and writable (odd sizes: a last
    /// column group of 2, rows not a multiple of anything); a raised stop flag ends the fill with `Canceled`.
    #[test]
    fn zeros_on_several_threads() {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(2).build().unwrap();
        let (n, m) = (1_003, 130);
        let mut z = pool.install(|| super::zeros_checked(n, m, &super::Control::default(), 2)).unwrap();
        assert_eq!((z.nrows(), z.ncols()), (n, m));
        assert!((0..m).all(|j| (0..n).all(|i| z[(i, j)] == 0.0)));
        z[(n - 1, m - 1)] = 1.0;
        assert_eq!(z.as_ref().sum(), 1.0);
        let stop = std::sync::atomic::AtomicBool::new(true);
        let control = super::Control { stop: Some(&stop), ..super::Control::default() };
        let r = pool.install(|| super::zeros_checked(n, m, &control, 2));
        assert!(matches!(r, Err(super::EigenError::Canceled)));
    }

    /// `finish` shares the threads it is given among its runs of column blocks, the leftover ones to the first runs'
    /// sparse products: each product with L makes as many ranges of rows as its run has threads. With one run (as
    /// beside the completeness check with a small basis) that run's products take every thread given.
    #[test]
    fn finish_shares_its_threads_among_its_runs() {
        use crate::geometry::{generate, Shape};
        let shape = Shape::TriangleMesh(generate::icosphere(5));
        let pair = crate::operators::build(&shape, &Default::default()).unwrap().pair;
        let o = super::EigenOptions { k: 16, method: super::Method::Sparse, threads: 1, ..Default::default() };
        let solved = super::eigs(&pair, &o, None, super::Control::default()).unwrap();
        let pool = rayon::ThreadPoolBuilder::new().num_threads(4).build().unwrap();
        // 16 pairs: two blocks of eight, so one product with L per block.
        for (threads, most_runs, ranges) in [(3, 1, 6), (3, usize::MAX, 3), (4, usize::MAX, 4), (1, usize::MAX, 2)] {
            let mut s = solved.clone();
            let (done, seen) = crate::operators::sparse::tests::ranges_of(&pair.stiffness, || {
                pool.install(|| super::finish(&pair, &mut s, 1, threads, most_runs, super::Control::default()))
            });
            done.unwrap();
            assert_eq!(seen.len(), ranges, "{threads} threads, at most {most_runs} runs: {seen:?}");
            assert_eq!(s.values, solved.values, "{threads} threads, at most {most_runs} runs");
        }
    }

    /// Columns made on a pool of four threads for a solve given two are made by at most two of them (each group of
    /// columns waits a little, so that idle threads of the pool would take groups if they were offered).
    #[test]
    fn columns_keep_to_the_threads_given() {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(4).build().unwrap();
        let seen = std::sync::Mutex::new(std::collections::HashSet::new());
        let (n, m) = (100, 64 * 16);
        let made = pool.install(|| {
            super::columns_checked(n, m, &super::Control::default(), 2, |j, col| {
                if j % 64 == 0 {
                    seen.lock().unwrap().insert(rayon::current_thread_index());
                    std::thread::sleep(std::time::Duration::from_millis(2));
                }
                col[0] = j as f64;
            })
        });
        let made = made.unwrap();
        assert!((0..m).all(|j| made[(0, j)] == j as f64));
        let seen = seen.into_inner().unwrap();
        assert!(seen.len() <= 2, "threads used: {seen:?}");
    }

    /// Released columns read as zeros (or as they were, on a page shared with a kept column) and can be written
    /// again; the columns before them keep their values.
    #[test]
    fn released_columns_leave_the_others_as_they_were() {
        let (n, m, from) = (3_000, 40, 17);
        let value = |i: usize, j: usize| (i * m + j) as f64 + 0.5;
        let mut a = faer::Mat::from_fn(n, m, value);
        super::release_columns(&mut a, from);
        let mut zeros = 0;
        for j in 0..m {
            for i in 0..n {
                let x = a[(i, j)];
                if j < from {
                    assert_eq!(x, value(i, j), "kept column {j}");
                } else {
                    assert!(x == value(i, j) || x == 0.0, "released column {j}: {x}");
                    zeros += usize::from(x == 0.0);
                }
            }
        }
        if cfg!(target_os = "linux") {
            // 23 columns of 24 kB: at least 16 whole pages.
            assert!(zeros >= 16 * 512, "{zeros} values released");
        }
        a.col_mut(m - 1).fill(2.0);
        assert!((0..n).all(|i| a[(i, m - 1)] == 2.0));
    }
}
