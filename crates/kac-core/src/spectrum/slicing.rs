//! Spectrum slicing: the k smallest pairs found as several slices of [0, λ_k], each by shift-invert Lanczos around a
//! shift of its own, with its own factorization, the slices solved in parallel on the threads given.
//!
//! - **The plan.** Weyl's law cuts the interval into windows expected to hold the same number of pairs; one LDLᵀ
//!   factorization at every edge between two windows counts, by Sylvester's inertia, the eigenvalues below it, so
//!   each window's count is known exactly and its Krylov subspace is sized for what it holds (Weyl's even split
//!   meets clustered spectra unevenly: a window of the sphere can hold a 57-fold cluster more than planned), and a
//!   window past the k-th eigenvalue is dropped.
//! - **A slice.** An interior window [lo, hi) is solved around its midpoint σ and is done when as many converged
//!   pairs lie in it as the inertia counts: that proves the window complete. The lowest window is the standard
//!   interior-shift run (σ at 0.7 of its top, every eigenvalue below σ returned); the top one returns the pairs up to
//!   the k-th eigenvalue counted from the bottom (its own inertia at σ says how many lie below σ) and guard pairs
//!   above it, for the completeness check of the whole; its subspace has up to [`TOP_EXTRA`] more columns, for a
//!   cluster across the k-th eigenvalue.
//! - **The edges.** Eigenvectors of different slices are M-orthogonal as far as their residuals allow; at every edge,
//!   where a cluster may be split between two slices, the pairs within a tenth of the narrower window go through one
//!   Rayleigh–Ritz step together (M-orthonormalized, a direction held twice dropped by rank).
//! - **Completeness** is then checked as for one run: Sylvester's inertia at a shift in a gap above λ_k must count
//!   exactly the pairs found below it, and missed pairs are repaired.
//! - **What it costs.** A window has unwanted eigenvalues on both sides, where the lowest run has them on one, so a
//!   slice's pairs take more block steps (and solves) than the same number at the bottom of one run; what slicing
//!   saves is the Gram–Schmidt work, which grows with the square of the basis, and memory, since a slice's basis
//!   holds about twice its own pairs, not twice k. Measured on the 164k-vertex sphere (BENCHMARKS.md): at k = 1000
//!   eight slices take 39.6 s and 2.8 GB on two threads against 58.6 s and 4.2 GB in one run; at k = 200 one run is
//!   faster on one thread and on two. The automatic plan slices from [`SLICING_MIN_PAIRS`] pairs on.
//!
//! - **Lent threads.** A host (the service) may lend idle threads of the solve's pool through [`Control::lender`]:
//!   one per slice beyond the solve's own `threads` (asked again after each slice of the solve's own thread), each
//!   taking the next slice waiting until no slice is left or the host wants it back ([`Lender`]). Each slice's report
//!   names the pool thread that solved it.
//!
//! - **Slices elsewhere.** A host may also have slices solved by other machines through [`Control::farm`] (the
//!   service's slice jobs, which any replica sharing its queue claims): the slices the solve's own and lent threads
//!   do not start at once are offered as [`SliceTask`]s; a thread that comes to an offered slice nobody has started
//!   takes it back, and the solve's own threads collect the others once no slice of their own is left. The machine
//!   that solves one rebuilds the pencil from the same request, checks it against the task's digest
//!   ([`pencil_digest`]), and runs [`solve_slice`]: the same run as here. A slice that failed or was lost elsewhere
//!   is solved here after all. Its report names who solved it.
//!
//! A plan the problem does not fit (a window holding more pairs than its subspace allows, a factor that is not
//! backward stable, too few unknowns) is given up, and the k pairs are solved in one run instead.

use super::lanczos::{self, Window};
use super::*;
use rayon::prelude::*;
use serde::Deserialize;
use std::sync::atomic::{AtomicUsize, Ordering};

/// The fewest pairs (beyond the known zero modes) the automatic plan slices: below, one run is faster on one thread
/// and on two (measured on the 164k-vertex sphere at k = 200: 9.4 s in one run against 15.2 s in two slices on one
/// thread, 8.2 s against 9.5 s on two: a slice's window has unwanted eigenvalues on both sides, so its pairs take
/// more block steps than the same pairs at the bottom of one run; BENCHMARKS.md).
pub const SLICING_MIN_PAIRS: usize = 400;

/// Pairs per slice the automatic plan aims at (measured on the 164k-vertex sphere at k = 1000).
pub const PAIRS_PER_SLICE: usize = 125;

/// The window an edge's Rayleigh–Ritz step reaches into on each side, as a fraction of the narrower window.
const EDGE_FRACTION: f64 = 0.1;

/// What one slice did (reported in the solver's statistics).
#[derive(Debug, Clone, Serialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct SliceReport {
    /// The window's lower end (null for the lowest slice, which starts at the bottom of the spectrum).
    pub lo: Option<f64>,
    /// The window's upper end (null for the top slice, which goes up to the k-th eigenvalue and its guards).
    pub hi: Option<f64>,
    pub sigma: f64,
    /// Eigenvalues below σ (Sylvester's inertia of the slice's LDLᵀ factor).
    pub below_sigma: Option<usize>,
    /// Pairs the slice returned.
    pub pairs: usize,
    pub block_steps: usize,
    pub solves: usize,
    pub restarts: usize,
    /// Factorization and iteration of this slice.
    pub seconds: f64,
    /// The thread of the solve's pool that solved this slice (its index there: in the service, the worker); null
    /// outside a pool. Slices of one job on several workers are the idle workers the service lent it.
    pub worker: Option<usize>,
    /// Who solved the slice when another machine did (in the service, the replica whose slice job solved it;
    /// `worker` is then null); null when the solve's own or lent threads did.
    pub solved_by: Option<String>,
}

