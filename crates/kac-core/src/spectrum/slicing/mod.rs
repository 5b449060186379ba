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
//!   holds about twice its own pairs, not twice k. So slicing pays at a thousand pairs, in time and memory, and one
//!   run is faster at a few hundred, on one thread and on two (BENCHMARKS.md has the figures). The automatic plan
//!   slices from [`SLICING_MIN_PAIRS`] pairs on.
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

mod edges;
mod schedule;

pub(crate) use schedule::{solve, Sliced};

use super::lanczos::{self, Window};
use super::*;
use rayon::prelude::*;
use serde::Deserialize;

/// The fewest pairs (beyond the known zero modes) the automatic plan slices: below, one run is faster on one thread
/// and on two (a slice's window has unwanted eigenvalues on both sides, so its pairs take more block steps than the
/// same pairs at the bottom of one run, which the smaller Gram–Schmidt work of slices repays only at larger k;
/// BENCHMARKS.md).
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

/// Columns added at most to the top slice's default subspace (as many as its pairs below that). A cluster across
/// the k-th eigenvalue (63-fold on the 164k-vertex sphere at k = 1000) makes the top slice restart often in its
/// default subspace; 100 more columns remove most of those restarts, and more columns gain nothing. The peak memory
/// does not grow: the top slice runs first, before the other slices' eigenvectors are held.
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

#[cfg(test)]
mod tests {
    use super::edges::rayleigh_ritz;
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
