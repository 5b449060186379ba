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

/// Factors with more values than this are made in pieces when a stop flag may end them (about 0.3 s of numeric
/// factorization on one core of this project's machines at 8·10⁶ values; `bench/cancel.py` measures the
/// latency).
pub const PIECES_FROM: usize = 8_000_000;

thread_local! {
    /// The most values a factor may hold on this thread (see [`with_factor_limit`]).
    static FACTOR_LIMIT: std::cell::Cell<usize> = const { std::cell::Cell::new(usize::MAX) };
}

/// Runs `f` with a limit on the values of every factor the solvers of this thread make outside the eigensolver
/// (which takes its own, [`super::EigenOptions::max_values`]): Poisson, diffusion, geodesics, smoothing and
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
    /// numeric factorization in one call, about a fifth faster on one thread.
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
    /// with the block stored row-major, so each factor entry meets all right-hand sides in one SIMD row: about
    /// 1.6× faster than faer's solve for 8 columns at 41k vertices); others use faer's solve with `par`.
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

type SupernodalFactor<'a> = faer::sparse::linalg::cholesky::supernodal::SupernodalLltRef<'a, usize, f64>;

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

/// Asserts what the intrinsic kernels take on trust from faer's supernodal structure, for a block X of `n` rows:
/// every supernode's columns `start..start + nc` and pattern rows are rows of X (< n), and its value block is
/// `ld × nc` column-major with column stride `ld = nc + pattern length`, so that entry (i, j) is at `j·ld + i`.
/// One pass over the supernodes' patterns, run once per factor by `Cholesky::checked` (run before every solve it
/// cost 6% of the solves at 41k vertices, k = 200).
fn assert_supernodes_fit(f: &SupernodalFactor<'_>, n: usize) {
    for s in 0..f.symbolic().n_supernodes() {
        let sn = f.supernode(s);
        let (c0, rows, l) = (sn.start(), sn.pattern(), sn.val());
        let nc = l.ncols();
        let ld = nc.checked_add(rows.len()).expect("supernode size");
        assert!(c0 <= n && nc <= n - c0, "supernode {s}: columns {c0}..{c0}+{nc} outside {n} rows");
        assert!(rows.iter().copied().max().is_none_or(|r| r < n), "supernode {s}: a pattern row outside {n} rows");
        assert!(
            l.nrows() == ld && l.row_stride() == 1 && (nc <= 1 || l.col_stride() == ld as isize),
            "supernode {s}: values not a column-major {ld} × {nc} block"
        );
    }
}

/// The fewest rows per task of a parallel solve's permutations (one range per thread above that).
const PERMUTE_ROWS: usize = 8192;

/// How the block solve runs on several threads: the tree's [`Split`] for the factor's values, each subtree's
/// column limit, and the buffer row of every column of the top.
struct SolvePlan {
    split: Split,
    /// Per worker, per subtree: the first column past the subtree (its pattern rows at or above it are the top's).
    limits: Vec<Vec<usize>>,
    /// The buffer row of each top column (`usize::MAX` elsewhere), and the top's columns in order.
    top_pos: Vec<usize>,
    top_cols: Vec<usize>,
}

/// Each supernode's weight in a block solve: each sweep streams its lower triangle and its rows below once.
fn solve_weights(sn: &SymbolicSupernodalCholesky<usize>) -> Vec<f64> {
    let (begin, end) = (sn.supernode_begin(), sn.supernode_end());
    (0..sn.n_supernodes())
        .map(|s| {
            let (c, r) = (end[s] - begin[s], sn.supernode(s).pattern().len());
            (c * (c + 1) / 2 + c * r) as f64
        })
        .collect()
}

impl SolvePlan {
    /// `None` where the tree does not split usefully for `threads` (see [`Split::new`]).
    fn new(sn: &SymbolicSupernodalCholesky<usize>, threads: usize) -> Option<Self> {
        let (begin, end) = (sn.supernode_begin(), sn.supernode_end());
        let split = Split::new(sn, threads, &solve_weights(sn))?;
        // What keeps the threads on their own rows (the kernels' redirection splits each pattern at the subtree's
        // limit): every supernode's pattern is strictly ascending and lies past its own columns, so a subtree's
        // rows below the limit are its own and those at or above it are its ancestors' (the top's). Checked once per
        // plan rather than taken on trust from faer.
        for s in 0..sn.n_supernodes() {
            let p = sn.supernode(s).pattern();
            assert!(
                p.first().is_none_or(|&r| r >= end[s]) && p.windows(2).all(|w| w[0] < w[1]),
                "supernode {s}: pattern not ascending past its columns"
            );
        }
        let limits = split.parts.iter().map(|p| p.iter().map(|&(_, hi)| end[hi - 1]).collect()).collect();
        let mut top_pos = vec![usize::MAX; sn.nrows()];
        let top_cols: Vec<usize> = split.top.iter().flat_map(|&s| begin[s]..end[s]).collect();
        for (i, &c) in top_cols.iter().enumerate() {
            top_pos[c] = i;
        }
        Some(SolvePlan { split, limits, top_pos, top_cols })
    }
}

