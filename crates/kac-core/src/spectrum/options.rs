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
    /// The most values one array of a sparse solve may hold (default: no limit): a factor of L − σM, predicted by
    /// the symbolic analysis before any numeric factorization, and a Krylov basis (n × subspace, each slice's
    /// own where the solve is sliced), checked before it is allocated. A larger one is [`EigenError::TooLarge`]. A
    /// slice task queued by a build from before the name was changed carries it as `max_factor_values`.
    #[serde(alias = "max_factor_values")]
    pub max_values: usize,
    /// Put the operator's known zero modes in the result exactly and iterate on their complement (default true;
    /// see [`null_space`]).
    pub deflate_null_space: bool,
    /// Slices of the spectrum solved apart ([`super::slicing`]): `None` chooses by k and the threads, `Some(1)`
    /// solves in one run.
    pub slices: Option<usize>,
}

/// The smallest residual tolerance a solve takes: a relative residual below about 100 machine epsilons cannot be
/// reached in double precision, and a solve asked for less would iterate until it is stopped.
pub const MIN_TOL: f64 = 1e-14;
/// The largest residual tolerance a solve takes (a looser one would call noise converged).
pub const MAX_TOL: f64 = 0.1;
/// The largest block size.
pub const MAX_BLOCK: usize = 64;
/// The most slices a solve is cut into ([`super::slicing`]).
pub const MAX_SLICES: usize = 64;
/// The largest |σ| a solve takes: beyond it, L − σM is σM to every digit for any operator a mesh of reasonable
/// units gives (and overflows for the largest doubles).
pub const MAX_ABS_SIGMA: f64 = 1e15;

impl EigenOptions {
    /// faer's parallelism for `threads`: one thread is sequential, 0 is the current rayon pool's threads.
    pub fn par(&self) -> faer::Par {
        if self.threads == 1 {
            faer::Par::Seq
        } else {
            faer::Par::rayon(self.threads)
        }
    }
    /// The threads a solve with these options uses: `threads`, or the current rayon pool's where it is 0.
    pub fn thread_count(&self) -> usize {
        if self.threads == 0 {
            rayon::current_num_threads()
        } else {
            self.threads
        }
    }
    /// Checks the settings no solve could honour, before anything is computed: a tolerance outside
    /// [`MIN_TOL`, `MAX_TOL`], a shift that is not finite, zero or beyond ±[`MAX_ABS_SIGMA`], a block outside
    /// 1..=[`MAX_BLOCK`], a subspace that cannot hold the pairs asked for, or no steps. Each error names the setting.
    pub fn check(&self) -> Result<(), EigenError> {
        let bad = |name: &'static str, message: String| Err(EigenError::InvalidOption { name, message });
        if !self.tol.is_finite() || self.tol < MIN_TOL || self.tol > MAX_TOL {
            return bad(
                "tol",
                format!(
                    "{:e} is outside [{MIN_TOL:e}, {MAX_TOL}]: a relative residual below about 100 machine epsilons \
                     cannot be reached in double precision",
                    self.tol
                ),
            );
        }
        if let Some(s) = self.sigma {
            if !s.is_finite() || s.abs() > MAX_ABS_SIGMA {
                return bad("sigma", format!("{s:e} is not a finite shift within ±{MAX_ABS_SIGMA:e}"));
            }
            if s == 0.0 {
                return bad(
                    "sigma",
                    "0 is an eigenvalue of every operator without a Dirichlet condition (its zero modes), where \
                     L − σM cannot be factored: give a shift below 0 (say −1e-3 · λ_k), or none for the default"
                        .into(),
                );
            }
        }
        if let Some(b) = self.block {
            if !(1..=MAX_BLOCK).contains(&b) {
                return bad("block", format!("{b} is outside 1..={MAX_BLOCK}"));
            }
        }
        if let Some(m) = self.subspace {
            let b = self.block.unwrap_or(8);
            let least = self.k + (b / 2).max(2) + 2 * b;
            if m < least {
                return bad(
                    "subspace",
                    format!(
                        "{m} columns cannot hold k = {} pairs with their guard and two blocks of {b}: give at least \
                         {least}, or none for the default",
                        self.k
                    ),
                );
            }
        }
        if let Some(s) = self.slices {
            if !(1..=MAX_SLICES).contains(&s) {
                return bad("slices", format!("{s} is outside 1..={MAX_SLICES}"));
            }
        }
        if self.max_steps == 0 {
            return bad("max_steps", "0 steps: give at least 1".into());
        }
        Ok(())
    }
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
            max_values: usize::MAX,
            deflate_null_space: true,
            slices: None,
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
    /// Idle threads a host lends to a sliced solve beyond its own `threads` ([`Lender`]); none without one.
    pub lender: Option<&'a dyn Lender>,
    /// Where slices may be solved by other machines ([`Farm`]); none without one.
    pub farm: Option<&'a dyn Farm>,
}

