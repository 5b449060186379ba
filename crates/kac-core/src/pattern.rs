//! The compressed-column pattern of a symmetric sparse matrix: vocabulary below both the operators
//! (`operators::sparse`, whose stiffness and mass share one) and the matrix writers (`io::matrix`). Depends on faer
//! only.

use faer::sparse::SymbolicSparseColMatRef;

/// A symmetric sparsity pattern in compressed-column form.
#[derive(Debug, Clone, PartialEq)]
pub struct Pattern {
    pub n: usize,
    pub col_ptr: Vec<usize>,
    pub row_idx: Vec<usize>,
}

impl Pattern {
    pub fn nnz(&self) -> usize {
        self.row_idx.len()
    }
    /// Rows of column `j`.
    pub fn col(&self, j: usize) -> &[usize] {
        &self.row_idx[self.col_ptr[j]..self.col_ptr[j + 1]]
    }
    /// Position of the diagonal entry of column `j`.
    pub fn diag_pos(&self, j: usize) -> usize {
        self.col_ptr[j] + self.col(j).binary_search(&j).expect("the diagonal is always stored")
    }
    pub fn faer(&self) -> SymbolicSparseColMatRef<'_, usize> {
        // SAFETY-free: checked construction (sorted rows, valid pointers).
        SymbolicSparseColMatRef::new_checked(self.n, self.n, &self.col_ptr, None, &self.row_idx)
    }
}
