//! The heat kernel read from the spectrum: k_t(x, y) = Σ_i e^{−λ_i t} φ_i(x) φ_i(y) (φ_i M-orthonormal, eq. 9.26),
//! the heat trace Z(t) = Σ_i e^{−λ_i t}, spectral heat diffusion of a function with a bound on what the
//! truncation to k eigenpairs leaves out, and the heat content of a Dirichlet problem.
//!
//! Sign: the heat equation is ∂u/∂t = −Δu (eq. 9.23 with α = 1; 9.25 for the kernel), Δ = −∇·∇ positive
//! semidefinite, discretely M u̇ = −L u with L the stiffness matrix (L φ = λ M φ, λ ≥ 0): every mode decays as
//! e^{−λt}, and on the unit sphere a degree-l harmonic as e^{−l(l+1)t}.
//!
//! Truncation: write u₀ = Σ_{i≤k} c_i φ_i + r with r M-orthogonal to the computed eigenvectors. Every eigenvalue
//! not computed is at least λ_k (the largest computed), so the part of e^{−tM⁻¹L}u₀ the sum leaves out has M-norm at
//! most e^{−λ_k t} ‖r‖_M. That bound is returned with every diffusion.

use super::{check_times, m_project, Basis, DescriptorError};
use crate::operators::sparse::{matvec, SparsePair};
use faer::Mat;
use serde::Serialize;

/// Z(t) = Σ_i e^{−λ_i t} over the computed eigenvalues, for each t. It is the trace of the heat kernel, so on a
/// closed surface of area A and Euler characteristic χ it approaches A/(4πt) + χ/6 as t → 0, provided enough
/// eigenvalues are summed that e^{−λ_k t} is negligible.
pub fn heat_trace(values: &[f64], times: &[f64]) -> Vec<f64> {
    times.iter().map(|&t| values.iter().map(|&l| (-l * t).exp()).sum()).collect()
}

/// The part of the heat trace the truncation can miss is at most (n − k) e^{−λ_k t}: reported with the trace.
pub fn heat_trace_tail_bound(values: &[f64], n: usize, t: f64) -> f64 {
    let k = values.len();
    let lk = values.last().copied().unwrap_or(0.0);
    (n.saturating_sub(k)) as f64 * (-lk * t).exp()
}

/// Rows of the heat kernel: column j is `k_t(sources[j], ·)` at every vertex (a density with respect to the
/// area: Σ_y M-integral of a row is 1 up to truncation on a closed surface).
pub fn heat_kernel_rows(basis: &Basis<'_>, sources: &[usize], t: f64) -> Result<Mat<f64>, DescriptorError> {
    check_times("t", &[t])?;
    check_source(basis, sources)?;
    let phi = basis.vectors;
    // W[i, j] = e^{−λ_i t} φ_i(s_j): then rows = Φ W.
    let w = Mat::from_fn(basis.k(), sources.len(), |i, j| (-basis.values[i] * t).exp() * phi[(sources[j], i)]);
    Ok(phi * w.as_ref())
}

/// One row of the heat kernel at several times: column j is k_{t_j}(source, ·).
pub fn heat_kernel_row(basis: &Basis<'_>, source: usize, times: &[f64]) -> Result<Mat<f64>, DescriptorError> {
    check_times("times", times)?;
    check_source(basis, &[source])?;
    let phi = basis.vectors;
    let w = Mat::from_fn(basis.k(), times.len(), |i, j| (-basis.values[i] * times[j]).exp() * phi[(source, i)]);
    Ok(phi * w.as_ref())
}

fn check_source(basis: &Basis<'_>, sources: &[usize]) -> Result<(), DescriptorError> {
    let n = basis.n();
    match sources.iter().find(|&&s| s >= n) {
        Some(s) => Err(DescriptorError::param("sources", format!("vertex {s} does not exist ({n} vertices)"))),
        None => Ok(()),
    }
}

/// Heat diffusion of u₀ by the spectrum.
#[derive(Debug, Clone, Serialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct SpectralDiffusion {
    pub times: Vec<f64>,
    /// n × T: u(·, t_j) in column j.
    #[serde(skip)]
    pub values: Mat<f64>,
    /// ‖r‖_M, the part of u₀ outside the computed eigenvectors.
    pub residual_norm: f64,
    /// ‖u₀‖_M.
    pub initial_norm: f64,
    /// For each time, e^{−λ_k t} ‖r‖_M: the M-norm of what the truncated sum can miss.
    pub truncation_bound: Vec<f64>,
    pub eigenpairs: usize,
}

/// u(t) = Σ_i e^{−λ_i t} ⟨u₀, φ_i⟩_M φ_i (eq. 9.24): the solution of ∂u/∂t = −Δu (M u̇ = −L u) from u₀, for each
/// time.
pub fn diffuse_spectral(
    basis: &Basis<'_>,
    pair: &SparsePair,
    u0: &[f64],
    times: &[f64],
) -> Result<SpectralDiffusion, DescriptorError> {
    check_times("times", times)?;
    let n = basis.n();
    if u0.len() != n || pair.n() != n {
        return Err(DescriptorError::param("u0", format!("{} values for {n} vertices", u0.len())));
    }
    let (c, residual) = m_project(basis, pair, u0);
    let norm2 = residual * residual + c.iter().map(|c| c * c).sum::<f64>();
    let phi = basis.vectors;
    let w = Mat::from_fn(basis.k(), times.len(), |i, j| (-basis.values[i] * times[j]).exp() * c[i]);
    let lk = basis.max_value();
    Ok(SpectralDiffusion {
        times: times.to_vec(),
        values: phi * w.as_ref(),
        residual_norm: residual,
        initial_norm: norm2.max(0.0).sqrt(),
        truncation_bound: times.iter().map(|t| (-lk * t).exp() * residual).collect(),
        eigenpairs: basis.k(),
    })
}

/// Heat content Q(t) = ∫ u(t) of the Dirichlet problem with u₀ = 1 (heat leaving through a boundary held at
/// zero): Q(t) = Σ_i e^{−λ_i t} ⟨1, φ_i⟩_M², with the truncation bound e^{−λ_k t} ‖r‖²_M (r the part of 1
/// outside the basis). `pair` is the Dirichlet-condensed operator the basis belongs to.
#[derive(Debug, Clone, Serialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct HeatContent {
    pub times: Vec<f64>,
    pub content: Vec<f64>,
    /// Q(0) = ∫ 1 over the kept (interior) vertices' mass.
    pub total_mass: f64,
    pub truncation_bound: Vec<f64>,
}

pub fn heat_content(basis: &Basis<'_>, pair: &SparsePair, times: &[f64]) -> Result<HeatContent, DescriptorError> {
    check_times("times", times)?;
    if pair.n() != basis.n() {
        return Err(DescriptorError::param("pair", "the operator does not match the basis"));
    }
    let ones = vec![1.0; basis.n()];
    let (c, residual) = m_project(basis, pair, &ones);
    let mut m1 = vec![0.0; basis.n()];
    matvec(&pair.pattern, &pair.mass, &ones, &mut m1);
    let lk = basis.max_value();
    Ok(HeatContent {
        times: times.to_vec(),
        content: times.iter().map(|&t| c.iter().zip(basis.values).map(|(c, l)| (-l * t).exp() * c * c).sum()).collect(),
        total_mass: m1.iter().sum(),
        truncation_bound: times.iter().map(|t| (-lk * t).exp() * residual * residual).collect(),
    })
}