/// One slice as another machine solves it ([`Farm`], [`solve_slice`]): its window, the options of its run, and the
/// digest of the pencil it belongs to.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SliceTask {
    /// Its place among the solve's slices (0: the lowest).
    pub index: usize,
    pub window: Window,
    /// The run's options: `k` the pairs the window holds, its subspace (`threads` is the solving machine's own).
    pub options: EigenOptions,
    /// [`pencil_digest`] of the problem: a machine that built another pencil refuses the task.
    pub pencil: String,
}

/// A slice solved elsewhere, as [`Farm::collect`] hands it back.
pub struct Solved {
    /// The slice's pairs; its statistics those [`PartStats`] carries.
    pub spectrum: Spectrum,
    pub seconds: f64,
    pub by: String,
}

/// What a slice's run did, as it travels with the pairs from the machine that solved it.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct PartStats {
    pub sigma: f64,
    pub block: usize,
    pub subspace: usize,
    pub restarts: usize,
    pub block_steps: usize,
    pub solves: usize,
    pub factor_nnz: usize,
    pub below_sigma: Option<usize>,
    pub numeric_s: f64,
    pub solve_s: f64,
    pub orthogonalize_s: f64,
    pub rayleigh_ritz_s: f64,
    pub restart_s: f64,
}

impl PartStats {
    pub fn of(s: &Stats) -> Self {
        let t = &s.timings;
        PartStats {
            sigma: s.sigma,
            block: s.block,
            subspace: s.subspace,
            restarts: s.restarts,
            block_steps: s.block_steps,
            solves: s.solves,
            factor_nnz: s.factor_nnz,
            below_sigma: s.below_sigma,
            numeric_s: t.numeric_s,
            solve_s: t.solve_s,
            orthogonalize_s: t.orthogonalize_s,
            rayleigh_ritz_s: t.rayleigh_ritz_s,
            restart_s: t.restart_s,
        }
    }
    pub fn stats(&self) -> Stats {
        Stats {
            method: "block-lanczos",
            factorization: "ldlt",
            sigma: self.sigma,
            block: self.block,
            subspace: self.subspace,
            restarts: self.restarts,
            block_steps: self.block_steps,
            solves: self.solves,
            factor_nnz: self.factor_nnz,
            below_sigma: self.below_sigma,
            timings: Timings {
                numeric_s: self.numeric_s,
                solve_s: self.solve_s,
                orthogonalize_s: self.orthogonalize_s,
                rayleigh_ritz_s: self.rayleigh_ritz_s,
                restart_s: self.restart_s,
                ..Default::default()
            },
            ..Default::default()
        }
    }
}

/// SHA-256 (hex) of a pencil: its size, dimension, pattern, both matrices' values to the bit, and what is known of
/// its null space. Two machines that built the same operator from the same request agree on it; any other pencil
/// differs.
pub fn pencil_digest(pair: &SparsePair) -> String {
    use sha2::{Digest, Sha256};
    let mut h = Sha256::new();
    let word = |h: &mut Sha256, x: u64| h.update(x.to_le_bytes());
    word(&mut h, pair.n() as u64);
    word(&mut h, pair.dimension.map_or(0, |d| 1 + d as u64));
    word(&mut h, pair.mass_is_diagonal as u64);
    for list in [&pair.pattern.col_ptr, &pair.pattern.row_idx] {
        word(&mut h, list.len() as u64);
        for &x in list.iter() {
            word(&mut h, x as u64);
        }
    }
    for values in [&pair.stiffness, &pair.mass] {
        word(&mut h, values.len() as u64);
        for &x in values.iter() {
            word(&mut h, x.to_bits());
        }
    }
    match &pair.kernel {
        crate::operators::sparse::Kernel::Unknown => word(&mut h, 0),
        crate::operators::sparse::Kernel::Components { weights, anchored } => {
            word(&mut h, 1);
            for &w in weights.iter().flat_map(|w| w.iter()) {
                word(&mut h, w.to_bits());
            }
            word(&mut h, u64::MAX);
            for &a in anchored.iter().flat_map(|a| a.iter()) {
                word(&mut h, a as u64);
            }
        }
    }
    h.finalize().iter().map(|b| format!("{b:02x}")).collect()
}

/// Solves one slice of a sliced solve on this machine, as the machine that planned it would: the pencil's known
/// zero modes deflated, its own symbolic analysis, and the task's window and options (on `threads` threads).
/// A pencil other than the task's is refused.
pub fn solve_slice(
    pair: &SparsePair,
    task: &SliceTask,
    threads: usize,
    control: Control<'_>,
) -> Result<Spectrum, EigenError> {
    let o = EigenOptions { threads, ..task.options.clone() };
    o.check()?;
    if pencil_digest(pair) != task.pencil {
        return Err(EigenError::InvalidOption {
            name: "pencil",
            message: "the slice belongs to another pencil than the one built here".into(),
        });
    }
    control.phase("null-space", 0, o.k)?;
    let zeros = if o.deflate_null_space { null_space::zero_modes(pair) } else { null_space::ZeroModes::default() };
    control.phase("symbolic", 0, o.k)?;
    let sym = factor::Symbolic::analyze(&pair.pattern).map_err(|message| EigenError::Factorization { message })?;
    let deflation = null_space::Deflation { sparse: &zeros.vectors, dense: None };
    let zero_values = vec![0.0; zeros.len()];
    let run = lanczos::Run {
        deflation: &deflation,
        deflated_values: &zero_values,
        interior_shift: true,
        window: Some(task.window),
        head: None,
    };
    lanczos::eigs_block_lanczos(pair, &o, Some(&sym), control, &run)?.ok_or(EigenError::NoConvergence {
        converged: 0,
        wanted: o.k,
        steps: 0,
    })
}

/// A thread lent by a [`Lender`], given back when dropped, and taken off the count of loans out.
struct Returned<'a>(&'a dyn Lender, &'a AtomicUsize);

