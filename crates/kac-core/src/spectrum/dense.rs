//! Dense generalized symmetric eigensolver for small problems: M = RRᵀ, C = R⁻¹ L R⁻ᵀ, C = U Λ Uᵀ, Φ = R⁻ᵀ U.

use super::small_dense::{cholesky_lower, symmetric_eigen};
use super::{EigenError, Spectrum, Stats, Timings};
use crate::operators::sparse::SparsePair;
use faer::linalg::triangular_solve::{solve_lower_triangular_in_place, solve_upper_triangular_in_place};
use faer::{Mat, Par};
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
