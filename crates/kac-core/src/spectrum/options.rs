//! What a solve is asked for: the method, k and the tolerance, the shift and the tuning of the sparse solver, and the
//! hooks a long solve reports progress to and is stopped by.

use super::EigenError;
use serde::{Deserialize, Serialize};
use std::sync::atomic::AtomicBool;

/// Which solver.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum Method {
    /// Dense for n ≤ 1500 or k > n/3 (n ≤ 8000), sparse otherwise (n counting the unknowns left once the known
    /// zero modes are deflated).
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
    /// Check completeness of a sparse solve by Sylvester's inertia and repair it (default true; see
    /// [`Completeness`]): one more numeric factorization (LDLᵀ of L − τM) on the same symbolic analysis, and
    /// further solves only when eigenvalues were missed. `false` skips the check (the result then says
    /// `completeness: null`).
    pub verify: bool,
    /// Put the operator's known zero modes in the result exactly and iterate on their complement (default true;
    /// see [`null_space`]).
    pub deflate_null_space: bool,
}

/// The residual tolerance of a solve unless asked otherwise (the one place this default is written: the CLI and
/// the service take it from here).
pub const DEFAULT_TOL: f64 = 1e-10;

impl Default for EigenOptions {
    fn default() -> Self {
        EigenOptions {
            k: 10,
            tol: DEFAULT_TOL,
            sigma: None,
            block: None,
            subspace: None,
            max_steps: 20_000,
            seed: 0x6b61_6321,
            threads: 0,
            method: Method::Auto,
            verify: true,
            deflate_null_space: true,
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

/// Hooks for a long solve: progress reports and a stop flag. The flag is checked after every phase (null space,
/// symbolic analysis, each factorization, each dense block, each completeness count) and within the iteration
/// before every block step, every Rayleigh–Ritz solve and every row chunk of the Ritz vectors, so that a stop
/// takes effect within a fraction of a second of work (`bench/cancel.py` measures it). Each phase is reported
/// to `progress` as it starts: `null-space`, `symbolic`, `factorization`, `iterating`, `ritz-vectors`,
/// `converged`, `verifying`, `dense`.
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
    /// `Err(Canceled)` once the stop flag is set.
    pub fn check(&self) -> Result<(), EigenError> {
        if self.stopped() {
            Err(EigenError::Canceled)
        } else {
            Ok(())
        }
    }
    /// Reports the start of a phase, then checks the flag.
    pub fn phase(&self, phase: &'static str, converged: usize, wanted: usize) -> Result<(), EigenError> {
        self.report(phase, converged, wanted);
        self.check()
    }
}