/// The slice loops running as tasks of the pool, and whether the caller has closed the queue (its own loop found no
/// slice left): a task that starts after that has nothing to do.
#[derive(Default)]
struct Tasks {
    state: std::sync::Mutex<(usize, bool)>,
    ended: std::sync::Condvar,
}

/// A task's loop, counted while it runs (its end signalled when dropped, a panic included).
struct Started<'a>(&'a Tasks);

impl Tasks {
    fn start(&self) -> Option<Started<'_>> {
        let mut st = self.state.lock().unwrap_or_else(|e| e.into_inner());
        if st.1 {
            return None;
        }
        st.0 += 1;
        Some(Started(self))
    }
    fn close_and_wait(&self) {
        let mut st = self.state.lock().unwrap_or_else(|e| e.into_inner());
        st.1 = true;
        while st.0 > 0 {
            st = self.ended.wait(st).unwrap_or_else(|e| e.into_inner());
        }
    }
}

impl Drop for Started<'_> {
    fn drop(&mut self) {
        self.0.state.lock().unwrap_or_else(|e| e.into_inner()).0 -= 1;
        self.0.ended.notify_all();
    }
}

impl Drop for Returned<'_> {
    fn drop(&mut self) {
        self.1.fetch_sub(1, Ordering::SeqCst);
        self.0.give_back();
    }
}

/// Columns added at most to the top slice's default subspace (as many as its pairs below that). Measured on the
/// 164k-vertex sphere, k = 1000, 8 slices, two threads: the top slice (104 pairs, the 63-fold cluster at λ ≈ 992
/// across the 1000th eigenvalue) took 99 block steps and 13 restarts in the default 216 columns, 63 steps and 2
/// restarts with 100 more, 61–62 with 200 or 300; the whole solve 32.6–34.9 s against 29.9–31.5 s, its peak memory
/// unchanged (2.9 GB: the top slice runs first, before the other slices' eigenvectors are held).
const TOP_EXTRA: usize = 100;

/// The number of slices for `wanted` pairs (beyond the deflated ones) on `threads` threads, unless `asked`.
pub fn slice_count(wanted: usize, threads: usize, asked: Option<usize>) -> usize {
    if let Some(s) = asked {
        return s.clamp(1, (wanted / 8).max(1));
    }
    if wanted < SLICING_MIN_PAIRS {
        return 1;
    }
    wanted.div_ceil(PAIRS_PER_SLICE).max(threads.min(wanted / PAIRS_PER_SLICE)).max(1)
}

/// The columns of the widest Krylov basis a sparse solve of `o.k` pairs of `n` unknowns allocates where its plan
/// holds, with the block vectors beside it (two blocks). `deflated` of the pairs are known zero modes, put in exactly
/// and not iterated for ([`widest_basis_for_zero_modes`] where their number is not known yet). Each slice's own
/// basis when the options let the solve be sliced: the fewest slices `o` allows, each with an even share of the pairs,
/// the top slice with the guard pairs above the k-th and its extra columns. Else the one run's. `None` where the
/// problem is too small for the Krylov method.
///
/// At run time a slice sizes its basis for the pairs its window holds, which can be a cluster more than its share,
/// and a plan that does not fit the spectrum (or an operator without a dimension for Weyl's law) is solved in one
/// run. Every basis is checked against [`EigenOptions::max_values`] before it is allocated, so the limit holds
/// where this prediction is short.
pub fn widest_basis(n: usize, deflated: usize, o: &EigenOptions) -> Option<usize> {
    let o = EigenOptions { k: o.k.saturating_sub(deflated), ..o.clone() };
    let sliceable = o.sigma.is_none() && !(o.subspace.is_some() && o.slices.is_none());
    let s = if sliceable { slice_count(o.k, 1, o.slices) } else { 1 };
    if s < 2 {
        let (b, _, m) = lanczos::plan(n, deflated, &o)?;
        return Some(m + 2 * b);
    }
    let guard = (o.block.unwrap_or(8) / 2).max(2);
    let pairs = o.k.div_ceil(s) + guard;
    let (b, _, m) = lanczos::plan(n, deflated, &EigenOptions { k: pairs, subspace: None, ..o })?;
    Some((m + TOP_EXTRA.min(pairs)).min(n) + 2 * b)
}

/// [`widest_basis`] where the number of known zero modes is not known yet but is at most `most` (a request at
/// submission: a Neumann operator's null space holds one constant per connected component; `o.k` where nothing
/// bounds it): the widest basis of a solve of k − `most` to k pairs, which bounds the solve for every such number (the
/// pairs beyond the zero modes decide whether and how the solve is sliced; n is taken whole). O(`most`) plans.
pub fn widest_basis_for_zero_modes(n: usize, o: &EigenOptions, most: usize) -> Option<usize> {
    let k = o.k;
    (k.saturating_sub(most).max(1)..=k)
        .filter_map(|wanted| widest_basis(n, 0, &EigenOptions { k: wanted, ..o.clone() }))
        .max()
}

/// The widest Krylov basis (columns, with the block vectors) a solve of `o.k` pairs of `n` unknowns may allocate,
/// predicted before the operator is built: for any number of known zero modes up to `most`
/// ([`widest_basis_for_zero_modes`]), and as one run where the operator has no dimension for Weyl's law to plan slices
/// by (`weyl` false). `None` where the solve is dense for every such number of zero modes (it holds no basis) or too
/// small for the Krylov method.
pub fn predicted_basis(n: usize, o: &EigenOptions, most: usize, weyl: bool) -> Option<usize> {
    let (k, most) = (o.k, most.min(o.k).min(n));
    // Dense only where it is for any number of zero modes (fewer pairs beyond them can tip it to sparse).
    let dense = |z: usize| super::use_dense(o.method, n, n - z, k - z);
    if dense(0) && dense(most) {
        return None;
    }
    let o = EigenOptions { slices: if weyl { o.slices } else { Some(1) }, ..o.clone() };
    widest_basis_for_zero_modes(n, &o, most)
}