/// A host that lends idle threads of the pool a solve runs on (the service's idle workers) to a solve cut into
/// spectrum slices ([`super::slicing`]). The solve asks when its slices are planned for as many threads as
/// it has slices beyond its own, and again after each slice the calling thread solves while more slices wait than
/// threads take them (a thread that came free since joins then). Each thread granted takes the next slice waiting,
/// and after each slice it asks whether the host wants it back (work of its own is waiting), and gives it back when
/// so or when no slice is left.
///
/// A granted thread is a task spawned on the solve's pool, which an idle thread of that pool runs; one that no
/// thread has started when the solve's own thread runs out of slices ends at once, so a grant the host cannot keep
/// delays nothing.
pub trait Lender: Sync {
    /// Up to `wanted` threads for the solve's slices; the number granted.
    fn borrow(&self, wanted: usize) -> usize;
    /// Whether the host wants a granted thread back now (asked after each slice it solved).
    fn wanted_back(&self) -> bool;
    /// One granted thread is given back.
    fn give_back(&self);
}

/// A host that has slices of a sliced solve solved elsewhere (the service's slice jobs, which any replica sharing its
/// queue may claim). The solve offers the slices its own and lent threads do not start at once; a thread that comes
/// to an offered slice takes it back when nobody has started it, and otherwise collects it once the solve has no
/// slice of its own left. A slice that failed or was lost elsewhere is solved here after all, so no slice is lost;
/// one that another machine has started is waited for, however slow that machine (one lost with its machine until
/// the host gives it back: the service's lease).
pub trait Farm: Sync {
    /// Offers a slice; false when it was not taken (the solve keeps it).
    fn offer(&self, task: &super::slicing::SliceTask) -> bool;
    /// Takes an offered slice back when nobody has started it; true: it is the solve's to run now.
    fn take_back(&self, task: &super::slicing::SliceTask) -> bool;
    /// Waits for an offered slice solved elsewhere, watching `control`'s stop flag: its pairs (values and
    /// M-orthonormal vectors of the whole problem), what the slice's run did, and who solved it. `None`: the slice
    /// is the solve's to run after all (taken back, or failed or lost where it ran).
    fn collect(
        &self,
        task: &super::slicing::SliceTask,
        control: &Control<'_>,
    ) -> Result<Option<super::slicing::Solved>, EigenError>;
    /// The solve no longer waits for an offered slice (another slice failed, or the solve was stopped): whatever
    /// solves it elsewhere may stop.
    fn release(&self, task: &super::slicing::SliceTask);
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
    /// Runs `work`, which cannot stop inside, where a stop still ends the caller at once: on a thread of its own
    /// while this one watches the flag every 50 ms; a stop returns `Canceled` and the abandoned work finishes on its
    /// thread with its result dropped (its core stays busy until then; the caller is free). At most one such
    /// thread per core, abandoned ones included: a caller beyond waits here, still stoppable. Without a flag the
    /// work runs here.
    pub fn abandonable<T: Send + 'static>(
        &self,
        name: &str,
        work: impl FnOnce() -> T + Send + 'static,
    ) -> Result<T, EigenError> {
        use std::sync::atomic::{AtomicUsize, Ordering};
        if self.stop.is_none() {
            return Ok(work());
        }
        static THREADS: AtomicUsize = AtomicUsize::new(0);
        let cores = std::thread::available_parallelism().map_or(1, |c| c.get());
        while THREADS.fetch_update(Ordering::SeqCst, Ordering::SeqCst, |n| (n < cores).then_some(n + 1)).is_err() {
            self.check()?;
            std::thread::sleep(std::time::Duration::from_millis(50));
        }
        let (tx, rx) = std::sync::mpsc::channel();
        std::thread::Builder::new()
            .name(format!("kac-{name}"))
            .spawn(move || {
                // A panic is carried back to the caller and raised there (where the service's runner catches it
                // as the job's), not lost with this thread.
                let _ = tx.send(std::panic::catch_unwind(std::panic::AssertUnwindSafe(work)));
                THREADS.fetch_sub(1, Ordering::SeqCst);
            })
            .inspect_err(|_| {
                THREADS.fetch_sub(1, Ordering::SeqCst);
            })
            .map_err(|e| EigenError::Factorization { message: format!("cannot start the {name} thread: {e}") })?;
        loop {
            match rx.recv_timeout(std::time::Duration::from_millis(50)) {
                Ok(Ok(result)) => return Ok(result),
                Ok(Err(panic)) => std::panic::resume_unwind(panic),
                Err(std::sync::mpsc::RecvTimeoutError::Timeout) => self.check()?,
                Err(std::sync::mpsc::RecvTimeoutError::Disconnected) => {
                    return Err(EigenError::Factorization { message: format!("the {name} stopped without a result") })
                }
            }
        }
    }
    /// Reports the start of a phase, then checks the flag.
    pub fn phase(&self, phase: &'static str, converged: usize, wanted: usize) -> Result<(), EigenError> {
        self.report(phase, converged, wanted);
        self.check()
    }
}