/// A pointer shared by the threads of one parallel solve, each writing its own rows (see [`parallel_solve`]).
#[cfg(target_arch = "x86_64")]
#[derive(Clone, Copy)]
struct Shared(*mut f64);
// SAFETY: `parallel_solve` hands the pointer to threads that write disjoint rows of X while it lives (each
// subtree's own columns; `SolvePlan::new` checked the patterns that make them disjoint) and read rows no thread
// writes meanwhile (the top's, in the backward sweep).
#[cfg(target_arch = "x86_64")]
unsafe impl Send for Shared {}
// SAFETY: as above.
#[cfg(target_arch = "x86_64")]
unsafe impl Sync for Shared {}

#[cfg(target_arch = "x86_64")]
impl Shared {
    /// The pointer (a method, so that closures capture the `Shared`, not its field).
    fn get(self) -> *mut f64 {
        self.0
    }
}

/// The block solve on the plan's threads. Forward: the workers sweep their subtrees side by side, each updating the
/// top's rows in a buffer of its own, which are then added to X; then the top, in order, on this thread. Backward:
/// the top first, then the subtrees side by side (each reads the top's final rows and writes its own). Subtrees are
/// closed under descendants ([`Split`]), so no two workers touch the same row of X.
///
/// `sweep` must be sound to call on X (n rows of B) for any range of supernodes with rows at or above the limit
/// redirected to a buffer of the plan's top rows: the kernels' contract given the factor and the CPU.
#[cfg(target_arch = "x86_64")]
fn parallel_solve<const B: usize>(
    f: &SupernodalFactor<'_>,
    x: &mut [[f64; B]],
    plan: &SolvePlan,
    sweep: impl Fn(&SupernodalFactor<'_>, bool, usize, usize, &kernels::Sweep<'_>) + Sync,
) {
    use rayon::prelude::*;
    let n_top = plan.top_cols.len();
    let xp = Shared(x.as_mut_ptr().cast::<f64>());
    let mut bufs: Vec<Vec<f64>> = vec![vec![0.0; n_top * B]; plan.split.parts.len()];
    bufs.par_iter_mut().zip(&plan.split.parts).zip(&plan.limits).for_each(|((buf, part), limits)| {
        for (&(lo, hi), &limit) in part.iter().zip(limits) {
            let sw = kernels::Sweep { x: xp.get(), limit, buf: buf.as_mut_ptr(), top_pos: &plan.top_pos, n_top };
            sweep(f, true, lo, hi, &sw);
        }
    });
    for buf in &bufs {
        for (i, &c) in plan.top_cols.iter().enumerate() {
            for (xv, bv) in x[c].iter_mut().zip(&buf[i * B..(i + 1) * B]) {
                *xv += bv;
            }
        }
    }
    // X was written through its reference just now: the pointer is taken again for what follows.
    let xp = Shared(x.as_mut_ptr().cast::<f64>());
    let whole = |buf: *mut f64, limit: usize| kernels::Sweep { x: xp.get(), limit, buf, top_pos: &plan.top_pos, n_top };
    let sw = whole(std::ptr::null_mut(), usize::MAX);
    for &s in &plan.split.top {
        sweep(f, true, s, s + 1, &sw);
    }
    for &s in plan.split.top.iter().rev() {
        sweep(f, false, s, s + 1, &sw);
    }
    plan.split.parts.par_iter().for_each(|part| {
        let sw = kernels::Sweep { x: xp.get(), limit: usize::MAX, buf: std::ptr::null_mut(), top_pos: &[], n_top: 0 };
        for &(lo, hi) in part {
            sweep(f, false, lo, hi, &sw);
        }
    });
}

