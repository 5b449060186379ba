//! The shift σ and the factor of L − σM: below the spectrum by default, inside it by Weyl's law, checked by its
//! inertia and a test solve's backward error.

use super::block::Rng;
use super::Run;
use crate::cholesky::factor::{Cholesky, Symbolic};
use crate::cholesky::numeric::FactorError;
use crate::operators::sparse::SparsePair;
use crate::spectrum::{Control, EigenError, EigenOptions};
use faer::{MatMut, Par};

/// The default shift: σ = −mean_j(L_jj / M_jj) / n. The mean diagonal ratio scales like the top of the
/// spectrum (≈ c/h² ≈ c·n/area on a surface), so σ lands near the bottom of the spectrum (about λ₁/4 on a
/// unit sphere), far from the null space: a shift much closer to 0 makes the null modes dominate T and costs
/// the small Ritz values digits (measured: 10⁻⁸ relative with σ = −10⁻⁶·mean, 10⁻¹³ with this σ).
pub fn default_sigma(pair: &SparsePair) -> f64 {
    let n = pair.n();
    let mut s = 0.0;
    for j in 0..n {
        let d = pair.pattern.diag_pos(j);
        if pair.mass[d] > 0.0 {
            s += pair.stiffness[d].abs() / pair.mass[d];
        }
    }
    let scale = s / n.max(1) as f64;
    -(if scale > 0.0 && scale.is_finite() { scale } else { 1.0 }) / n.max(1) as f64
}

/// Where the shift goes, as a fraction of Weyl's estimate of λ_k: the wanted eigenvalues below σ become the most
/// negative θ = 1/(λ − σ) and those above it the largest positive ones, so the unwanted rest (above λ_k) is squeezed
/// into (0, 1/(λ_{k+1} − σ)], far from both ends. Measured on the unit icosphere (10k vertices, k = 50, λ_50 = 56):
/// 38 block steps at σ < 0, 28 at σ = 30, 24 at σ = 40, 26 at σ = 45, 30 at σ = 50; balancing the two ends'
/// relative gaps puts the optimum near 0.7 λ_k. Weyl's leading term is 50 there (σ = 35, 26 steps); it
/// overestimates λ_k where a free boundary adds eigenvalues (N(λ) gains |∂Ω|√λ/4π under Neumann conditions: the
/// unit square's λ_50 is 484 against 628), which is why the fraction is not taken higher.
pub const WEYL_FRACTION: f64 = 0.7;

/// Below this k the shift stays below the spectrum (a handful of pairs converge in a few steps either way).
pub(super) const INTERIOR_MIN_K: usize = 8;

/// The largest backward error ‖K x − b‖ / (‖K‖_∞ ‖x‖ + ‖b‖) accepted from a test solve with an LDLᵀ factor (no
/// pivoting): solves with LDLᵀ factors at the Weyl shift measure 10⁻¹⁶–10⁻¹⁴ on 2.5k–164k-vertex spheres; above
/// this the factor grew and the default shift below the spectrum (Cholesky) is used instead.
pub(super) const LDLT_BACKWARD_ERROR: f64 = 1e-12;

/// Where else in a slice's window [lo, hi] σ is tried, as fractions of the window, when the factor at its planned
/// shift is not backward stable.
pub(super) const WINDOW_SHIFTS: [f64; 4] = [0.4, 0.6, 0.3, 0.7];

/// The shift inside the spectrum from Weyl's law, σ = 0.7·λ̂_k with λ̂_k = (2π)² (k / (ω_d |Ω|))^{2/d} and |Ω| = 1ᵀM1
/// (see [`WEYL_FRACTION`]); `None` for operators without a dimension (graphs) or small k.
pub fn weyl_shift(pair: &SparsePair, k: usize) -> Option<f64> {
    let d = pair.dimension?;
    let measure: f64 = pair.mass.iter().sum();
    if k < INTERIOR_MIN_K || !(measure > 0.0) || !measure.is_finite() {
        return None;
    }
    let s = WEYL_FRACTION * crate::spectrum::weyl_law::weyl_eigenvalue(d, measure, k as f64);
    (s > 0.0 && s.is_finite()).then_some(s)
}

/// K = L − σM factored, with what the factorization says about the spectrum.
pub(super) struct Shifted {
    pub(super) sigma: f64,
    pub(super) factor: Cholesky,
    /// Eigenvalues below σ (the LDLᵀ inertia); `None` for a Cholesky factor (σ below the spectrum).
    pub(super) below_sigma: Option<usize>,
}

