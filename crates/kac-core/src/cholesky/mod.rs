//! The sparse Cholesky (and LDLᵀ) factor of a pencil's shifted matrix K = L − σM: the symbolic analysis kept apart
//! from the numeric factorization ([`factor`]), the numeric factorization in pieces that a stop flag can end and
//! threads can share ([`numeric`]), and the split of the supernodal elimination tree into subtrees ([`tree`]).
//!
//! Below the solvers that factor (`spectrum`, `pde`, `descriptors`, the operators' property report) and above the
//! sparse storage (`operators::sparse`) and the kernels (`simd`) only; `spectrum` re-exports these modules at
//! `spectrum::factor`, `spectrum::numeric` and `spectrum::tree`.

pub mod factor;
pub mod numeric;
pub mod tree;