/// The slices' windows by Weyl's law (each expected to hold the same number of pairs), or `None` where slicing does
/// not apply (one slice, a fixed shift, an operator without a dimension for Weyl's law).
pub(crate) fn plan(pair: &SparsePair, deflated: usize, wanted: usize, o: &EigenOptions) -> Option<Vec<Window>> {
    // A fixed shift, or a subspace chosen for one run, asks for one run.
    if o.sigma.is_some() || (o.subspace.is_some() && o.slices.is_none()) {
        return None;
    }
    let d = pair.dimension?;
    let measure: f64 = pair.mass.iter().sum();
    if !(measure > 0.0) || !measure.is_finite() {
        return None;
    }
    let threads = o.thread_count();
    let s = slice_count(wanted, threads, o.slices);
    if s < 2 {
        return None;
    }
    let edge = |j: usize| weyl_law::weyl_eigenvalue(d, measure, (deflated + j * wanted / s) as f64);
    let guard = (o.block.unwrap_or(8) / 2).max(2);
    let mut out = Vec::with_capacity(s);
    for j in 0..s {
        let window = if j == 0 {
            let hi = edge(1);
            Window {
                lo: f64::NEG_INFINITY,
                hi,
                sigma: lanczos::WEYL_FRACTION * hi,
                total: None,
                count: None,
                below_lo: 0,
            }
        } else if j + 1 < s {
            let (lo, hi) = (edge(j), edge(j + 1));
            Window { lo, hi, sigma: 0.5 * (lo + hi), total: None, count: None, below_lo: 0 }
        } else {
            let (lo, top) = (edge(j), edge(s));
            Window {
                lo,
                hi: f64::INFINITY,
                sigma: 0.5 * (lo + top),
                total: Some(deflated + wanted + guard),
                count: None,
                below_lo: 0,
            }
        };
        if !(window.sigma > 0.0 && window.sigma.is_finite()) {
            return None;
        }
        out.push(window);
    }
    Some(out)
}

/// What [`solve`] did: slicing does not apply (one run is the plan), the slices' pairs, or the plan given up (the
/// caller then solves in one run and reports why).
pub(crate) enum Sliced {
    NotPlanned,
    Solved(Box<Spectrum>),
    GivenUp(String),
}

