//! Generalized symmetric eigensolvers for L φ = λ M φ: the k smallest eigenpairs (or all in a band).
//!
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
//!
//! Output: eigenvalues ascending (the Rayleigh quotients φᵀLφ / φᵀMφ of the returned vectors), M-orthonormal
//! eigenvectors with the largest-magnitude entry positive, and per pair the relative residual ‖Lφ − λMφ‖₂ / (max(|λ|, |σ|) · ‖Mφ‖₂). With [`EigenOptions::verify`], Sylvester's
//! inertia of L − τM confirms that no eigenvalue below the found ones was missed ([`Completeness`]).

pub mod basis_products;
pub mod dense;
pub mod factor;
pub mod lanczos;

use crate::operators::sparse::SparsePair;
use faer::Mat;
use serde::{Deserialize, Serialize};
use std::sync::atomic::AtomicBool;

/// Which solver.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum Method {
    /// Dense for n ≤ 1500 or k > n/3 (n ≤ 8000), sparse otherwise.
    #[default]
    Auto,
    Dense,
    Sparse,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EigenOptions {
    /// Number of eigenpairs (1 ≤ k ≤ n − 1 for the sparse path, ≤ n for the dense one).
    pub k: usize,
    /// Relative residual tolerance of the shift-inverted problem (default 1e-10).
    pub tol: f64,
    /// A fixed shift (Cholesky of L − σM below the spectrum, σ < 0; LDLᵀ otherwise); default: chosen by
    /// the rules of [`lanczos::weyl_shift`] and [`lanczos::default_sigma`] (inside the spectrum by Weyl's law where the operator has a dimension).
    pub sigma: Option<f64>,
    /// Block size b (default 8).
    pub block: Option<usize>,
    /// Subspace size (default: max(2w, w + 6b, min(3w, w + 100)) columns for w = k + guard wanted pairs, at most n).
    pub subspace: Option<usize>,
    /// Limit on block expansions.
    pub max_steps: usize,
    pub seed: u64,
    /// Threads for the factorization and solves (0: all of rayon's).
    pub threads: usize,
    pub method: Method,
    /// Check completeness after a sparse solve by Sylvester's inertia (see [`Completeness`]): one more numeric
    /// factorization (LDLᵀ of L − τM) on the same symbolic analysis.
    pub verify: bool,
}

impl Default for EigenOptions {
    fn default() -> Self {
        EigenOptions {
            k: 10,
            tol: 1e-10,
            sigma: None,
            block: None,
            subspace: None,
            max_steps: 20_000,
            seed: 0x6b61_6321,
            threads: 0,
            method: Method::Auto,
            verify: false,
        }
    }
}

/// Progress of a solve, for callbacks.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct Progress {
    pub phase: &'static str,
    pub converged: usize,
    pub wanted: usize,
}

/// Hooks for a long solve: progress reports and a stop flag checked between block steps.
#[derive(Default, Clone, Copy)]
pub struct Control<'a> {
    pub progress: Option<&'a (dyn Fn(Progress) + Sync)>,
    pub stop: Option<&'a AtomicBool>,
}

impl Control<'_> {
    pub(crate) fn report(&self, phase: &'static str, converged: usize, wanted: usize) {
        if let Some(p) = self.progress {
            p(Progress { phase, converged, wanted });
        }
    }
    pub(crate) fn stopped(&self) -> bool {
        self.stop.is_some_and(|s| s.load(std::sync::atomic::Ordering::Relaxed))
    }
}

/// Seconds spent in each phase.
#[derive(Debug, Clone, Default, Serialize)]
pub struct Timings {
    pub symbolic_s: f64,
    pub numeric_s: f64,
    pub iteration_s: f64,
    /// Inside the iteration: block solves with the factor.
    pub solve_s: f64,
    /// Inside the iteration: the recurrence, full M-reorthogonalization and M-normalization of new blocks.
    pub orthogonalize_s: f64,
    /// Inside the iteration: the projected eigenproblems and convergence tests.
    pub rayleigh_ritz_s: f64,
    /// Inside the iteration: Ritz vectors at thick restarts and at the end.
    pub restart_s: f64,
    pub total_s: f64,
}

#[derive(Debug, Clone, Serialize)]
pub struct Stats {
    pub method: &'static str,
    pub sigma: f64,
    pub block: usize,
    pub subspace: usize,
    pub restarts: usize,
    pub block_steps: usize,
    /// Right-hand sides solved (columns).
    pub solves: usize,
    pub factor_nnz: usize,
    /// `cholesky` (σ below the spectrum) or `ldlt` (σ inside it; see [`lanczos::weyl_shift`]).
    pub factorization: &'static str,
    /// With σ inside the spectrum: the number of eigenvalues below σ (Sylvester's inertia of the LDLᵀ factor), all
    /// of which the solver returned.
    pub below_sigma: Option<usize>,
    pub symbolic_reused: bool,
    pub timings: Timings,
    /// The inertia check, when asked for and possible.
    pub completeness: Option<Completeness>,
}

