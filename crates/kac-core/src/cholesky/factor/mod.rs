//! Sparse Cholesky of K = L − σM through faer's supernodal factorization, with the symbolic analysis (AMD
//! ordering, elimination tree, supernodes) kept apart so that the same pattern with another shift or another
//! mass never redoes it.

use crate::operators::sparse::{Pattern, SparsePair};
use crate::simd::Isa;
use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::cholesky::llt::factor::LltRegularization;
use faer::sparse::linalg::cholesky::supernodal::SymbolicSupernodalCholesky;
use faer::sparse::linalg::cholesky::{
    factorize_symbolic_cholesky, LdltRef, LltRef, SymbolicCholesky, SymmetricOrdering,
};
use faer::sparse::SparseColMatRef;
use faer::{Conj, MatMut, Par, Side};
use std::sync::atomic::AtomicBool;
use std::sync::{Arc, Mutex, OnceLock};

use super::numeric::{self, FactorError};
use super::tree::Split;

mod solve;

use solve::{assert_supernodes_fit, solve_weights, supernodal_solve_with, SolvePlan, PERMUTE_ROWS};

/// Factors with more values than this are made in pieces when a stop flag may end them: below it, one numeric
/// factorization on one core takes a fraction of a second, the longest a stop then waits (`bench/cancel.py`
/// measures the latency).
pub const PIECES_FROM: usize = 8_000_000;

thread_local! {
    /// The most values a factor may hold on this thread (see [`with_factor_limit`]).
    static FACTOR_LIMIT: std::cell::Cell<usize> = const { std::cell::Cell::new(usize::MAX) };
}

/// Runs `f` with a limit on the values of every factor the solvers of this thread make outside the eigensolver
/// (which takes its own, [`crate::spectrum::EigenOptions::max_values`]): Poisson, diffusion, geodesics, smoothing and
/// interpolation check the symbolic analysis' fill against it before any numeric factorization.
pub fn with_factor_limit<T>(limit: usize, f: impl FnOnce() -> T) -> T {
    let old = FACTOR_LIMIT.with(|l| l.replace(limit));
    let out = f();
    FACTOR_LIMIT.with(|l| l.set(old));
    out
}

/// The limit [`with_factor_limit`] set on this thread (no limit outside it).
pub fn factor_limit() -> usize {
    FACTOR_LIMIT.with(|l| l.get())
}

/// The symbolic analysis of a pattern, shareable across shifts and masses.
#[derive(Debug, Clone)]
pub struct Symbolic {
    pub pattern: Arc<Pattern>,
    pub inner: Arc<SymbolicCholesky<usize>>,
}

impl Symbolic {
    pub fn analyze(pattern: &Arc<Pattern>) -> Result<Self, String> {
        let inner =
            factorize_symbolic_cholesky(pattern.faer(), Side::Lower, SymmetricOrdering::Amd, Default::default())
                .map_err(|e| format!("symbolic Cholesky failed: {e:?}"))?;
        Ok(Symbolic { pattern: pattern.clone(), inner: Arc::new(inner) })
    }
    /// Whether this analysis fits a pair (same pattern).
    pub fn fits(&self, pair: &SparsePair) -> bool {
        Arc::ptr_eq(&self.pattern, &pair.pattern) || *self.pattern == *pair.pattern
    }
}

/// The diagonal of a factor on `s` (L_jj of an LLᵀ factor, D_jj of an LDLᵀ one), in factor order.
fn factor_diagonal(s: &SymbolicCholesky<usize>, values: &[f64]) -> Vec<f64> {
    use faer::sparse::linalg::cholesky::{supernodal::SupernodalLltRef, SymbolicCholeskyRaw};
    match s.raw() {
        SymbolicCholeskyRaw::Simplicial(s) => {
            let (cp, ri) = (s.col_ptr(), s.row_idx());
            (0..s.ncols())
                .map(|j| {
                    debug_assert_eq!(ri[cp[j]], j, "the diagonal leads each column of a simplicial factor");
                    values[cp[j]]
                })
                .collect()
        }
        SymbolicCholeskyRaw::Supernodal(s) => {
            let f = SupernodalLltRef::<'_, usize, f64>::new(s, values);
            (0..s.n_supernodes())
                .flat_map(|sn| {
                    let block = f.supernode(sn).val();
                    (0..block.ncols()).map(move |j| block[(j, j)])
                })
                .collect()
        }
    }
}

