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
) -> Result<(Mat<f64>, f64), PdeError> {
    let n = basis.n();
    check_len("u0", u0.len(), n)?;
    if let Some(v) = v0 {
        check_len("v0", v.len(), n)?;
    }
    if times.iter().any(|t| !t.is_finite()) {
        return Err(PdeError::param("times", "times must be finite"));
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

/// The discrete energy of the wave `u` that [`wave`] returned for these inputs, at each time,
/// E(t) = ½(u̇ᵀM u̇ + uᵀL u), computed from the vertex values of u(t) and u̇(t) (so that its conservation, exact for
/// the modal solution, is checked to rounding).
pub fn wave_energy(
    basis: &Basis<'_>,
    pair: &SparsePair,
    u: MatRef<'_, f64>,
    (u0, v0): (&[f64], Option<&[f64]>),
    times: &[f64],
) -> Result<Vec<f64>, PdeError> {
    if u.nrows() != basis.n() || u.ncols() != times.len() {
        return Err(PdeError::param("u", "the wave of these times on this basis"));
    }
    let (a, _) = m_project(basis, pair, u0);
    let b = v0.map(|v| m_project(basis, pair, v).0).unwrap_or_else(|| vec![0.0; basis.k()]);
    // u̇(t) in the basis: the derivative of each mode.
    let wd = Mat::from_fn(basis.k(), times.len(), |i, j| {
        let t = times[j];
        if basis.is_zero(i) {
            b[i]
        } else {
            let om = basis.values[i].sqrt();
            -a[i] * om * (om * t).sin() + b[i] * (om * t).cos()
        }
    });
    let ud = basis.vectors * wd.as_ref();
    let n = basis.n();
    let (mut mu, mut lu) = (vec![0.0; n], vec![0.0; n]);
    Ok((0..times.len())
        .map(|j| {
            let uj: Vec<f64> = (0..n).map(|i| u[(i, j)]).collect();
            let vj: Vec<f64> = (0..n).map(|i| ud[(i, j)]).collect();
            crate::operators::sparse::matvec(&pair.pattern, &pair.mass, &vj, &mut mu);
            crate::operators::sparse::matvec(&pair.pattern, &pair.stiffness, &uj, &mut lu);
            let kinetic: f64 = vj.iter().zip(&mu).map(|(x, y)| x * y).sum();
            let potential: f64 = uj.iter().zip(&lu).map(|(x, y)| x * y).sum();
            0.5 * (kinetic + potential)
        })
        .collect())
}

/// ψ(t) of [`schrodinger`].
#[derive(Debug, Clone)]
pub struct Evolution {
    /// Re ψ, n × times.
    pub re: Mat<f64>,
    /// Im ψ, n × times.
    pub im: Mat<f64>,
    /// ‖ψ(t)‖_M at every time, computed from the vertex values (conserved up to rounding).
    pub norms: Vec<f64>,
    /// The M-norm of the part of ψ₀ outside the basis.
    pub dropped: f64,
}

/// The Schrödinger equation ∂ψ/∂t = −iΔψ (example 9.7) from ψ₀ = re + i·im, by unitary evolution in the computed
/// eigenbasis: ψ(t) = Σ_i e^{−iλ_i t} c_i φ_i with c = ΦᵀM ψ₀.
pub fn schrodinger(
    basis: &Basis<'_>,
    pair: &SparsePair,
    re0: &[f64],
    im0: Option<&[f64]>,
    times: &[f64],
) -> Result<Evolution, PdeError> {
    let n = basis.n();
    check_len("initial", re0.len(), n)?;
    if let Some(v) = im0 {
        check_len("initial_imag", v.len(), n)?;
    }
    if times.iter().any(|t| !t.is_finite()) {
        return Err(PdeError::param("times", "times must be finite"));
    }
    let phi = basis.vectors;
    let (a, dropped_re) = m_project(basis, pair, re0);
    let (b, dropped_im) = match im0 {
        Some(v) => m_project(basis, pair, v),
        None => (vec![0.0; basis.k()], 0.0),
    };
    // (a + ib)(cos λt − i sin λt) = (a cos + b sin) + i (b cos − a sin).
    let (wr, wi) = (
        Mat::from_fn(basis.k(), times.len(), |i, j| {
            let (s, c) = (basis.values[i] * times[j]).sin_cos();
            a[i] * c + b[i] * s
        }),
        Mat::from_fn(basis.k(), times.len(), |i, j| {
            let (s, c) = (basis.values[i] * times[j]).sin_cos();
            b[i] * c - a[i] * s
        }),
    );
    let (re, im) = (phi * wr.as_ref(), phi * wi.as_ref());
    let mut norms = vec![];
    let mut m_col = vec![0.0; n];
    for j in 0..times.len() {
        let mut sum = 0.0;
        for part in [&re, &im] {
            let col: Vec<f64> = (0..n).map(|x| part[(x, j)]).collect();
            matvec(&pair.pattern, &pair.mass, &col, &mut m_col);
            sum += col.iter().zip(&m_col).map(|(u, v)| u * v).sum::<f64>();
        }
        norms.push(sum.max(0.0).sqrt());
    }
    Ok(Evolution { re, im, norms, dropped: dropped_re.hypot(dropped_im) })
}
