//! The wave equation ∂²u/∂t² = −Δu by modal superposition.

use super::*;

/// The wave equation ∂²u/∂t² = −Δu (example 9.7) from u₀ with velocity v₀, by modal superposition over the computed
/// eigenpairs (the chapter's (9.4)): u(t) = Σ_i [a_i cos(ω_i t) + b_i sin(ω_i t)/ω_i] φ_i with ω_i = √λ_i,
/// a = ΦᵀM u₀, b = ΦᵀM v₀ (zero modes: a_i + b_i t). Energy is conserved exactly; the part of u₀ outside the
/// basis is dropped (its M-norm is returned).
pub fn wave(
    basis: &Basis<'_>,
    pair: &SparsePair,
    u0: &[f64],
    v0: Option<&[f64]>,
    times: &[f64],
) -> Result<(Mat<f64>, f64), DescriptorError> {
    let n = basis.n();
    check_len("u0", u0.len(), n)?;
    if let Some(v) = v0 {
        check_len("v0", v.len(), n)?;
    }
    if times.iter().any(|t| !t.is_finite()) {
        return Err(DescriptorError::param("times", "times must be finite"));
    }
    let phi = basis.vectors;
    let (a, dropped) = m_project(basis, pair, u0);
    let b = v0.map(|v| m_project(basis, pair, v).0).unwrap_or_else(|| vec![0.0; basis.k()]);
    let w = Mat::from_fn(basis.k(), times.len(), |i, j| {
        let t = times[j];
        if basis.is_zero(i) {
            a[i] + b[i] * t
        } else {
            let om = basis.values[i].sqrt();
            a[i] * (om * t).cos() + b[i] * (om * t).sin() / om
        }
    });
    Ok((phi * w.as_ref(), dropped))
}
