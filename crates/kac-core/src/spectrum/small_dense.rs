//! Dense factorizations of the solvers' small matrices (Gram matrices, projected pencils, the dense solver's
//! pencil): Cholesky and the symmetric eigendecomposition, on the threads a solve was given. The eigensolvers
//! (`dense`, `lanczos`, `null_space`, `slicing`) all use these; this module uses none of them.

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::{Mat, MatRef, Par};

/// The lower Cholesky factor of the symmetric matrix whose lower triangle is `a`, on `par`'s threads (faer's
/// `Mat::llt` takes the process-wide parallelism, the whole pool, instead of the threads a solve was given).
pub(crate) fn cholesky_lower(
    a: MatRef<'_, f64>,
    par: Par,
) -> Result<Mat<f64>, faer::linalg::cholesky::llt::factor::LltError> {
    use faer::linalg::cholesky::llt::factor::{cholesky_in_place, cholesky_in_place_scratch};
    let n = a.nrows();
    let mut l = Mat::<f64>::zeros(n, n);
    l.copy_from_triangular_lower(a);
    let mut mem = MemBuffer::new(cholesky_in_place_scratch::<f64>(n, par, Default::default()));
    cholesky_in_place(l.as_mut(), Default::default(), par, MemStack::new(&mut mem), Default::default())?;
    for j in 1..n {
        l.as_mut().col_mut(j).subrows_mut(0, j).fill(0.0);
    }
    Ok(l)
}

/// The eigenvalues (ascending) and eigenvectors (columns) of the symmetric matrix whose lower triangle is `a`, on
/// `par`'s threads (faer's `self_adjoint_eigen` takes the process-wide parallelism instead).
pub(crate) fn symmetric_eigen(
    a: MatRef<'_, f64>,
    par: Par,
) -> Result<(Vec<f64>, Mat<f64>), faer::linalg::evd::EvdError> {
    use faer::linalg::evd::{self_adjoint_evd, self_adjoint_evd_scratch, ComputeEigenvectors};
    let n = a.nrows();
    let mut u = Mat::<f64>::zeros(n, n);
    let mut s = faer::diag::Diag::<f64>::zeros(n);
    let mut mem = MemBuffer::new(self_adjoint_evd_scratch::<f64>(n, ComputeEigenvectors::Yes, par, Default::default()));
    self_adjoint_evd(a, s.as_mut(), Some(u.as_mut()), par, MemStack::new(&mut mem), Default::default())?;
    Ok(((0..n).map(|i| s[i]).collect(), u))
}
