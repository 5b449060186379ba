//! Implicit smoothing (M + αL) u = M ū.

use super::*;

/// Smoothing (exercise 9.4): the minimizer of ∫ (u − ū)² + α |∇u|² (eq. 9.40), i.e. u + αΔu = ū, discretely
/// (M + αL) u = M ū, for each column of `ubar`; each mode is damped by 1/(1 + αλ). With `fixed`, those vertices
/// keep ū (a clamped boundary); then, as L annihilates linear functions at interior vertices of a flat mesh
/// (linear precision), a linear ū is reproduced exactly.
pub fn smooth(
    pair: &SparsePair,
    ubar: MatRef<'_, f64>,
    alpha: f64,
    fixed: Option<&[bool]>,
) -> Result<Mat<f64>, PdeError> {
    check_len("u", ubar.nrows(), pair.n())?;
    check_positive("alpha", alpha)?;
    let k: Vec<f64> = pair.mass.iter().zip(&pair.stiffness).map(|(m, l)| m + alpha * l).collect();
    let rhs = mass_times(pair, ubar);
    solve_spd(&pair.pattern, &k, rhs.as_ref(), fixed.map(|f| (f, ubar)))
}