/// Chooses σ and factors L − σM. An explicit σ is used as given (Cholesky when negative, LDLᵀ otherwise). Else,
/// where the operator has a dimension, σ goes inside the spectrum by Weyl's law ([`weyl_shift`]) and L − σM is
/// factored as LDLᵀ: accepted when its inertia puts at most k eigenvalues below σ and a test solve is backward
/// stable; with more than k below, σ is lowered once as if N(λ) grew like √λ (thin shapes, whose low spectrum is
/// one-dimensional, are what Weyl's two- or three-dimensional law overestimates). Otherwise, and as the last
/// resort, σ = [`default_sigma`] below the spectrum with a Cholesky factor, multiplied by 100 while a pivot fails.
pub(super) fn factor_shift(
    pair: &SparsePair,
    o: &EigenOptions,
    sym: &Symbolic,
    par: Par,
    run: &Run<'_>,
    control: &Control<'_>,
) -> Result<Shifted, EigenError> {
    // A stop ends the solve; any other failure of a factorization names its shift.
    let failed = |sigma: f64, e: FactorError| match e {
        FactorError::Stopped => EigenError::Canceled,
        FactorError::Failed(message) => EigenError::Factorization { message: format!("σ = {sigma:e}: {message}") },
    };
    let stop = control.stop;
    if let Some(w) = &run.window {
        // σ at the window's planned shift, else elsewhere inside the window: whether an LDLᵀ factor is backward
        // stable depends on σ and on the elimination order (one vertex numbering of a mesh is stable where another
        // is not), and any σ inside the window serves the slice.
        let a = if w.lo.is_finite() { w.lo } else { 0.0 };
        let b = if w.hi.is_finite() { w.hi } else { 2.0 * w.sigma - a };
        let mut tries: Vec<f64> = vec![];
        for sigma in std::iter::once(w.sigma).chain(WINDOW_SHIFTS.iter().map(|f| a + f * (b - a))) {
            // Each shift once (the first slice's planned shift is one of the fractions).
            if sigma.is_finite() && sigma > a && sigma < b && tries.iter().all(|t| (t - sigma).abs() > 1e-12 * b.abs())
            {
                tries.push(sigma);
            }
        }
        let mut last = None;
        for sigma in tries {
            control.check()?;
            let values = pair.shifted(sigma);
            // A failed factorization (a zero pivot) is tried elsewhere too; only a stop ends the search.
            let (factor, below) = match Cholesky::factor_ldlt_stoppable(sym, &values, par, stop) {
                Ok(f) => f,
                Err(FactorError::Stopped) => return Err(EigenError::Canceled),
                Err(FactorError::Failed(message)) => {
                    last = Some(format!("σ = {sigma:e}: {message}"));
                    continue;
                }
            };
            let e = solve_backward_error(pair, &values, &factor, par);
            if e <= LDLT_BACKWARD_ERROR {
                return Ok(Shifted { sigma, factor, below_sigma: Some(below) });
            }
            last = Some(format!("σ = {sigma:e}: the LDLᵀ factor is not backward stable ({e:.1e})"));
        }
        return Err(EigenError::Factorization {
            message: last.unwrap_or_else(|| format!("σ = {:e} lies outside its window", w.sigma)),
        });
    }
    if let Some(sigma) = o.sigma {
        if sigma < 0.0 {
            let factor =
                Cholesky::factor_stoppable(sym, &pair.shifted(sigma), par, stop).map_err(|e| failed(sigma, e))?;
            return Ok(Shifted { sigma, factor, below_sigma: None });
        }
        let (factor, below) =
            Cholesky::factor_ldlt_stoppable(sym, &pair.shifted(sigma), par, stop).map_err(|e| failed(sigma, e))?;
        return Ok(Shifted { sigma, factor, below_sigma: Some(below) });
    }
    let interior = if run.interior_shift { weyl_shift(pair, o.k + run.deflated_values.len()) } else { None };
    if let Some(mut sigma) = interior {
        for _attempt in 0..2 {
            control.check()?;
            let values = pair.shifted(sigma);
            let (factor, below) = match Cholesky::factor_ldlt_stoppable(sym, &values, par, stop) {
                Ok(f) => f,
                Err(FactorError::Stopped) => return Err(EigenError::Canceled),
                Err(FactorError::Failed(_)) => break,
            };
            let undeflated = below.saturating_sub(run.deflated_below(sigma));
            if undeflated > o.k {
                sigma *= WEYL_FRACTION * (o.k as f64 / undeflated as f64).powi(2);
                continue;
            }
            if solve_backward_error(pair, &values, &factor, par) <= LDLT_BACKWARD_ERROR {
                return Ok(Shifted { sigma, factor, below_sigma: Some(below) });
            }
            break;
        }
    }
    let mut sigma = default_sigma(pair);
    let mut attempt = 0;
    loop {
        control.check()?;
        match Cholesky::factor_stoppable(sym, &pair.shifted(sigma), par, stop) {
            Ok(factor) => return Ok(Shifted { sigma, factor, below_sigma: None }),
            Err(FactorError::Stopped) => return Err(EigenError::Canceled),
            Err(message) => {
                attempt += 1;
                if attempt >= 4 {
                    return Err(failed(sigma, message));
                }
                sigma *= 100.0;
            }
        }
    }
}

/// Backward error ‖K x − b‖₂ / (‖K‖_∞ ‖x‖₂ + ‖b‖₂) of one solve with `factor` (K's values on the pair's pattern)
/// for a fixed pseudo-random b.
pub(crate) fn solve_backward_error(pair: &SparsePair, values: &[f64], factor: &Cholesky, par: Par) -> f64 {
    let n = pair.n();
    let mut rng = Rng(0x5eed);
    let rhs: Vec<f64> = (0..n).map(|_| rng.next()).collect();
    let mut x = rhs.clone();
    factor.solve_in_place(MatMut::from_column_major_slice_mut(&mut x, n, 1), par);
    let mut kx = vec![0.0; n];
    crate::operators::sparse::matvec_on(&pair.pattern, values, &x, &mut kx, par.degree());
    let norm = |v: &[f64]| v.iter().map(|a| a * a).sum::<f64>().sqrt();
    let r: Vec<f64> = kx.iter().zip(&rhs).map(|(a, b)| a - b).collect();
    let k_inf = (0..n)
        .map(|j| (pair.pattern.col_ptr[j]..pair.pattern.col_ptr[j + 1]).map(|p| values[p].abs()).sum::<f64>())
        .fold(0.0, f64::max);
    let e = norm(&r) / (k_inf * norm(&x) + norm(&rhs));
    if e.is_finite() {
        e
    } else {
        f64::INFINITY
    }
}