/// The `o.k` smallest pairs of the deflated problem by slicing, with the guard pairs above them (see [`Sliced`]).
pub(crate) fn solve(
    pair: &SparsePair,
    o: &EigenOptions,
    sym: &factor::Symbolic,
    control: Control<'_>,
    deflation: &null_space::Deflation<'_>,
    deflated_values: &[f64],
    head: Option<&Spectrum>,
) -> Result<Sliced, EigenError> {
    let t0 = Instant::now();
    let Some(slices) = plan(pair, deflation.len(), o.k, o) else { return Ok(Sliced::NotPlanned) };
    let threads = o.thread_count();
    control.phase("factorization", 0, o.k)?;
    // Sylvester's inertia at every edge between two slices: each window's count exactly, so its subspace is
    // sized for what it holds (Weyl's even split meets clustered spectra unevenly: a sphere's window can hold a
    // 57-fold cluster more than planned). An edge moves within ±1 % of its window where its LDLᵀ factor is not
    // backward stable.
    let count_edge = |j: usize| -> Result<(f64, usize), EigenError> {
        let (w0, w1) = (slices[j - 1], slices[j]);
        let e = w1.lo;
        let below = if w0.lo.is_finite() { w0.lo } else { 0.0 };
        let above = if w1.hi.is_finite() { w1.hi } else { w1.sigma };
        let reach = 0.01 * (e - below).min(above - e);
        // Each edge on one thread; the runs of edges below are counted side by side.
        completeness::inertia_in_gap(sym, pair, (e - reach, e + reach), &control, faer::Par::Seq)
    };
    // One run of consecutive edges per thread given (not one task per edge, which idle threads of a shared pool
    // would take, each holding a factor).
    let inner: Vec<usize> = (1..slices.len()).collect();
    let runs: Vec<&[usize]> = inner.chunks(inner.len().div_ceil(threads.max(1)).max(1)).collect();
    let edges: Vec<Result<(f64, usize), EigenError>> = if runs.len() > 1 {
        let counted: Vec<Vec<_>> =
            runs.into_par_iter().with_max_len(1).map(|run| run.iter().map(|&j| count_edge(j)).collect()).collect();
        counted.into_iter().flatten().collect()
    } else {
        inner.iter().map(|&j| count_edge(j)).collect()
    };
    let edges: Vec<(f64, usize)> = match edges.into_iter().collect() {
        Ok(e) => e,
        Err(EigenError::Canceled) => return Err(EigenError::Canceled),
        Err(e) => return Ok(Sliced::GivenUp(format!("the inertia count at a slice edge failed: {e}"))),
    };
    let deflated = deflation.len();
    let total = slices.last().and_then(|s| s.total).unwrap_or(deflated + o.k);
    // Windows with their exact counts; slices past the one that reaches `total` pairs are dropped.
    let mut planned: Vec<(Window, usize)> = Vec::with_capacity(slices.len());
    let mut below = deflated;
    for (j, w) in slices.iter().enumerate() {
        let mut w = *w;
        if j > 0 {
            w.lo = edges[j - 1].0;
        }
        w.below_lo = below;
        let last = j + 1 == slices.len() || edges[j].1 >= total;
        if last {
            w.hi = f64::INFINITY;
            w.total = Some(total);
            if j + 1 < slices.len() {
                // The `total`-th eigenvalue lies below this window's planned top edge: σ halfway to where the count
                // between the edges (linear in λ) reaches it, not at the planned midpoint, which may lie above it.
                let (top, at_top) = edges[j];
                let share = (total - below) as f64 / (at_top - below).max(1) as f64;
                let lam_total = w.lo + share.clamp(0.0, 1.0) * (top - w.lo);
                w.sigma = 0.5 * (w.lo + lam_total);
            }
            if !(w.sigma > w.lo) {
                w.sigma = w.lo + 0.5 * (slices[j].sigma - slices[j].lo).abs().max(w.lo.abs() * 1e-3);
            }
            planned.push((w, total.saturating_sub(below).max(1)));
            break;
        }
        w.hi = edges[j].0;
        w.sigma = if w.lo.is_finite() { 0.5 * (w.lo + w.hi) } else { lanczos::WEYL_FRACTION * w.hi };
        let count = edges[j].1.saturating_sub(below);
        w.count = Some(count);
        below = edges[j].1;
        planned.push((w, count.max(1)));
    }
    let slices = planned;
    if slices.len() < 2 {
        return Ok(Sliced::GivenUp(format!(
            "the counts at the slice edges put all {total} pairs in the first slice (Weyl's law misjudged this spectrum)"
        )));
    }
    // Threads left to each slice's factorization and solves once every slice has one.
    let inner = (threads / slices.len()).max(1);
    let converged: Vec<AtomicUsize> = slices.iter().map(|_| AtomicUsize::new(0)).collect();
    let k = o.k;
    // A slice's run: `pairs` sizes its subspace. The top slice ends at the k-th eigenvalue, not at an edge placed in
    // a gap, and must see whole the cluster that may straddle it: its subspace gets as many more columns as its
    // pairs, at most [`TOP_EXTRA`].
    let options_of = |i: usize| -> EigenOptions {
        let (window, pairs) = slices[i];
        let sub = window.total.and_then(|_| {
            let own = EigenOptions { k: pairs, subspace: None, ..o.clone() };
            let (_, _, msize) = lanczos::plan(pair.n(), deflation.len(), &own)?;
            Some((msize + TOP_EXTRA.min(pairs)).min(pair.n()))
        });
        EigenOptions { k: pairs, threads: inner, subspace: sub, ..o.clone() }
    };
    // (pairs, seconds, pool thread, who solved it elsewhere)
    type Outcome = (Result<Option<Spectrum>, EigenError>, f64, Option<usize>, Option<String>);
    let progress_of = |i: usize, done: usize| {
        converged[i].store(done, Ordering::Relaxed);
        let sum: usize = converged.iter().map(|c| c.load(Ordering::Relaxed)).sum();
        control.report("iterating", sum.min(k), k);
    };
    let run_slice = |i: usize| -> Outcome {
        let t = Instant::now();
        let report = |p: Progress| {
            if p.phase == "iterating" {
                progress_of(i, p.converged);
            }
        };
        let slice_control = Control { progress: Some(&report), stop: control.stop, lender: None, farm: None };
        let run =
            lanczos::Run { deflation, deflated_values, interior_shift: true, window: Some(slices[i].0), head: None };
        let r = lanczos::eigs_block_lanczos(pair, &options_of(i), Some(sym), slice_control, &run);
        (r, t.elapsed().as_secs_f64(), rayon::current_thread_index(), None)
    };
    // The solve's own threads, and the idle threads its host lends for the slices beyond them (the service's idle
    // workers; see [`Lender`]).
    let own = threads.min(slices.len());
    let lender = control.lender.filter(|_| slices.len() > own);
    let lent = lender.map_or(0, |l| l.borrow(slices.len() - own));
    // One queue, the top slice first: it holds the k-th eigenvalue, often inside a cluster it must see whole, and
    // takes the most block steps (164k sphere, k = 1000, 8 slices: 99 steps and 9.7 s against 44 to 65 and 4.9 to
    // 8.3 s). Each thread takes the next slice when it is free, so the longest does not start last (rayon's halves
    // gave one thread slices 0 to 3 and the other 4 to 7: 26.4 against 30.1 s).
    let order: Vec<usize> = (0..slices.len()).rev().collect();
    // The slices no thread starts at once, offered to the host's other machines ([`Farm`]).
    let farm = control.farm.filter(|_| slices.len() > own + lent);
    let offers: Vec<Option<SliceTask>> = match farm {
        Some(f) => {
            let pencil = pencil_digest(pair);
            let mut offers: Vec<Option<SliceTask>> = vec![None; slices.len()];
            for &i in &order[own + lent..] {
                let task = SliceTask {
                    index: i,
                    window: slices[i].0,
                    options: EigenOptions { threads: 0, ..options_of(i) },
                    pencil: pencil.clone(),
                };
                if f.offer(&task) {
                    offers[i] = Some(task);
                }
            }
            offers
        }
        None => vec![],
    };
    let offered = |i: usize| offers.get(i).and_then(Option::as_ref);
    let results: Vec<Outcome> = if own + lent > 1 || lender.is_some() || farm.is_some() {
        // A lent thread also leaves when its host wants it back, and is given back however it leaves (a panic
        // included).
        let next = AtomicUsize::new(0);
        let failed = std::sync::atomic::AtomicBool::new(false);
        let done: Vec<std::sync::Mutex<Option<Outcome>>> = slices.iter().map(|_| std::sync::Mutex::new(None)).collect();
        // Offered slices another machine started: collected by the solve's own threads once none of theirs is left.
        let elsewhere = std::sync::Mutex::new(Vec::<usize>::new());
        let (order, next, failed, slots, run_slice, elsewhere) =
            (&order, &next, &failed, &done, &run_slice, &elsewhere);
        let keep = |i: usize, r: Outcome| {
            if !matches!(r.0, Ok(Some(_))) {
                failed.store(true, Ordering::Relaxed);
            }
            *slots[i].lock().unwrap_or_else(|e| e.into_inner()) = Some(r);
            !failed.load(Ordering::Relaxed)
        };
        // The offered slices another machine started, collected (or solved here when they come back unsolved).
        let collect_rest = || {
            let Some(f) = farm else { return };
            while !failed.load(Ordering::Relaxed) {
                let Some(i) = elsewhere.lock().unwrap_or_else(|e| e.into_inner()).pop() else { break };
                let Some(task) = offered(i) else { continue };
                let r = match f.collect(task, &control) {
                    // Pairs of this pencil's size, one vector per value (anything else is solved here).
                    Ok(Some(solved))
                        if solved.spectrum.vectors.nrows() == pair.n()
                            && solved.spectrum.vectors.ncols() == solved.spectrum.values.len() =>
                    {
                        progress_of(i, solved.spectrum.values.len());
                        (Ok(Some(solved.spectrum)), solved.seconds, None, Some(solved.by))
                    }
                    // Taken back, or failed or lost where it ran: solved here.
                    Ok(_) => run_slice(i),
                    Err(e) => (Err(e), 0.0, None, None),
                };
                if !keep(i, r) {
                    return;
                }
            }
        };
        let collect_rest = &collect_rest;
        // A thread's loop over the slices waiting, `after` run after each of its slices.
        let looper = |loan: Option<&Returned<'_>>, after: &dyn Fn()| {
            // After a failure the rest is not started (the plan falls back to one run, or the stop ends it).
            while !failed.load(Ordering::Relaxed) {
                let Some(&i) = order.get(next.fetch_add(1, Ordering::Relaxed)) else { break };
                if let (Some(f), Some(task)) = (farm, offered(i)) {
                    if !f.take_back(task) {
                        elsewhere.lock().unwrap_or_else(|e| e.into_inner()).push(i);
                        continue;
                    }
                }
                if !keep(i, run_slice(i)) {
                    return;
                }
                after();
                if loan.is_some_and(|l| l.0.wanted_back()) {
                    return;
                }
            }
            // A lent thread goes back to its host rather than wait for another machine.
            if loan.is_none() {
                collect_rest();
            }
        };
        let tasks = Tasks::default();
        // Loans spawned and not yet ended: the caller asks for more after each of its slices while more slices wait
        // than threads take them (a worker the host could not lend at first, or that came free since, joins then).
        let out = AtomicUsize::new(lent);
        let (looper, tasks, out) = (&looper, &tasks, &out);
        rayon::scope(|scope| {
            let spawn = |lent: bool| {
                let loan = lender.filter(|_| lent).map(|l| Returned(l, out));
                scope.spawn(move |_| {
                    let started = tasks.start();
                    // Declared after `started`, so dropped before it (a panic included): the loan is given back
                    // before the caller may leave its wait.
                    let loan = loan;
                    if started.is_some() {
                        looper(loan.as_ref(), &|| {});
                    }
                });
            };
            // The caller's own loop runs here; the other threads (its own beyond the first, then the lent ones) are
            // tasks of the pool, taken by its idle threads.
            for t in 1..own + lent {
                spawn(t >= own);
            }
            looper(None, &|| {
                if let Some(l) = lender {
                    let left = order.len().saturating_sub(next.load(Ordering::Relaxed));
                    let waiting = left.saturating_sub(own + out.load(Ordering::SeqCst));
                    let more = if waiting > 0 { l.borrow(waiting) } else { 0 };
                    out.fetch_add(more, Ordering::SeqCst);
                    for _ in 0..more {
                        spawn(true);
                    }
                }
            });
            // The caller waits for the tasks that started, blocked: a thread waiting inside the pool runs whatever
            // work the pool has, another job's included, and this solve would end only when that job does. The
            // tasks no thread has started return at once.
            tasks.close_and_wait();
            // A lent thread may have found an offered slice started elsewhere after the caller's own collecting ended.
            collect_rest();
        });
        // Offered slices the solve no longer waits for (after a failure) are released.
        if let Some(f) = farm {
            for (i, slot) in done.iter().enumerate() {
                if let (None, Some(task)) = (&*slot.lock().unwrap_or_else(|e| e.into_inner()), offered(i)) {
                    f.release(task);
                }
            }
        }
        // Slices never started (after a failure) are left out: the failure is in the list, and ends the solve
        // below as in the sequential path.
        done.into_iter().filter_map(|m| m.into_inner().unwrap_or_else(|e| e.into_inner())).collect()
    } else {
        let mut out = Vec::with_capacity(slices.len());
        for i in 0..slices.len() {
            let r = run_slice(i);
            let failed = r.0.is_err();
            out.push(r);
            if failed {
                break;
            }
        }
        out
    };
    let mut parts = Vec::with_capacity(slices.len());
    let mut seconds = Vec::with_capacity(slices.len());
    let which = |i: usize| format!("slice {} of {} ({} pairs)", i + 1, slices.len(), slices[i].1);
    for (i, (r, s, worker, by)) in results.into_iter().enumerate() {
        match r {
            Ok(Some(spectrum)) => parts.push(spectrum),
            Err(EigenError::Canceled) => return Err(EigenError::Canceled),
            // A slice's basis over the limit: one run instead where its basis fits (a top slice that a misjudged
            // plan gave nearly every pair, with its extra columns, can be wider than one run), else the slice's error.
            Err(e @ EigenError::TooLarge { .. }) => {
                let one_run = lanczos::plan(pair.n(), deflation.len(), o).map(|(_, _, m)| pair.n().saturating_mul(m));
                return if one_run.is_some_and(|v| v <= o.max_values) {
                    Ok(Sliced::GivenUp(format!("{}: {e}", which(i))))
                } else {
                    Err(e)
                };
            }
            // The plan did not fit this problem (or too few unknowns): one run instead.
            Ok(None) => return Ok(Sliced::GivenUp(format!("{}: too few unknowns for its Krylov basis", which(i)))),
            Err(e) => return Ok(Sliced::GivenUp(format!("{}: {e}", which(i)))),
        }
        seconds.push((s, worker, by));
    }
    if parts.len() < slices.len() {
        return Ok(Sliced::GivenUp(format!("{} of {} slices were solved", parts.len(), slices.len())));
    }
    control.check()?;
    let reports: Vec<SliceReport> = parts
        .iter()
        .zip(&slices)
        .zip(&seconds)
        .map(|((p, (w, _)), (s, worker, by))| SliceReport {
            lo: w.lo.is_finite().then_some(w.lo),
            hi: w.hi.is_finite().then_some(w.hi),
            // The shift the slice was solved at (another than planned where the planned one's factor was not
            // backward stable).
            sigma: p.stats.sigma,
            below_sigma: p.stats.below_sigma,
            pairs: p.values.len(),
            block_steps: p.stats.block_steps,
            solves: p.stats.solves,
            restarts: p.stats.restarts,
            seconds: *s,
            worker: *worker,
            solved_by: by.clone(),
        })
        .collect();
    let mut s = stitch(pair, parts, head, &slices, &control, threads)?;
    if s.values.len() < k + head.map_or(0, |h| h.values.len()) {
        return Ok(Sliced::GivenUp(format!(
            "the slices held {} pairs together, fewer than the {k} asked",
            s.values.len()
        )));
    }
    s.stats.slices = reports;
    s.stats.timings.iteration_s = t0.elapsed().as_secs_f64();
    Ok(Sliced::Solved(Box::new(s)))
}