/// No eigenvalue was missed below a shift τ: the LDLᵀ inertia of L − τM counts the eigenvalues below τ
/// (Sylvester), and the solver found exactly that many. τ is the midpoint of the largest-index gap between found
/// eigenvalues wider than 10⁻⁶ relative, so a cut through a multiplicity cluster (the sphere's 2l + 1) is checked
/// below the cluster and nothing depends on how the cluster itself was split.
#[derive(Debug, Clone, Serialize)]
pub struct Completeness {
    pub shift: f64,
    /// Eigenvalues of the problem below `shift` (inertia).
    pub below_shift: usize,
    /// Eigenvalues the solver returned below `shift`.
    pub found_below_shift: usize,
    pub complete: bool,
    pub seconds: f64,
}

/// Eigenpairs with their residuals.
#[derive(Debug, Clone)]
pub struct Spectrum {
    pub values: Vec<f64>,
    /// n × k, M-orthonormal columns.
    pub vectors: Mat<f64>,
    pub residuals: Vec<f64>,
    pub stats: Stats,
}

#[derive(Debug, Clone, PartialEq, thiserror::Error, Serialize)]
#[serde(tag = "error", rename_all = "snake_case")]
pub enum EigenError {
    #[error("k = {k} is out of range for {n} unknowns (1 ≤ k ≤ {max})")]
    InvalidK { k: usize, n: usize, max: usize },
    #[error("the shifted matrix L − σM could not be factored: {message}")]
    Factorization { message: String },
    #[error("stopped on request")]
    Canceled,
    #[error("did not converge: {converged} of {wanted} pairs after {steps} block steps")]
    NoConvergence { converged: usize, wanted: usize, steps: usize },
    #[error("invalid option {name}: {message}")]
    InvalidOption { name: &'static str, message: String },
}

impl EigenError {
    pub fn code(&self) -> &'static str {
        match self {
            EigenError::InvalidK { .. } => "invalid-k",
            EigenError::Factorization { .. } => "factorization-failed",
            EigenError::Canceled => "canceled",
            EigenError::NoConvergence { .. } => "no-convergence",
            EigenError::InvalidOption { .. } => "invalid-option",
        }
    }
}

/// The k smallest eigenpairs of L φ = λ M φ.
pub fn eigs(
    pair: &SparsePair,
    options: &EigenOptions,
    symbolic: Option<&factor::Symbolic>,
    control: Control<'_>,
) -> Result<Spectrum, EigenError> {
    let n = pair.n();
    let k = options.k;
    let dense = match options.method {
        Method::Dense => true,
        Method::Sparse => false,
        Method::Auto => n <= 1500 || (3 * k > n && n <= 8000) || k + 1 >= n,
    };
    let max = if dense { n } else { n.saturating_sub(1) };
    if k == 0 || k > max {
        return Err(EigenError::InvalidK { k, n, max });
    }
    if !(options.tol > 0.0 && options.tol < 1.0) {
        return Err(EigenError::InvalidOption { name: "tol", message: format!("{} is not in (0, 1)", options.tol) });
    }
    // The dense path runs in one call to faer; a stop requested before it starts is honoured here.
    if control.stopped() {
        return Err(EigenError::Canceled);
    }
    let mut s = if dense {
        dense::eigs_dense(pair, k)?
    } else {
        lanczos::eigs_block_lanczos(pair, options, symbolic, control)?
    };
    finish(pair, &mut s);
    Ok(s)
}

/// The inertia check of [`Completeness`]; `None` when the found eigenvalues have no gap to put τ in.
pub fn check_completeness(
    pair: &SparsePair,
    values: &[f64],
    symbolic: Option<&factor::Symbolic>,
) -> Result<Option<Completeness>, EigenError> {
    let t = std::time::Instant::now();
    let Some(j) = (0..values.len().saturating_sub(1))
        .rev()
        .find(|&j| values[j + 1] - values[j] > 1e-6 * values[j + 1].abs().max(values[j].abs()).max(1e-300))
    else {
        return Ok(None);
    };
    let shift = 0.5 * (values[j] + values[j + 1]);
    let owned;
    let sym = match symbolic {
        Some(s) if s.fits(pair) => s,
        _ => {
            owned =
                factor::Symbolic::analyze(&pair.pattern).map_err(|message| EigenError::Factorization { message })?;
            &owned
        }
    };
    let below = factor::count_below(sym, pair, shift).map_err(|message| EigenError::Factorization { message })?;
    Ok(Some(Completeness {
        shift,
        below_shift: below,
        found_below_shift: j + 1,
        complete: below == j + 1,
        seconds: t.elapsed().as_secs_f64(),
    }))
}

