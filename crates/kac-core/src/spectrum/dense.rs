//! Dense generalized symmetric eigensolver for small problems: M = RRᵀ, C = R⁻¹ L R⁻ᵀ, C = U Λ Uᵀ, Φ = R⁻ᵀ U.

use super::{EigenError, Spectrum, Stats, Timings};
use crate::operators::sparse::SparsePair;
use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::triangular_solve::{solve_lower_triangular_in_place, solve_upper_triangular_in_place};
use faer::{Mat, MatRef, Par};
use std::time::Instant;

fn to_dense(pair: &SparsePair, values: &[f64]) -> Mat<f64> {
    let n = pair.n();
    let p = &pair.pattern;
    let mut a = Mat::<f64>::zeros(n, n);
    for j in 0..n {
        for pos in p.col_ptr[j]..p.col_ptr[j + 1] {
            a[(p.row_idx[pos], j)] = values[pos];
        }
    }
    a
}

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

/// Every eigenpair of the dense pencil, the k smallest kept, on `par`'s threads.
pub fn eigs_dense(pair: &SparsePair, k: usize, par: Par) -> Result<Spectrum, EigenError> {
    let t0 = Instant::now();
    let n = pair.n();
    let l = to_dense(pair, &pair.stiffness);
    let m = to_dense(pair, &pair.mass);
    let chol = cholesky_lower(m.as_ref(), par).map_err(|e| EigenError::Factorization {
        message: format!("the mass matrix is not positive definite ({e:?})"),
    })?;
    let r = chol.as_ref();
    // C = R⁻¹ L R⁻ᵀ: solve R X = L, then R Cᵀ = Xᵀ.
    let mut x = l.clone();
    solve_lower_triangular_in_place(r, x.as_mut(), par);
    let mut c = x.transpose().to_owned();
    solve_lower_triangular_in_place(r, c.as_mut(), par);
    let c = Mat::from_fn(n, n, |i, j| 0.5 * (c[(i, j)] + c[(j, i)]));
    let (s, u) = symmetric_eigen(c.as_ref(), par)
        .map_err(|e| EigenError::Factorization { message: format!("dense eigensolver failed ({e:?})") })?;
    let mut phi = u.subcols(0, k).to_owned();
    solve_upper_triangular_in_place(r.transpose(), phi.as_mut(), par);
    let values = s[..k].to_vec();
    let total = t0.elapsed().as_secs_f64();
    Ok(Spectrum {
        values,
        vectors: phi,
        residuals: vec![],
        stats: Stats {
            method: "dense",
            sigma: super::lanczos::default_sigma(pair),
            block: 0,
            subspace: n,
            restarts: 0,
            block_steps: 0,
            solves: 0,
            factor_nnz: n * (n + 1) / 2,
            factorization: "cholesky",
            below_sigma: None,
            symbolic_reused: false,
            timings: Timings { iteration_s: total, total_s: total, ..Default::default() },
            ..Default::default()
        },
    })
}