/// The slices' pairs in one ascending spectrum after `head`'s (the known zero modes), with each edge's neighbourhood
/// Rayleigh–Ritz'd (see the module docs). Statistics add up the slices' work; σ and the inertia are the lowest
/// slice's.
fn stitch(
    pair: &SparsePair,
    parts: Vec<Spectrum>,
    head: Option<&Spectrum>,
    slices: &[(Window, usize)],
    control: &Control<'_>,
    threads: usize,
) -> Result<Spectrum, EigenError> {
    let n = pair.n();
    let total: usize = parts.iter().map(|p| p.values.len()).sum::<usize>() + head.map_or(0, |h| h.values.len());
    // Filled slice by slice, each slice's vectors dropped once copied: the peak holds one copy of the
    // eigenvectors and one slice's.
    // The copies run on the slices' threads.
    let mut vectors = super::Columns::new(n, total);
    let mut values = Vec::with_capacity(total);
    let mut stats = Stats { method: "block-lanczos", factorization: "ldlt", ..Default::default() };
    if let Some(h) = head {
        vectors.append(h.values.len(), control, threads, |j, col| {
            for (x, y) in col.iter_mut().zip(h.vectors.col(j).iter()) {
                *x = *y;
            }
        })?;
        values.extend_from_slice(&h.values);
    }
    for (i, p) in parts.into_iter().enumerate() {
        control.check()?;
        let from = p.vectors.as_ref();
        vectors.append(p.values.len(), control, threads, |j, col| {
            for (x, y) in col.iter_mut().zip(from.col(j).iter()) {
                *x = *y;
            }
        })?;
        values.extend_from_slice(&p.values);
        let ps = &p.stats;
        if i == 0 {
            stats.sigma = ps.sigma;
            stats.below_sigma = ps.below_sigma;
            stats.factor_nnz = ps.factor_nnz;
            stats.block = ps.block;
        }
        stats.subspace = stats.subspace.max(ps.subspace);
        stats.restarts += ps.restarts;
        stats.block_steps += ps.block_steps;
        stats.solves += ps.solves;
        let (t, pt) = (&mut stats.timings, &ps.timings);
        t.numeric_s += pt.numeric_s;
        t.solve_s += pt.solve_s;
        t.orthogonalize_s += pt.orthogonalize_s;
        t.rayleigh_ritz_s += pt.rayleigh_ritz_s;
        t.restart_s += pt.restart_s;
    }
    let mut s = Spectrum { values, vectors: vectors.done(), residuals: vec![], stats };
    // Each interior edge: the slices' windows meet there.
    for j in 1..slices.len() {
        control.check()?;
        let edge = slices[j].0.lo;
        let width = |w: &Window| -> f64 {
            let lo = if w.lo.is_finite() { w.lo } else { 0.0 };
            let hi = if w.hi.is_finite() { w.hi } else { s.values.last().copied().unwrap_or(lo) };
            (hi - lo).max(0.0)
        };
        let reach = EDGE_FRACTION * width(&slices[j - 1].0).min(width(&slices[j].0));
        let a = s.values.partition_point(|&v| v < edge - reach);
        let b = s.values.partition_point(|&v| v < edge + reach);
        if b > a {
            rayleigh_ritz(pair, &mut s, (a, b), threads, control)?;
        }
    }
    Ok(s)
}