/// Fixes signs (largest-magnitude entry positive), replaces each eigenvalue by the Rayleigh quotient φᵀLφ / φᵀMφ
/// of its vector and computes true residuals (block products with L and M, eight columns at a time), then keeps
/// the pairs in ascending order. The Rayleigh quotient's error is quadratic in the vector's, and it does not
/// depend on the shift: a solver's λ = σ + 1/θ carries θ's rounding error magnified by (λ − σ)², which with σ
/// inside the spectrum reached 10⁻¹¹ relative on the lowest eigenvalues of a 41k-vertex sphere (10⁻¹⁴ with the
/// quotient).
fn finish(pair: &SparsePair, s: &mut Spectrum) {
    let n = pair.n();
    let k = s.values.len();
    let sigma_floor = s.stats.sigma.abs().max(f64::MIN_POSITIVE);
    for j in 0..k {
        let (mut big, mut sign) = (0.0f64, 1.0);
        for &x in s.vectors.col(j).iter() {
            if x.abs() > big {
                (big, sign) = (x.abs(), x.signum());
            }
        }
        if sign < 0.0 {
            s.vectors.col_mut(j).iter_mut().for_each(|x| *x = -*x);
        }
    }
    s.residuals = vec![0.0; k];
    // Eight columns at a time as one row-major block: the block products take it without transposing.
    const B: usize = 8;
    let mut scratch = Vec::new();
    let (mut xr, mut lr, mut mr) = (vec![0.0; n * B], vec![0.0; n * B], vec![0.0; n * B]);
    for j0 in (0..k).step_by(B) {
        let bw = B.min(k - j0);
        for c in 0..bw {
            for (i, &x) in s.vectors.col(j0 + c).iter().enumerate() {
                xr[i * bw + c] = x;
            }
        }
        let x = faer::MatRef::from_row_major_slice(&xr[..n * bw], n, bw);
        let product = |values: &[f64], out: &mut [f64], scratch: &mut Vec<f64>| {
            let y = faer::MatMut::from_row_major_slice_mut(&mut out[..n * bw], n, bw);
            crate::operators::sparse::spmm(&pair.pattern, values, x, y, scratch);
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
            lam[c] = if xmx[c] > 0.0 { xlx[c] / xmx[c] } else { s.values[j0 + c] };
            s.values[j0 + c] = lam[c];
        }
        let (mut r, mut mnorm) = ([0.0f64; B], [0.0f64; B]);
        for (li, mi) in lb.chunks_exact(bw).zip(mb.chunks_exact(bw)) {
            for c in 0..bw {
                r[c] += (li[c] - lam[c] * mi[c]).powi(2);
                mnorm[c] += mi[c] * mi[c];
            }
        }
        for c in 0..bw {
            s.residuals[j0 + c] = r[c].sqrt() / (lam[c].abs().max(sigma_floor) * mnorm[c].sqrt());
        }
    }
    // Members of a cluster may trade places by rounding.
    if s.values.windows(2).any(|w| w[0] > w[1]) {
        let mut idx: Vec<usize> = (0..k).collect();
        idx.sort_by(|&a, &b| s.values[a].total_cmp(&s.values[b]));
        s.values = idx.iter().map(|&j| s.values[j]).collect();
        s.residuals = idx.iter().map(|&j| s.residuals[j]).collect();
        let mut sorted = Mat::<f64>::zeros(n, k);
        for (j, &from) in idx.iter().enumerate() {
            sorted.col_mut(j).copy_from(s.vectors.col(from));
        }
        s.vectors = sorted;
    }
}

/// All eigenpairs with λ in [a, b]. The shift stays below the spectrum (K must be positive definite), so this
/// asks for the smallest k pairs with k doubling (from 16) until the largest found exceeds b or k reaches the
/// solver's limit; the symbolic analysis is done once and reused. Efficient for bands near the bottom of the
/// spectrum, which is where shape analysis looks.
pub fn eigs_band(
    pair: &SparsePair,
    a: f64,
    b: f64,
    options: &EigenOptions,
    control: Control<'_>,
) -> Result<Spectrum, EigenError> {
    if !(a <= b) || !a.is_finite() || !b.is_finite() {
        return Err(EigenError::InvalidOption { name: "band", message: format!("[{a}, {b}] is not an interval") });
    }
    let n = pair.n();
    let symbolic = factor::Symbolic::analyze(&pair.pattern).map_err(|message| EigenError::Factorization { message })?;
    let mut k = 16usize.min(n.saturating_sub(1)).max(1);
    loop {
        let s = eigs(pair, &EigenOptions { k, ..options.clone() }, Some(&symbolic), control)?;
        let top = s.values.last().copied().unwrap_or(f64::INFINITY);
        let limit = if s.stats.method == "dense" { n } else { n - 1 };
        if top > b || k >= limit {
            let keep: Vec<usize> = (0..s.values.len()).filter(|&j| s.values[j] >= a && s.values[j] <= b).collect();
            let vectors = Mat::from_fn(n, keep.len(), |i, j| s.vectors[(i, keep[j])]);
            return Ok(Spectrum {
                values: keep.iter().map(|&j| s.values[j]).collect(),
                residuals: keep.iter().map(|&j| s.residuals[j]).collect(),
                vectors,
                stats: s.stats,
            });
        }
        k = (2 * k).min(limit);
    }
}