/// Runs the block solve with intrinsics for 4, 8 or 16 right-hand sides when `isa` is AVX2 + FMA or AVX-512 and
/// the CPU has it (detected at run time by the caller, as faer's own kernels do), else the portable
/// `supernodal_solve` (compiled for AVX2 + FMA where available).
///
/// `f` must be the factor of a `Cholesky` (whose constructor ran `assert_supernodes_fit` on it against its n rows);
/// the length of `x` is asserted equal to that n here.
fn supernodal_solve_with<const B: usize>(
    f: &SupernodalFactor<'_>,
    x: &mut [[f64; B]],
    ldlt: bool,
    isa: Isa,
    plan: Option<&SolvePlan>,
) {
    #[cfg(target_arch = "x86_64")]
    {
        if let Some(plan) = plan.filter(|_| isa != Isa::Scalar && isa.supported()) {
            type Sweep = unsafe fn(&SupernodalFactor<'_>, bool, usize, usize, &kernels::Sweep<'_>);
            let sweep: Option<Sweep> = match (isa, B, ldlt) {
                (Isa::Avx512, 8, false) => Some(kernels::sweep_avx512::<1, false>),
                (Isa::Avx512, 8, true) => Some(kernels::sweep_avx512::<1, true>),
                (Isa::Avx512, 16, false) => Some(kernels::sweep_avx512::<2, false>),
                (Isa::Avx512, 16, true) => Some(kernels::sweep_avx512::<2, true>),
                (_, 4, false) => Some(kernels::sweep_avx2::<1, false>),
                (_, 4, true) => Some(kernels::sweep_avx2::<1, true>),
                (_, 8, false) => Some(kernels::sweep_avx2::<2, false>),
                (_, 8, true) => Some(kernels::sweep_avx2::<2, true>),
                _ => None,
            };
            if let Some(sweep) = sweep {
                assert_eq!(x.len(), f.symbolic().nrows(), "the block must have one row per unknown");
                assert_eq!(plan.top_pos.len(), x.len(), "a plan for another factor");
                parallel_solve(f, x, plan, |f, fwd, lo, hi, sw| {
                    // SAFETY: the CPU has the sweep's instruction set (`isa.supported()` above); X is n rows of
                    // B = R·LANES values (the `match` pairs each width with its sweep; n asserted just above), the
                    // factor passed `assert_supernodes_fit` against n in `Cholesky::checked`, and `parallel_solve`
                    // keeps the rest of the sweep's contract (see there).
                    unsafe { sweep(f, fwd, lo, hi, sw) }
                });
                return;
            }
        }
        #[target_feature(enable = "avx2,fma")]
        fn portable_avx2<const B: usize, const UNIT: bool>(f: &SupernodalFactor<'_>, x: &mut [[f64; B]]) {
            supernodal_solve::<B, true, UNIT>(f, x)
        }
        if isa != Isa::Scalar && isa.supported() {
            type Kernel = unsafe fn(&SupernodalFactor<'_>, &mut [f64]);
            // Each kernel's width R·LANES is B: AVX-512 has 8 lanes, AVX2 4.
            let kernel: Option<Kernel> = match (isa, B, ldlt) {
                (Isa::Avx512, 8, false) => Some(kernels::solve_avx512::<1, false>),
                (Isa::Avx512, 8, true) => Some(kernels::solve_avx512::<1, true>),
                (Isa::Avx512, 16, false) => Some(kernels::solve_avx512::<2, false>),
                (Isa::Avx512, 16, true) => Some(kernels::solve_avx512::<2, true>),
                (_, 4, false) => Some(kernels::solve_avx2::<1, false>),
                (_, 4, true) => Some(kernels::solve_avx2::<1, true>),
                (_, 8, false) => Some(kernels::solve_avx2::<2, false>),
                (_, 8, true) => Some(kernels::solve_avx2::<2, true>),
                _ => None,
            };
            match kernel {
                Some(kernel) => {
                    assert_eq!(x.len(), f.symbolic().nrows(), "the block must have one row per unknown");
                    // SAFETY: the CPU has the kernel's instruction set (`isa.supported()` above; an AVX-512 CPU
                    // counts as such only with AVX2 + FMA too); the flattened block is x.len() rows of B = R·LANES
                    // values (the `match` pairs each width with its kernel), x.len() is the factor's n (the
                    // `assert_eq!` just above), and `Cholesky::checked` ran `assert_supernodes_fit` on this factor
                    // against n when it was built: the kernel's `# Safety`.
                    unsafe { kernel(f, x.as_flattened_mut()) };
                }
                // SAFETY: the CPU has AVX2 + FMA (`isa.supported()` above); the portable body indexes with checks.
                None if ldlt => unsafe { portable_avx2::<B, true>(f, x) },
                // SAFETY: as in the arm above.
                None => unsafe { portable_avx2::<B, false>(f, x) },
            }
            return;
        }
    }
    // The split solve needs the intrinsic kernels: elsewhere the plan goes unused.
    let _ = plan;
    if ldlt {
        supernodal_solve::<B, false, true>(f, x)
    } else {
        supernodal_solve::<B, false, false>(f, x)
    }
}

/// `supernodal_solve` for B = R·LANES right-hand sides (R registers of `S::LANES` doubles per row of X: AVX2's four
/// or AVX-512's eight, see [`crate::simd`]) with intrinsics: the same passes and groups of four columns, with the
/// group's solved rows (forward) or its four accumulators (backward) in registers. Written with intrinsics because the compiler vectorized the portable
/// loops across rows of X instead (transposing shuffles and operands spilled to the stack).
#[cfg(target_arch = "x86_64")]
mod kernels {
    use super::SupernodalFactor;
    use crate::simd::F64s;
    use std::arch::x86_64::{__m256d, __m512d};

    // Register helpers of the two sweeps, for a row of B = R·LANES values at a pointer. `S` and `R` are the
    // expanding function's register type and count (macro_rules resolve them where the macro is used).
    macro_rules! load {
        ($p:expr) => {{
            let p: *mut f64 = $p;
            let mut v = [S::zero(); R];
            for q in 0..R {
                v[q] = S::load(p.add(S::LANES * q));
            }
            v
        }};
    }
    macro_rules! store {
        ($p:expr, $v:expr) => {{
            let (p, v): (*mut f64, [S; R]) = ($p, $v);
            for q in 0..R {
                v[q].store(p.add(S::LANES * q));
            }
        }};
    }
    macro_rules! scale {
        ($v:expr, $d:expr) => {{
            let d = S::splat(&(1.0 / $d));
            for q in 0..R {
                $v[q] = $v[q].mul(d);
            }
        }};
    }
    // x ← x − a·g for one broadcast factor entry a.
    macro_rules! axpy {
        ($x:expr, $a:expr, $g:expr) => {{
            let a = S::splat($a);
            for q in 0..R {
                $x[q] = a.neg_mul_add($g[q], $x[q]);
            }
        }};
    }

    /// [`supernodal_solve`] with AVX2 + FMA registers (B = 4·R right-hand sides).
    ///
    /// # Safety
    /// As [`supernodal_solve`] with `S = __m256d`: the CPU has AVX2 and FMA, `x.len()` is a multiple of 4·R, and
    /// `assert_supernodes_fit(f, x.len() / (4·R))` holds.
    #[target_feature(enable = "avx2,fma")]
    pub(super) unsafe fn solve_avx2<const R: usize, const UNIT: bool>(f: &SupernodalFactor<'_>, x: &mut [f64]) {
        // SAFETY: this function's contract is the kernel's.
        unsafe { supernodal_solve::<__m256d, R, UNIT>(f, x) }
    }

    /// [`supernodal_solve`] with AVX-512 registers (B = 8·R right-hand sides).
    ///
    /// # Safety
    /// As [`supernodal_solve`] with `S = __m512d`: the CPU has AVX-512F, `x.len()` is a multiple of 8·R, and
    /// `assert_supernodes_fit(f, x.len() / (8·R))` holds.
    #[target_feature(enable = "avx512f")]
    pub(super) unsafe fn solve_avx512<const R: usize, const UNIT: bool>(f: &SupernodalFactor<'_>, x: &mut [f64]) {
        // SAFETY: this function's contract is the kernel's.
        unsafe { supernodal_solve::<__m512d, R, UNIT>(f, x) }
    }

    /// Where a forward sweep reads and writes (see [`forward`]): X, and the rows redirected into a buffer.
    pub(super) struct Sweep<'a> {
        /// Row r of X at `x + r·b`.
        pub x: *mut f64,
        /// Pattern rows at or above this go to `buf` (`usize::MAX`: none).
        pub limit: usize,
        /// `n_top` rows of b values.
        pub buf: *mut f64,
        /// The buffer row of each redirected row (n entries; others are not read).
        pub top_pos: &'a [usize],
        pub n_top: usize,
    }

    /// One sweep of the block solve ([`forward`] or [`backward`], on `sw.x`) over supernodes `lo..hi` with AVX2 +
    /// FMA registers (B = 4·R right-hand sides).
    ///
    /// # Safety
    /// As [`forward`] or [`backward`] with `S = __m256d`: the CPU has AVX2 and FMA.
    #[target_feature(enable = "avx2,fma")]
    pub(super) unsafe fn sweep_avx2<const R: usize, const UNIT: bool>(
        f: &SupernodalFactor<'_>,
        fwd: bool,
        lo: usize,
        hi: usize,
        sw: &Sweep<'_>,
    ) {
        // SAFETY: this function's contract is the sweep's.
        unsafe {
            if fwd {
                forward::<__m256d, R, UNIT>(f, lo, hi, sw)
            } else {
                backward::<__m256d, R, UNIT>(f, lo, hi, sw.x)
            }
        }
    }

    /// [`sweep_avx2`] with AVX-512 registers (B = 8·R right-hand sides).
    ///
    /// # Safety
    /// As [`forward`] or [`backward`] with `S = __m512d`: the CPU has AVX-512F.
    #[target_feature(enable = "avx512f")]
    pub(super) unsafe fn sweep_avx512<const R: usize, const UNIT: bool>(
        f: &SupernodalFactor<'_>,
        fwd: bool,
        lo: usize,
        hi: usize,
        sw: &Sweep<'_>,
    ) {
        // SAFETY: this function's contract is the sweep's.
        unsafe {
            if fwd {
                forward::<__m512d, R, UNIT>(f, lo, hi, sw)
            } else {
                backward::<__m512d, R, UNIT>(f, lo, hi, sw.x)
            }
        }
    }

    /// The block solve on X row-major (row r at `x[r·b..(r + 1)·b]`, b = R·LANES), through raw pointers.
    ///
    /// # Safety
    /// - The CPU has `S`'s instruction set (the caller checks `Isa::supported`).
    /// - `x.len()` is a multiple of b; with n = x.len() / b, `assert_supernodes_fit(f, n)` holds: every row the
    ///   structure names is < n (so `row!` stays in `x`), and each supernode's values are a column-major `ld × nc`
    ///   block with column stride `ld` (so `lp + j·ld + i`, i < ld, j < nc, stays in the block).
    #[inline(always)]
    unsafe fn supernodal_solve<S: F64s, const R: usize, const UNIT: bool>(f: &SupernodalFactor<'_>, x: &mut [f64]) {
        let ns = f.symbolic().n_supernodes();
        let xp = x.as_mut_ptr();
        let whole = Sweep { x: xp, limit: usize::MAX, buf: std::ptr::null_mut(), top_pos: &[], n_top: 0 };
        // SAFETY: the contract above is `forward`'s and `backward`'s for the whole range of supernodes, with no rows
        // redirected (limit past every row).
        unsafe {
            forward::<S, R, UNIT>(f, 0, ns, &whole);
            backward::<S, R, UNIT>(f, 0, ns, xp);
        }
    }

    /// The forward sweep (L y = x, D⁻¹ y stored for LDLᵀ) over supernodes `lo..hi`, in order. Rows below
    /// `sw.limit` are rows of X at `sw.x`; a pattern row at or above it (an ancestor's, in the top of a
    /// [`super::super::tree::Split`]) is updated in `sw.buf` at row `sw.top_pos[r]` instead.
    ///
    /// # Safety
    /// As [`supernodal_solve`], for X at `sw.x` (n rows of b, n the factor's); every supernode of `lo..hi` lies
    /// below `sw.limit` with its columns; and where some pattern row is at or above `sw.limit`, `sw.top_pos` has n
    /// entries and `sw.buf` holds `sw.n_top` rows of b (positions are checked against `n_top`). No other thread
    /// touches the rows written meanwhile.
    #[inline(always)]
    unsafe fn forward<S: F64s, const R: usize, const UNIT: bool>(
        f: &SupernodalFactor<'_>,
        lo: usize,
        hi: usize,
        sw: &Sweep<'_>,
    ) {
        // SAFETY: the contract above. Every pointer below is `row!(r)` or `top!(r)` (then up to b values from it)
        // for a row r the structure names, or `lp.add(j·ld + i)` with j < nc, i < ld inside a supernode's value
        // block: in bounds by `assert_supernodes_fit`, which `Cholesky::checked` ran on the factor, and by the
        // `top_pos` check. The register operations need the instruction set the caller checked.
        unsafe {
            let b = S::LANES * R;
            let xp = sw.x;
            macro_rules! row {
                ($r:expr) => {{
                    let r: usize = $r;
                    xp.add(r * b)
                }};
            }
            macro_rules! top {
                ($r:expr) => {{
                    let pos = sw.top_pos[$r];
                    assert!(pos < sw.n_top, "a pattern row above the range that is not in the top");
                    sw.buf.add(pos * b)
                }};
            }
            for s in lo..hi {
                let sn = f.supernode(s);
                let (c0, rows, l) = (sn.start(), sn.pattern(), sn.val());
                let nc = l.ncols();
                let ld = nc + rows.len();
                let lp = l.as_ptr();
                let lead = nc % 4;
                // Pattern rows below the limit are the range's own; the rest are the top's.
                let own = if sw.limit == usize::MAX { rows.len() } else { rows.partition_point(|&r| r < sw.limit) };
                for j in 0..lead {
                    let cj = lp.add(j * ld);
                    let mut g = load!(row!(c0 + j));
                    if UNIT {
                        let mut stored = g;
                        scale!(stored, *cj.add(j));
                        store!(row!(c0 + j), stored);
                    } else {
                        scale!(g, *cj.add(j));
                        store!(row!(c0 + j), g);
                    }
                    for i in j + 1..nc {
                        let p = row!(c0 + i);
                        let mut xi = load!(p);
                        axpy!(xi, cj.add(i), g);
                        store!(p, xi);
                    }
                    for (t, &r) in rows[..own].iter().enumerate() {
                        let p = row!(r);
                        let mut xi = load!(p);
                        axpy!(xi, cj.add(nc + t), g);
                        store!(p, xi);
                    }
                    for (t, &r) in rows[own..].iter().enumerate() {
                        let p = top!(r);
                        let mut xi = load!(p);
                        axpy!(xi, cj.add(nc + own + t), g);
                        store!(p, xi);
                    }
                }
                for j in (lead..nc).step_by(4) {
                    let c = [lp.add(j * ld), lp.add((j + 1) * ld), lp.add((j + 2) * ld), lp.add((j + 3) * ld)];
                    // The group's triangle: g_u = (x_u − Σ_{v<u} L[j+u, j+v] g_v) / L[j+u, j+u].
                    let mut g = [[S::zero(); R]; 4];
                    for u in 0..4 {
                        let mut xu = load!(row!(c0 + j + u));
                        for v in 0..u {
                            axpy!(xu, c[v].add(j + u), g[v]);
                        }
                        if UNIT {
                            let mut stored = xu;
                            scale!(stored, *c[u].add(j + u));
                            store!(row!(c0 + j + u), stored);
                        } else {
                            scale!(xu, *c[u].add(j + u));
                            store!(row!(c0 + j + u), xu);
                        }
                        g[u] = xu;
                    }
                    // Every row below (diagonal block, then pattern) once with all four: two independent pairs.
                    macro_rules! update4 {
                        ($p:expr, $o:expr) => {{
                            let (p, o): (*mut f64, usize) = ($p, $o);
                            let a0 = S::splat(c[0].add(o));
                            let a1 = S::splat(c[1].add(o));
                            let a2 = S::splat(c[2].add(o));
                            let a3 = S::splat(c[3].add(o));
                            let mut xi = load!(p);
                            for q in 0..R {
                                let t = a1.neg_mul_add(g[1][q], a0.neg_mul_add(g[0][q], xi[q]));
                                let u = a3.mul_add(g[3][q], a2.mul(g[2][q]));
                                xi[q] = t.sub(u);
                            }
                            store!(p, xi);
                        }};
                    }
                    for i in j + 4..nc {
                        update4!(row!(c0 + i), i);
                    }
                    for (t, &r) in rows[..own].iter().enumerate() {
                        update4!(row!(r), nc + t);
                    }
                    for (t, &r) in rows[own..].iter().enumerate() {
                        update4!(top!(r), nc + own + t);
                    }
                }
            }
        }
    }

    /// The backward sweep (Lᵀ x = y) over supernodes `lo..hi`, in reverse: reads the rows of their patterns
    /// (final already: the range's ancestors are swept before it) and writes the range's own rows.
    ///
    /// # Safety
    /// As [`supernodal_solve`], for X at `x` (n rows of b, n the factor's). No other thread writes the rows read or
    /// touches the rows written meanwhile.
    #[inline(always)]
    unsafe fn backward<S: F64s, const R: usize, const UNIT: bool>(
        f: &SupernodalFactor<'_>,
        lo: usize,
        hi: usize,
        xp: *mut f64,
    ) {
        // SAFETY: as in `forward`, without redirected rows.
        unsafe {
            let b = S::LANES * R;
            macro_rules! row {
                ($r:expr) => {{
                    let r: usize = $r;
                    xp.add(r * b)
                }};
            }
            for s in (lo..hi).rev() {
                let sn = f.supernode(s);
                let (c0, rows, l) = (sn.start(), sn.pattern(), sn.val());
                let nc = l.ncols();
                let ld = nc + rows.len();
                let lp = l.as_ptr();
                let lead = nc % 4;
                for j in (lead..nc).step_by(4).rev() {
                    let c = [lp.add(j * ld), lp.add((j + 1) * ld), lp.add((j + 2) * ld), lp.add((j + 3) * ld)];
                    let mut acc = [
                        load!(row!(c0 + j)),
                        load!(row!(c0 + j + 1)),
                        load!(row!(c0 + j + 2)),
                        load!(row!(c0 + j + 3)),
                    ];
                    // Each row below gathered once into the four accumulators (independent FMA chains).
                    macro_rules! gather4 {
                        ($p:expr, $o:expr) => {{
                            let (p, o): (*mut f64, usize) = ($p, $o);
                            let xr = load!(p);
                            for u in 0..4 {
                                axpy!(acc[u], c[u].add(o), xr);
                            }
                        }};
                    }
                    for (t, &r) in rows.iter().enumerate() {
                        gather4!(row!(r), nc + t);
                    }
                    for i in j + 4..nc {
                        gather4!(row!(c0 + i), i);
                    }
                    // The group's triangle, last column first: x_u = (acc_u − Σ_{v>u} L[j+v, j+u] x_v) / L[j+u, j+u].
                    let mut xs = [[S::zero(); R]; 4];
                    for u in (0..4).rev() {
                        let mut xu = acc[u];
                        for v in u + 1..4 {
                            axpy!(xu, c[u].add(j + v), xs[v]);
                        }
                        if !UNIT {
                            scale!(xu, *c[u].add(j + u));
                        }
                        xs[u] = xu;
                        store!(row!(c0 + j + u), xu);
                    }
                }
                for j in (0..lead).rev() {
                    let cj = lp.add(j * ld);
                    let mut acc = load!(row!(c0 + j));
                    for (t, &r) in rows.iter().enumerate() {
                        let xr = load!(row!(r));
                        axpy!(acc, cj.add(nc + t), xr);
                    }
                    for i in j + 1..nc {
                        let xr = load!(row!(c0 + i));
                        axpy!(acc, cj.add(i), xr);
                    }
                    if !UNIT {
                        scale!(acc, *cj.add(j));
                    }
                    store!(row!(c0 + j), acc);
                }
            }
        }
    }
}

