//! Sparse Cholesky of K = L − σM through faer's supernodal factorization, with the symbolic analysis (AMD
//! ordering, elimination tree, supernodes) kept apart so that the same pattern with another shift or another
//! mass never redoes it.

use crate::operators::sparse::{Pattern, SparsePair};
use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::cholesky::llt::factor::LltRegularization;
use faer::sparse::linalg::cholesky::{factorize_symbolic_cholesky, LltRef, SymbolicCholesky, SymmetricOrdering};
use faer::sparse::SparseColMatRef;
use faer::{Conj, MatMut, Par, Side};
use std::sync::Arc;

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

/// A numeric Cholesky factor of a symmetric positive definite matrix on a symbolic analysis.
pub struct Cholesky {
    symbolic: Symbolic,
    values: Vec<f64>,
}

impl Cholesky {
    /// Factors the matrix with `values` on the analysed pattern; `Err` if it is not numerically positive definite.
    pub fn factor(symbolic: &Symbolic, values: &[f64], par: Par) -> Result<Self, String> {
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
        Ok(Cholesky { symbolic: symbolic.clone(), values: l })
    }
    /// Solves K X = B in place for every column of `rhs`.
    pub fn solve_in_place(&self, rhs: MatMut<'_, f64>, par: Par) {
        let s = &self.symbolic.inner;
        let mut mem = MemBuffer::new(s.solve_in_place_scratch::<f64>(rhs.ncols(), par));
        LltRef::<'_, usize, f64>::new(s, &self.values).solve_in_place_with_conj(
            Conj::No,
            rhs,
            par,
            MemStack::new(&mut mem),
        );
    }
    /// log det K = 2 Σ log L_jj from the factor's diagonal (the ordering does not change the determinant).
    pub fn log_det(&self) -> f64 {
        use faer::sparse::linalg::cholesky::{supernodal::SupernodalLltRef, SymbolicCholeskyRaw};
        match self.symbolic.inner.raw() {
            SymbolicCholeskyRaw::Simplicial(s) => {
                let (cp, ri) = (s.col_ptr(), s.row_idx());
                (0..s.ncols())
                    .map(|j| {
                        debug_assert_eq!(ri[cp[j]], j, "the diagonal leads each column of a simplicial factor");
                        2.0 * self.values[cp[j]].ln()
                    })
                    .sum()
            }
            SymbolicCholeskyRaw::Supernodal(s) => {
                let f = SupernodalLltRef::<'_, usize, f64>::new(s, &self.values);
                (0..s.n_supernodes())
                    .map(|sn| {
                        let block = f.supernode(sn).val();
                        (0..block.ncols()).map(|j| 2.0 * block[(j, j)].ln()).sum::<f64>()
                    })
                    .sum()
            }
        }
    }
    /// Entries of the factor (a measure of fill-in).
    pub fn factor_nnz(&self) -> usize {
        self.values.len()
    }
}