/// Sylvester's law of inertia: the number of eigenvalues of L φ = λ M φ below τ is the number of negative pivots
/// of an LDLᵀ factorization of L − τM (M positive definite). The factorization reuses the symbolic analysis and
/// does not pivot; `Err` when it meets an exact zero pivot (τ on an eigenvalue, or a singular leading block).
pub fn count_below(symbolic: &Symbolic, pair: &SparsePair, tau: f64) -> Result<usize, String> {
    Cholesky::factor_ldlt(symbolic, &pair.shifted(tau), Par::Seq)
        .map(|(_, below)| below)
        .map_err(|e| format!("LDLᵀ of L − {tau:e}·M failed ({e})"))
}

/// A numeric factor of a symmetric matrix K on a symbolic analysis: Cholesky K = LLᵀ when K is positive definite,
/// or K = LDLᵀ (L unit lower triangular, D diagonal, no pivoting) when it may be indefinite, as L − σM is for a
/// shift σ inside the spectrum. Both live in faer's supernodal (or simplicial) storage on the same analysis; an LDLᵀ
/// factor keeps D on the diagonal of its blocks.
pub struct Cholesky {
    symbolic: Symbolic,
    values: Vec<f64>,
    /// LDLᵀ (unit diagonal in L, D on the diagonal) rather than LLᵀ.
    ldlt: bool,
    /// The block solve's split of the tree for the thread count of its first parallel solve (`None` inside: the
    /// tree does not split usefully).
    plan: OnceLock<(usize, Option<Arc<SolvePlan>>)>,
    /// The parallel block solve's permuted block, kept between solves.
    scratch: Mutex<Vec<f64>>,
}

