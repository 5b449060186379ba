//! Heat diffusion by backward Euler, (M + τL) u_{j+1} = M u_j.

use super::*;

/// The discrete delta at unknown `s`: u = M⁻¹e_s, the function whose M-inner product with any φ is φ(s). Its heat
/// flow is the heat kernel k_t(·, s) (the spectral form Σ e^{−λt} φ(s) φ).
pub fn discrete_delta(pair: &SparsePair, s: usize) -> Result<Vec<f64>, PdeError> {
    let n = pair.n();
    if s >= n {
        return Err(PdeError::param("source", format!("{s} is not one of the {n} unknowns")));
    }
    let e = Mat::from_fn(n, 1, |i, _| if i == s { 1.0 } else { 0.0 });
    let u = super::solve_spd(&pair.pattern, &pair.mass, e.as_ref(), None)?;
    Ok(u.col(0).iter().copied().collect())
}

/// Heat diffusion ∂u/∂t = −Δu (eq. 9.23), M u̇ = −L u, by backward Euler: for each t, `steps` steps
/// (M + τL) u_{j+1} = M u_j with τ = t/steps from u₀ (one factorization per distinct τ, one symbolic analysis in
/// all). Each mode is multiplied by (1 + τλ)^{−steps} → e^{−λt}: it decays, never grows. Unconditionally stable;
/// first-order in τ.
pub fn heat_implicit(pair: &SparsePair, u0: &[f64], times: &[f64], steps: usize) -> Result<Mat<f64>, PdeError> {
    let n = pair.n();
    check_len("u0", u0.len(), n)?;
    crate::descriptors::check_times("times", times)?;
    if steps == 0 {
        return Err(PdeError::param("steps", "at least one step"));
    }
    let sym = PdeError::analyze(&pair.pattern)?;
    let mut out = Mat::<f64>::zeros(n, times.len());
    let mut mu = vec![0.0; n];
    for (c, &t) in times.iter().enumerate() {
        let tau = t / steps as f64;
        let k: Vec<f64> = pair.mass.iter().zip(&pair.stiffness).map(|(m, l)| m + tau * l).collect();
        let chol = Cholesky::factor(&sym, &k, Par::Seq).map_err(solve_err)?;
        let mut u = u0.to_vec();
        for _ in 0..steps {
            matvec(&pair.pattern, &pair.mass, &u, &mut mu);
            let mut x = Mat::from_fn(n, 1, |i, _| mu[i]);
            chol.solve_in_place(x.as_mut(), Par::Seq);
            u.iter_mut().enumerate().for_each(|(i, v)| *v = x[(i, 0)]);
        }
        out.col_mut(c).iter_mut().zip(&u).for_each(|(o, v)| *o = *v);
    }
    Ok(out)
}
