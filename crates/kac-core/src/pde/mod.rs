//! The chapter's PDE tools on a discrete operator pair (L, M). Sign: Δ = −∇·∇ (eq. 9.7), positive semidefinite;
//! L is its weak form, the stiffness matrix L_ij = ∫ ∇ψ_i·∇ψ_j (L ⪰ 0, libigl's `cotmatrix` is −L), and M the mass,
//! so "Δf = g" means L f = M g (§9.5, Galerkin FEM) and eigenpairs Δφ = λφ, λ ≥ 0, are L φ = λ M φ. Each tool
//! solves sparse symmetric positive definite systems by Cholesky (faer), reusing one symbolic analysis where a tool
//! factors several matrices on the same pattern.
//!
//! | tool | equation (Δ ⪰ 0) | discrete system |
//! |---|---|---|
//! | [`smooth`] | u + αΔu = ū (exercise 9.4, eq. 9.40) | (M + αL) u = M ū |
//! | [`heat_implicit`] | ∂u/∂t = −Δu (eq. 9.23, α = 1) | backward Euler (M + τL) u_{j+1} = M u_j, τ = t/steps |
//! | [`harmonic`] | Δu = 0 (§9.2.2), u given on a vertex set | L_II u_I = −L_IB u_B |
//! | [`labels`] | harmonic functions of one-hot labels (Zhu, Ghahramani & Lafferty 2003) | as above, argmax |
//! | [`poisson`] | Δf = g (§9.5) | L f = M g (Neumann: g made compatible, f of mean zero) |
//! | [`wave`] | ∂²u/∂t² = −Δu (example 9.7) | modal superposition over computed eigenpairs (as in eq. 9.4) |
//! | [`geodesic::heat_method`] | distance from heat (Crane, Weischedel & Wardetzky 2013) | two solves |
//!
//! So heat decays (e^{−λt} per mode), waves oscillate (cos √λ t per mode) and on the unit sphere a degree-l
//! spherical harmonic Y_l (Δ Y_l = l(l+1) Y_l) solves Poisson as f = Y_l / (l(l+1)).
//!
//! "Fixed" vertices (Dirichlet data) are eliminated, never replaced by identity rows.

pub mod calculus;
mod error;
pub mod geodesic;

pub use error::PdeError;

use crate::cholesky::factor::Cholesky;
use crate::descriptors::{graph::components, m_project, Basis};
use crate::operators::sparse::{matvec, submatrix, Pattern, SparsePair};
use faer::{Mat, MatRef, Par};
use serde::Serialize;
use std::sync::Arc;

mod diffusion;
mod interpolation;
mod poisson_eq;
mod smoothing;
mod waves;

pub use diffusion::*;
pub use interpolation::*;
pub use poisson_eq::*;
pub use smoothing::*;
pub use waves::*;

pub(crate) fn solve_err(message: String) -> PdeError {
    PdeError::Solve { message }
}

/// Solves K X = B for the rows not fixed, with X = G on the fixed rows: K_FF… eliminated, K_II X_I = B_I − K_IF G_F.
/// `values` are K's entries on `pattern`; the free block must be positive definite.
pub fn solve_spd(
    pattern: &Arc<Pattern>,
    values: &[f64],
    rhs: MatRef<'_, f64>,
    fixed: Option<(&[bool], MatRef<'_, f64>)>,
) -> Result<Mat<f64>, PdeError> {
    let n = pattern.n;
    let c = rhs.ncols();
    let Some((mask, g)) = fixed.filter(|(m, _)| m.iter().any(|&x| x)) else {
        let sym = PdeError::analyze(pattern)?;
        let chol = Cholesky::factor(&sym, values, Par::Seq).map_err(solve_err)?;
        let mut x = rhs.to_owned();
        chol.solve_in_place(x.as_mut(), Par::Seq);
        return Ok(x);
    };
    let free: Vec<usize> = (0..n).filter(|&i| !mask[i]).collect();
    let mut out = Mat::<f64>::zeros(n, c);
    for i in (0..n).filter(|&i| mask[i]) {
        for j in 0..c {
            out[(i, j)] = g[(i, j)];
        }
    }
    if free.is_empty() {
        return Ok(out);
    }
    let mut index = vec![usize::MAX; n];
    for (k, &i) in free.iter().enumerate() {
        index[i] = k;
    }
    let mut b = Mat::from_fn(free.len(), c, |k, j| rhs[(free[k], j)]);
    for f in (0..n).filter(|&i| mask[i]) {
        for pos in pattern.col_ptr[f]..pattern.col_ptr[f + 1] {
            let k = index[pattern.row_idx[pos]];
            if k != usize::MAX {
                for j in 0..c {
                    b[(k, j)] -= values[pos] * g[(f, j)];
                }
            }
        }
    }
    let (sub, vals) = submatrix(pattern, &[values], &free);
    let sub = Arc::new(sub);
    let sym = PdeError::analyze(&sub)?;
    let chol = Cholesky::factor(&sym, &vals[0], Par::Seq).map_err(solve_err)?;
    chol.solve_in_place(b.as_mut(), Par::Seq);
    for (k, &i) in free.iter().enumerate() {
        for j in 0..c {
            out[(i, j)] = b[(k, j)];
        }
    }
    Ok(out)
}

pub(crate) fn mass_times(pair: &SparsePair, u: MatRef<'_, f64>) -> Mat<f64> {
    let n = pair.n();
    let mut out = Mat::<f64>::zeros(n, u.ncols());
    let mut y = vec![0.0; n];
    for j in 0..u.ncols() {
        let x: Vec<f64> = u.col(j).iter().copied().collect();
        matvec(&pair.pattern, &pair.mass, &x, &mut y);
        out.col_mut(j).iter_mut().zip(&y).for_each(|(o, v)| *o = *v);
    }
    out
}

pub(crate) fn check_len(name: &'static str, got: usize, n: usize) -> Result<(), PdeError> {
    if got != n {
        return Err(PdeError::param(name, format!("{got} values for {n} vertices")));
    }
    Ok(())
}

pub(crate) fn check_positive(name: &'static str, v: f64) -> Result<(), PdeError> {
    if !(v > 0.0 && v.is_finite()) {
        return Err(PdeError::param(name, format!("{v} is not a positive finite number")));
    }
    Ok(())
}