/// Solves L Lᵀ X = Y (or, with `UNIT`, L D Lᵀ X = Y for an LDLᵀ factor: unit diagonal in L, D on the diagonal)
/// in place for a supernodal factor, X given row-major in the factor's (permuted) numbering. For LDLᵀ the forward
/// sweep stores D⁻¹y for each solved row while it updates the rows below with y itself, so no third pass is needed.
///
/// Columns of a supernode are taken four at a time (the first `nc % 4` one by one). Forward: the group's 4 × 4
/// diagonal triangle, then every row below it (in the diagonal block and in the supernode's pattern) is updated once
/// with all four columns, whose solved rows of X stay in registers — four sequential streams of the factor and one
/// read-modify-write of X per row instead of four. Backward: each of the four columns gathers the rows below into
/// its own accumulator in one pass (independent FMA chains), then the group's triangle.
#[inline(always)]
fn supernodal_solve<const B: usize, const FMA: bool, const UNIT: bool>(f: &SupernodalFactor<'_>, x: &mut [[f64; B]]) {
    // x − a·y, fused where the CPU has FMA (the body is compiled twice, see `supernodal_solve_with`).
    let sub = |x: f64, a: f64, y: f64| if FMA { (-a).mul_add(y, x) } else { x - a * y };
    let ns = f.symbolic().n_supernodes();
    for s in 0..ns {
        let sn = f.supernode(s);
        let (c0, rows, l) = (sn.start(), sn.pattern(), sn.val());
        let nc = l.ncols();
        let col = |j: usize| l.col(j).try_as_col_major().expect("supernode columns are contiguous").as_slice();
        let lead = nc % 4;
        for j in 0..lead {
            let cj = col(j);
            let d = 1.0 / cj[j];
            let mut xj = x[c0 + j];
            let mut stored = xj;
            for (v, st) in xj.iter_mut().zip(stored.iter_mut()) {
                if UNIT {
                    *st *= d;
                } else {
                    *v *= d;
                    *st = *v;
                }
            }
            x[c0 + j] = stored;
            for (i, &a) in cj[j + 1..nc].iter().enumerate() {
                let xi = &mut x[c0 + j + 1 + i];
                for t in 0..B {
                    xi[t] = sub(xi[t], a, xj[t]);
                }
            }
            for (&r, &a) in rows.iter().zip(&cj[nc..]) {
                let xr = &mut x[r];
                for t in 0..B {
                    xr[t] = sub(xr[t], a, xj[t]);
                }
            }
        }
        for j in (lead..nc).step_by(4) {
            let c = [col(j), col(j + 1), col(j + 2), col(j + 3)];
            // The group's triangle: x_u = (x_u − Σ_{v<u} L[j+u, j+v] x_v) / L[j+u, j+u].
            let mut g = [[0.0f64; B]; 4];
            for u in 0..4 {
                let mut xu = x[c0 + j + u];
                for v in 0..u {
                    for t in 0..B {
                        xu[t] = sub(xu[t], c[v][j + u], g[v][t]);
                    }
                }
                let d = 1.0 / c[u][j + u];
                let mut stored = xu;
                for (v, st) in xu.iter_mut().zip(stored.iter_mut()) {
                    if UNIT {
                        *st *= d;
                    } else {
                        *v *= d;
                        *st = *v;
                    }
                }
                g[u] = xu;
                x[c0 + j + u] = stored;
            }
            let (g0, g1, g2, g3) = (g[0], g[1], g[2], g[3]);
            let (c0v, c1v, c2v, c3v) = (c[0], c[1], c[2], c[3]);
            for i in j + 4..nc {
                let (a0, a1, a2, a3) = (c0v[i], c1v[i], c2v[i], c3v[i]);
                let xr = &mut x[c0 + i];
                for t in 0..B {
                    xr[t] = sub(sub(sub(sub(xr[t], a0, g0[t]), a1, g1[t]), a2, g2[t]), a3, g3[t]);
                }
            }
            let (b0, b1, b2, b3) = (&c0v[nc..], &c1v[nc..], &c2v[nc..], &c3v[nc..]);
            for (p, &r) in rows.iter().enumerate() {
                let (a0, a1, a2, a3) = (b0[p], b1[p], b2[p], b3[p]);
                let xr = &mut x[r];
                for t in 0..B {
                    xr[t] = sub(sub(sub(sub(xr[t], a0, g0[t]), a1, g1[t]), a2, g2[t]), a3, g3[t]);
                }
            }
        }
    }
    for s in (0..ns).rev() {
        let sn = f.supernode(s);
        let (c0, rows, l) = (sn.start(), sn.pattern(), sn.val());
        let nc = l.ncols();
        let col = |j: usize| l.col(j).try_as_col_major().expect("supernode columns are contiguous").as_slice();
        let lead = nc % 4;
        for j in (lead..nc).step_by(4).rev() {
            let c = [col(j), col(j + 1), col(j + 2), col(j + 3)];
            let (mut p0, mut p1, mut p2, mut p3) = (x[c0 + j], x[c0 + j + 1], x[c0 + j + 2], x[c0 + j + 3]);
            let (c0v, c1v, c2v, c3v) = (c[0], c[1], c[2], c[3]);
            for i in j + 4..nc {
                let (a0, a1, a2, a3) = (c0v[i], c1v[i], c2v[i], c3v[i]);
                let xr = &x[c0 + i];
                for t in 0..B {
                    p0[t] = sub(p0[t], a0, xr[t]);
                    p1[t] = sub(p1[t], a1, xr[t]);
                    p2[t] = sub(p2[t], a2, xr[t]);
                    p3[t] = sub(p3[t], a3, xr[t]);
                }
            }
            let (b0, b1, b2, b3) = (&c0v[nc..], &c1v[nc..], &c2v[nc..], &c3v[nc..]);
            for (p, &r) in rows.iter().enumerate() {
                let (a0, a1, a2, a3) = (b0[p], b1[p], b2[p], b3[p]);
                let xr = &x[r];
                for t in 0..B {
                    p0[t] = sub(p0[t], a0, xr[t]);
                    p1[t] = sub(p1[t], a1, xr[t]);
                    p2[t] = sub(p2[t], a2, xr[t]);
                    p3[t] = sub(p3[t], a3, xr[t]);
                }
            }
            let acc = [p0, p1, p2, p3];
            // The group's triangle, last column first: x_u = (acc_u − Σ_{v>u} L[j+v, j+u] x_v) / L[j+u, j+u].
            for u in (0..4).rev() {
                let mut xu = acc[u];
                for v in u + 1..4 {
                    let xv = x[c0 + j + v];
                    for t in 0..B {
                        xu[t] = sub(xu[t], c[u][j + v], xv[t]);
                    }
                }
                if !UNIT {
                    let d = 1.0 / c[u][j + u];
                    for v in xu.iter_mut() {
                        *v *= d;
                    }
                }
                x[c0 + j + u] = xu;
            }
        }
        for j in (0..lead).rev() {
            let cj = col(j);
            let mut acc = x[c0 + j];
            for (&r, &a) in rows.iter().zip(&cj[nc..]) {
                let xr = &x[r];
                for t in 0..B {
                    acc[t] = sub(acc[t], a, xr[t]);
                }
            }
            for (i, &a) in cj[j + 1..nc].iter().enumerate() {
                let xi = &x[c0 + j + 1 + i];
                for t in 0..B {
                    acc[t] = sub(acc[t], a, xi[t]);
                }
            }
            if !UNIT {
                let d = 1.0 / cj[j];
                for v in acc.iter_mut() {
                    *v *= d;
                }
            }
            x[c0 + j] = acc;
        }
    }
}