/// Replaces the pairs a..b of `s` by the Ritz pairs of their span (M-orthonormal; a direction the others already
/// hold, as a pair found by both slices, is dropped), on `threads` threads.
///
/// The projected matrices Xᵀ M X and Xᵀ L X are taken eight columns at a time: each group is copied row-major once,
/// multiplied by M and L, and met by the whole of X in the basis' Gram kernel; the Ritz vectors are formed in place
/// by rows. No n × p matrix is allocated (before: X copied, M X, L X and the Ritz vectors, four n × p matrices per
/// edge, 1.4 s for the 7 edges at 164k vertices, k = 1000, two threads).
pub(crate) fn rayleigh_ritz(
    pair: &SparsePair,
    s: &mut Spectrum,
    (a, b): (usize, usize),
    threads: usize,
    control: &Control<'_>,
) -> Result<(), EigenError> {
    const W: usize = 8;
    let (n, p) = (s.vectors.nrows(), b - a);
    let (mut g, mut l) = (Mat::<f64>::zeros(p, p), Mat::<f64>::zeros(p, p));
    {
        let x = s.vectors.as_ref().subcols(a, p);
        let (mut xr, mut mr, mut lr) = (vec![0.0; n * W], vec![0.0; n * W], vec![0.0; n * W]);
        let mut scratch = Vec::new();
        for c0 in (0..p).step_by(W) {
            control.check()?;
            let w = W.min(p - c0);
            for c in 0..w {
                for (i, &v) in x.col(c0 + c).iter().enumerate() {
                    xr[i * w + c] = v;
                }
            }
            let xb = MatRef::from_row_major_slice(&xr[..n * w], n, w);
            for (values, out, projected) in [(&pair.mass, &mut mr, &mut g), (&pair.stiffness, &mut lr, &mut l)] {
                let y = faer::MatMut::from_row_major_slice_mut(&mut out[..n * w], n, w);
                crate::operators::sparse::spmm(&pair.pattern, values, xb, y, &mut scratch, threads);
                let part = super::basis_products::gram_par(x, &out[..n * w], w, threads);
                projected.as_mut().subcols_mut(c0, w).copy_from(part.as_ref());
            }
        }
    }
    let g = Mat::from_fn(p, p, |i, j| 0.5 * (g[(i, j)] + g[(j, i)]));
    // The small eigenproblems and products on one thread (faer's `self_adjoint_eigen` and `*` would take the whole
    // pool).
    let Ok((gs, gu)) = super::dense::symmetric_eigen(g.as_ref(), faer::Par::Seq) else { return Ok(()) };
    let top = gs.iter().copied().fold(0.0, f64::max);
    let kept: Vec<usize> = (0..p).filter(|&i| gs[i] > 1e-10 * top).collect();
    let whiten = Mat::from_fn(p, kept.len(), |i, j| gu[(i, kept[j])] / gs[kept[j]].sqrt());
    let seq = |a: faer::MatRef<'_, f64>, b: faer::MatRef<'_, f64>| {
        let mut c = Mat::<f64>::zeros(a.nrows(), b.ncols());
        faer::linalg::matmul::matmul(c.as_mut(), faer::Accum::Replace, a, b, 1.0, faer::Par::Seq);
        c
    };
    let lw = seq(seq(whiten.transpose(), l.as_ref()).as_ref(), whiten.as_ref());
    let r = kept.len();
    let lw = Mat::from_fn(r, r, |i, j| 0.5 * (lw[(i, j)] + lw[(j, i)]));
    let Ok((ls, lu)) = super::dense::symmetric_eigen(lw.as_ref(), faer::Par::Seq) else { return Ok(()) };
    // X ← X (whiten U₂): the r new vectors in columns a..a + r.
    let t = seq(whiten.as_ref(), lu.as_ref());
    let par = if threads > 1 { faer::Par::rayon(threads) } else { faer::Par::Seq };
    lanczos::ritz_in_place(&mut s.vectors, a, p, t.as_ref(), par, control)?;
    s.values[a..a + r].copy_from_slice(&ls[..r]);
    if r < p {
        // A direction held twice: the columns after the edge move down over the p − r dropped ones.
        let total = s.values.len() - (p - r);
        for j in a + r..total {
            super::copy_column(&mut s.vectors, j + (p - r), j);
        }
        s.values.drain(a + r..b);
        s.vectors.truncate(n, total);
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::{generate, Shape};
    use crate::operators;

    /// An edge's step on pairs of which one is held twice (as two slices can both find a pair at their edge) drops
    /// the copy: the spectrum is the solve's again, every pair with a small residual, and the columns after the
    /// edge moved down unchanged. On one thread and on two: at 10,242 vertices the Gram products split by rows and
    /// the Ritz vectors are formed in five chunks of rows, taken by both threads.
    #[test]
    fn an_edge_step_drops_a_direction_held_twice() {
        let shape = Shape::TriangleMesh(generate::icosphere(5));
        let pair = operators::build(&shape, &Default::default()).unwrap().pair;
        let o = EigenOptions { k: 30, method: Method::Sparse, threads: 1, slices: Some(1), ..Default::default() };
        let solved = eigs(&pair, &o, None, Control::default()).unwrap();
        let n = pair.n();
        // Pair 10 again after pair 12: 31 pairs, the edge's step over 8..16.
        let order: Vec<usize> = (0..=12).chain([10]).chain(13..30).collect();
        let doubled = Spectrum {
            values: order.iter().map(|&j| solved.values[j]).collect(),
            vectors: Mat::from_fn(n, order.len(), |i, j| solved.vectors[(i, order[j])]),
            ..solved.clone()
        };
        for threads in [1, 2] {
            let mut s = doubled.clone();
            let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
            pool.install(|| rayleigh_ritz(&pair, &mut s, (8, 16), threads, &Control::default())).unwrap();
            assert_eq!(s.values.len(), 30, "{threads} threads: the copy dropped");
            for j in 15..30 {
                assert_eq!(s.vectors.col(j), solved.vectors.col(j), "{threads} threads: column {j} moved down");
            }
            finish(&pair, &mut s, 1, threads, usize::MAX, Control::default()).unwrap();
            for (j, (x, y)) in s.values.iter().zip(&solved.values).enumerate() {
                assert!((x - y).abs() <= 1e-10 * y.abs().max(1.0), "{threads} threads: λ_{j} {x} against {y}");
            }
            let worst = s.residuals.iter().copied().fold(0.0f64, f64::max);
            assert!(worst < 1e-8, "{threads} threads: largest residual {worst:e}");
        }
    }
}