impl Cholesky {
    /// Factors the matrix with `values` on the analysed pattern; `Err` if it is not numerically positive definite.
    pub fn factor(symbolic: &Symbolic, values: &[f64], par: Par) -> Result<Self, String> {
        Self::factor_whole(symbolic, values, par)
    }
    /// As [`Cholesky::factor_ldlt`], stopped by `stop` within a fraction of a second: a factor of more than
    /// [`PIECES_FROM`] values is made in pieces ([`numeric`]) when there is a flag to see, and so is a factor of more
    /// than [`PARALLEL_FROM`] values on several threads when its tree splits (subtrees side by side); others by faer's
    /// numeric factorization in one call, which is faster on one thread.
    ///
    /// [`numeric`]: super::numeric
    pub fn factor_ldlt_stoppable(
        symbolic: &Symbolic,
        values: &[f64],
        par: Par,
        stop: Option<&AtomicBool>,
    ) -> Result<(Self, usize), FactorError> {
        if pieces(symbolic, par, stop) {
            return Self::factor_ldlt_pieces(symbolic, values, par, stop);
        }
        Self::factor_ldlt_whole(symbolic, values, par).map_err(FactorError::Failed)
    }
    /// As [`Cholesky::factor`], stopped by `stop` within a fraction of a second (see
    /// [`Cholesky::factor_ldlt_stoppable`]).
    pub fn factor_stoppable(
        symbolic: &Symbolic,
        values: &[f64],
        par: Par,
        stop: Option<&AtomicBool>,
    ) -> Result<Self, FactorError> {
        if pieces(symbolic, par, stop) {
            return Self::factor_pieces(symbolic, values, par, stop);
        }
        Self::factor_whole(symbolic, values, par).map_err(FactorError::Failed)
    }
    /// LDLᵀ in pieces, the stop flag seen between them (a simplicial analysis is factored whole).
    pub fn factor_ldlt_pieces(
        symbolic: &Symbolic,
        values: &[f64],
        par: Par,
        stop: Option<&AtomicBool>,
    ) -> Result<(Self, usize), FactorError> {
        let Some(l) = Self::supernodal(symbolic, values, true, par, stop)? else {
            return Self::factor_ldlt_whole(symbolic, values, par).map_err(FactorError::Failed);
        };
        let negative = factor_diagonal(&symbolic.inner, &l).iter().filter(|&&d| d < 0.0).count();
        Ok((Cholesky::checked(symbolic, l, true), negative))
    }
    /// LLᵀ in pieces, the stop flag seen between them (a simplicial analysis is factored whole).
    pub fn factor_pieces(
        symbolic: &Symbolic,
        values: &[f64],
        par: Par,
        stop: Option<&AtomicBool>,
    ) -> Result<Self, FactorError> {
        match Self::supernodal(symbolic, values, false, par, stop)? {
            Some(l) => Ok(Cholesky::checked(symbolic, l, false)),
            None => Self::factor_whole(symbolic, values, par).map_err(FactorError::Failed),
        }
    }
    /// A supernodal analysis' factor in pieces ([`numeric::factor_supernodal`]); `None` for a simplicial one
    /// (small or very sparse problems, factored whole in a fraction of a second).
    fn supernodal(
        symbolic: &Symbolic,
        values: &[f64],
        ldlt: bool,
        par: Par,
        stop: Option<&AtomicBool>,
    ) -> Result<Option<Vec<f64>>, FactorError> {
        use faer::sparse::linalg::cholesky::SymbolicCholeskyRaw;
        let SymbolicCholeskyRaw::Supernodal(sn) = symbolic.inner.raw() else { return Ok(None) };
        let inv = symbolic.inner.perm().map(|p| p.arrays().1);
        let p = &symbolic.pattern;
        numeric::factor_supernodal(sn, inv, &p.col_ptr, &p.row_idx, values, ldlt, par, stop).map(Some)
    }
    /// faer's numeric LLᵀ in one call (simplicial analyses; the reference the pieces are tested against).
    pub fn factor_whole(symbolic: &Symbolic, values: &[f64], par: Par) -> Result<Self, String> {
        let s = &symbolic.inner;
        let mut l = vec![0.0f64; s.len_val()];
        let a = SparseColMatRef::new(symbolic.pattern.faer(), values);
        let mut mem = MemBuffer::new(s.factorize_numeric_llt_scratch::<f64>(par, Default::default()));
        s.factorize_numeric_llt(
            &mut l,
            a,
            Side::Lower,
            LltRegularization::default(),
            par,
            MemStack::new(&mut mem),
            Default::default(),
        )
        .map_err(|e| format!("the matrix is not positive definite ({e:?})"))?;
        Ok(Cholesky::checked(symbolic, l, false))
    }
    /// Factors the (possibly indefinite) matrix with `values` as LDLᵀ without pivoting, and counts the negative
    /// entries of D: by Sylvester's law of inertia, the number of negative eigenvalues of the matrix. `Err` on an
    /// exact zero pivot. Without pivoting nothing bounds the growth of L when a leading block is nearly singular;
    /// callers that need accurate solves check the backward error of a solve.
    pub fn factor_ldlt(symbolic: &Symbolic, values: &[f64], par: Par) -> Result<(Self, usize), String> {
        Self::factor_ldlt_whole(symbolic, values, par)
    }
    /// faer's numeric LDLᵀ in one call (simplicial analyses; the reference the pieces are tested against).
    pub fn factor_ldlt_whole(symbolic: &Symbolic, values: &[f64], par: Par) -> Result<(Self, usize), String> {
        use faer::linalg::cholesky::ldlt::factor::LdltRegularization;
        let s = &symbolic.inner;
        let mut l = vec![0.0f64; s.len_val()];
        let a = SparseColMatRef::new(symbolic.pattern.faer(), values);
        let mut mem = MemBuffer::new(s.factorize_numeric_ldlt_scratch::<f64>(par, Default::default()));
        s.factorize_numeric_ldlt(
            &mut l,
            a,
            Side::Lower,
            LdltRegularization::default(),
            par,
            MemStack::new(&mut mem),
            Default::default(),
        )
        .map_err(|e| format!("zero pivot ({e:?})"))?;
        let negative = factor_diagonal(s, &l).iter().filter(|&&d| d < 0.0).count();
        Ok((Cholesky::checked(symbolic, l, true), negative))
    }
    /// The one constructor: checks, once per factor, the supernodal structure the intrinsic solve kernels take on
    /// trust (`assert_supernodes_fit` against the matrix's n rows). A `Cholesky` is never changed afterwards
    /// (private fields, no `&mut self` method), so every solve with it may rely on the check.
    fn checked(symbolic: &Symbolic, values: Vec<f64>, ldlt: bool) -> Self {
        use faer::sparse::linalg::cholesky::{supernodal::SupernodalLltRef, SymbolicCholeskyRaw};
        if let SymbolicCholeskyRaw::Supernodal(sn) = symbolic.inner.raw() {
            assert_supernodes_fit(&SupernodalLltRef::<'_, usize, f64>::new(sn, &values), symbolic.inner.nrows());
        }
        Cholesky { symbolic: symbolic.clone(), values, ldlt, plan: OnceLock::new(), scratch: Mutex::new(Vec::new()) }
    }
    /// The parallel block solve's plan for `threads` threads, made once for the first thread count asked (another
    /// count makes its own each time).
    fn plan(&self, sn: &SymbolicSupernodalCholesky<usize>, threads: usize) -> Option<Arc<SolvePlan>> {
        let (t, plan) = self.plan.get_or_init(|| (threads, SolvePlan::new(sn, threads).map(Arc::new)));
        if *t == threads {
            plan.clone()
        } else {
            SolvePlan::new(sn, threads).map(Arc::new)
        }
    }
    /// Whether a block solve on `threads` threads splits the tree (subtrees side by side), where its kernels apply.
    pub fn solves_in_parallel(&self, threads: usize) -> bool {
        use faer::sparse::linalg::cholesky::SymbolicCholeskyRaw;
        match self.symbolic.inner.raw() {
            SymbolicCholeskyRaw::Supernodal(sn) if threads > 1 => self.plan(sn, threads).is_some(),
            _ => false,
        }
    }
    /// Whether this is an LDLᵀ factor (else Cholesky).
    pub fn is_ldlt(&self) -> bool {
        self.ldlt
    }
    /// Solves K X = B in place for every column of `rhs`.
    ///
    /// Supernodal factors with 1, 2, 4, 8 or 16 right-hand sides use `supernodal_solve` (one sequential pass
    /// with the block stored row-major, so each factor entry meets all right-hand sides in one SIMD row, which faer's
    /// column-by-column solve does not); others use faer's solve with `par`.
    pub fn solve_in_place(&self, rhs: MatMut<'_, f64>, par: Par) {
        self.solve_in_place_with(rhs, par, Isa::detect())
    }
    /// [`Cholesky::solve_in_place`] with the block-solve kernels of a given instruction set (`Isa::Scalar`: the
    /// portable code); the tests run every set the CPU has.
    ///
    /// # Panics
    /// If `rhs` does not have as many rows as the factored matrix (any column count, stride or view is accepted).
    pub fn solve_in_place_with(&self, mut rhs: MatMut<'_, f64>, par: Par, isa: Isa) {
        use faer::sparse::linalg::cholesky::{supernodal::SupernodalLltRef, SymbolicCholeskyRaw};
        let s = &self.symbolic.inner;
        let n = s.nrows();
        assert_eq!(rhs.nrows(), n, "Cholesky::solve_in_place: the right-hand side must have one row per unknown");
        if let SymbolicCholeskyRaw::Supernodal(sn) = s.raw() {
            let f = SupernodalLltRef::<'_, usize, f64>::new(sn, &self.values);
            let plan = match par {
                Par::Rayon(t) if t.get() > 1 => self.plan(sn, t.get()),
                _ => None,
            };
            let plan = plan.as_deref();
            let perm = s.perm();
            let fwd = |i: usize| perm.map_or(i, |p| p.arrays().0[i]);
            macro_rules! run {
                ($b:literal) => {{
                    // Row-major right-hand sides (the eigensolver's blocks) are permuted a whole row at a time.
                    let row_major = rhs.col_stride() == 1 && (n <= 1 || rhs.row_stride() == $b);
                    if row_major {
                        // SAFETY: `rhs` is n × b (the `assert_eq!` on its rows above, the `match` on its columns
                        // below), and the `row_major` check (column stride 1, row stride b or a single row) puts
                        // entry (i, c) at offset i·b + c: the n·b values from the pointer are exactly its entries,
                        // seen as n rows of b (`[f64; b]` has the alignment of f64). `rhs` is borrowed mutably for
                        // this call and not used while `rows` lives.
                        let rows = unsafe { std::slice::from_raw_parts_mut(rhs.as_ptr_mut().cast::<[f64; $b]>(), n) };
                        if plan.is_some() {
                            // On the plan's threads: both permutations as gathers, one range of rows per thread,
                            // into the factor's kept scratch (a fresh n × b block would be faulted in page by page
                            // each time).
                            use rayon::prelude::*;
                            let per = n.div_ceil(par.degree().max(1)).max(PERMUTE_ROWS);
                            let mut kept = self.scratch.try_lock().ok();
                            let mut own = Vec::new();
                            let buf: &mut Vec<f64> = match kept.as_deref_mut() {
                                Some(v) => v,
                                None => &mut own,
                            };
                            buf.resize(n * $b, 0.0);
                            let x: &mut [[f64; $b]] = buf.as_chunks_mut::<$b>().0;
                            let inv = |j: usize| perm.map_or(j, |p| p.arrays().1[j]);
                            x.par_chunks_mut(per).enumerate().for_each(|(c, chunk)| {
                                for (i, row) in chunk.iter_mut().enumerate() {
                                    *row = rows[fwd(c * per + i)];
                                }
                            });
                            supernodal_solve_with::<$b>(&f, x, self.ldlt, isa, plan);
                            rows.par_chunks_mut(per).enumerate().for_each(|(c, chunk)| {
                                for (j, row) in chunk.iter_mut().enumerate() {
                                    *row = x[inv(c * per + j)];
                                }
                            });
                            return;
                        }
                        let mut x = vec![[0.0f64; $b]; n];
                        for (i, row) in x.iter_mut().enumerate() {
                            *row = rows[fwd(i)];
                        }
                        supernodal_solve_with::<$b>(&f, &mut x, self.ldlt, isa, plan);
                        for (i, row) in x.iter().enumerate() {
                            rows[fwd(i)] = *row;
                        }
                        return;
                    }
                    let mut x = vec![[0.0f64; $b]; n];
                    for (i, row) in x.iter_mut().enumerate() {
                        let src = fwd(i);
                        for (c, v) in row.iter_mut().enumerate() {
                            *v = rhs[(src, c)];
                        }
                    }
                    supernodal_solve_with::<$b>(&f, &mut x, self.ldlt, isa, plan);
                    for (i, row) in x.iter().enumerate() {
                        let dst = fwd(i);
                        for (c, v) in row.iter().enumerate() {
                            rhs[(dst, c)] = *v;
                        }
                    }
                    return;
                }};
            }
            match rhs.ncols() {
                1 => run!(1),
                2 => run!(2),
                4 => run!(4),
                8 => run!(8),
                16 => run!(16),
                _ => {}
            }
        }
        let mut mem = MemBuffer::new(s.solve_in_place_scratch::<f64>(rhs.ncols(), par));
        if self.ldlt {
            LdltRef::<'_, usize, f64>::new(s, &self.values).solve_in_place_with_conj(
                Conj::No,
                rhs,
                par,
                MemStack::new(&mut mem),
            );
        } else {
            LltRef::<'_, usize, f64>::new(s, &self.values).solve_in_place_with_conj(
                Conj::No,
                rhs,
                par,
                MemStack::new(&mut mem),
            );
        }
    }
    /// log |det K| from the factor's diagonal: 2 Σ log L_jj (Cholesky) or Σ log |D_jj| (LDLᵀ); the ordering does
    /// not change the determinant.
    pub fn log_det(&self) -> f64 {
        let d = factor_diagonal(&self.symbolic.inner, &self.values);
        if self.ldlt {
            d.iter().map(|d| d.abs().ln()).sum()
        } else {
            d.iter().map(|d| 2.0 * d.ln()).sum()
        }
    }
    /// Whether faer chose the supernodal factorization (else simplicial, for small or very sparse factors).
    pub fn is_supernodal(&self) -> bool {
        matches!(self.symbolic.inner.raw(), faer::sparse::linalg::cholesky::SymbolicCholeskyRaw::Supernodal(_))
    }
    /// The factor's values in faer's storage order (supernode by supernode, column-major within each).
    pub fn values(&self) -> &[f64] {
        &self.values
    }
    /// Entries of the factor (a measure of fill-in).
    pub fn factor_nnz(&self) -> usize {
        self.values.len()
    }
}

/// Whether a numeric factorization is made in pieces ([`numeric`]) rather than by faer in one call: where a stop
/// flag must be seen within a fraction of a second (factors of more than [`PIECES_FROM`] values), and where several
/// threads can factor disjoint subtrees side by side (more than [`PARALLEL_FROM`] values, and a tree that splits;
/// faer's numeric factorization uses threads only inside each supernode's dense blocks).
fn pieces(symbolic: &Symbolic, par: Par, stop: Option<&AtomicBool>) -> bool {
    use faer::sparse::linalg::cholesky::SymbolicCholeskyRaw;
    let len = symbolic.inner.len_val();
    if stop.is_some() && len > PIECES_FROM {
        return true;
    }
    match (par, symbolic.inner.raw()) {
        (Par::Rayon(t), SymbolicCholeskyRaw::Supernodal(sn)) if t.get() > 1 && len > PARALLEL_FROM => {
            Split::new(sn, t.get(), &solve_weights(sn)).is_some()
        }
        _ => false,
    }
}

/// Factors with more values than this are made in pieces, subtrees side by side, when several threads are given.
pub const PARALLEL_FROM: usize = 1_000_000;
