//! What a solve returns: the eigenpairs with their residuals, the solver's statistics and timings, the
//! completeness check's report, and why a solve failed.

use super::*;

/// Seconds spent in each phase. On more than one thread some phases run beside each other (the symbolic analysis
/// beside the null space, the numeric factorization beside the basis' allocation, the completeness check's first count
/// beside the final residuals); each phase counts its own seconds, so the phases can add up to more than `total_s`.
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
    /// The completeness check (inertia) and any repair solves, with the first count's seconds where it ran beside the
    /// final residuals.
    pub verify_s: f64,
    pub total_s: f64,
}

#[derive(Debug, Clone, Default, Serialize)]
pub struct Stats {
    /// `dense`, `block-lanczos`, or `null-space` (every pair asked for is a known zero mode: nothing solved).
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
    /// Connected components of L's graph (where the operator's null space is known).
    pub components: Option<usize>,
    /// Known zero modes put in the result exactly (eigenvalue 0) and deflated from the iteration.
    pub zero_modes: usize,
    /// A band [a, b] ([`super::eigs_band`]): the eigenvalues below a, solved for and left out (so the first pair
    /// returned is the (below_band + 1)-th eigenvalue).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub below_band: Option<usize>,
    pub timings: Timings,
    /// Spectrum slicing ([`super::slicing`]): what each slice did; empty for a solve in one run.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub slices: Vec<super::slicing::SliceReport>,
    /// The path the solve took where it is not the one it planned (spectrum slicing given up for one run, the
    /// Krylov method for the dense solver), with why; `None` when it took the path planned.
    pub plan: Option<PlanChange>,
    /// The completeness check; `None` when it was turned off.
    pub completeness: Option<Completeness>,
}

/// A solve that took another path than the one it planned: nothing switches paths silently.
#[derive(Debug, Clone, Serialize, PartialEq)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct PlanChange {
    /// `slices` or `block-lanczos`.
    pub planned: &'static str,
    /// `one-run` (block Lanczos in one run) or `dense`.
    pub taken: &'static str,
    /// Why the planned path was given up.
    pub reason: String,
}

/// Whether the returned eigenvalues are the k smallest, with nothing missed.
///
/// `inertia`: Sylvester's law of inertia counts the eigenvalues below a shift τ as the negative pivots of an LDLᵀ
/// factorization of L − τM; τ sits in the first gap wider than 10⁻⁶ (relative) above λ_k among the converged
/// pairs (the solver converges a few guard pairs beyond k for this), so the count must equal the pairs found below
/// τ, which include all k returned. When the cluster at λ_k extends past the guard pairs, τ goes in the last gap
/// below it instead: a pair missed inside that cluster would differ from a returned one by less than 10⁻⁶, and
/// the returned pairs are then still a valid choice of the cluster's eigenvectors. When the count exceeds the pairs
/// found, the found pairs are deflated and the missing ones solved for (`repairs` times). `dense`: every
/// eigenvalue was computed. `null-space`: every returned pair is a known zero mode.
#[derive(Debug, Clone, Serialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct Completeness {
    /// `inertia`, `dense` or `null-space`.
    pub method: &'static str,
    pub complete: bool,
    /// τ of the (last) inertia count.
    pub shift: Option<f64>,
    /// Eigenvalues of the problem below `shift` (inertia).
    pub below_shift: Option<usize>,
    /// Eigenvalues the solver found below `shift`.
    pub found_below_shift: Option<usize>,
    /// Repair rounds that found missed pairs.
    pub repairs: usize,
    /// Pairs the repairs added.
    pub repaired_pairs: usize,
    pub seconds: f64,
}

impl Completeness {
    pub(crate) fn by(method: &'static str) -> Self {
        Completeness {
            method,
            complete: true,
            shift: None,
            below_shift: None,
            found_below_shift: None,
            repairs: 0,
            repaired_pairs: 0,
            seconds: 0.0,
        }
    }
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
    #[error(
        "incomplete spectrum: {below} eigenvalues lie below {shift:e} (Sylvester's inertia), the solver found {found} \
         after {repairs} repair rounds"
    )]
    Incomplete { shift: f64, below: usize, found: usize, repairs: usize },
    /// An array of the solve (`what`: the factor of L − σM or a Krylov basis) would hold more values than
    /// [`EigenOptions::max_values`].
    #[error("{what} would hold {values} values, above the limit of {limit}")]
    TooLarge { what: String, values: usize, limit: usize },
}

impl EigenError {
    /// Whether the request was at fault (it cannot succeed as given) rather than the computation.
    pub fn caller_fault(&self) -> bool {
        match self {
            EigenError::InvalidK { .. } | EigenError::InvalidOption { .. } | EigenError::TooLarge { .. } => true,
            EigenError::Factorization { .. }
            | EigenError::Canceled
            | EigenError::NoConvergence { .. }
            | EigenError::Incomplete { .. } => false,
        }
    }
}
