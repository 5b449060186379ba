//! What a spectrum tells: heat kernel and heat trace, per-vertex signatures (HKS, SI-HKS, WKS, GPS), shape-DNA,
//! Weyl's-law estimates and the spectral facts of graphs (spanning trees, components, Fiedler vector,
//! eigenmaps).
//!
//! Every function here reads a computed eigenbasis ([`Basis`]): eigenvalues ascending and M-orthonormal
//! eigenvectors of L φ = λ M φ (see [`crate::spectrum`]). Nothing is solved again. Conventions shared by all:
//!
//! - A *zero mode* is an eigenpair with λ ≤ `zero_tol` (one per connected component for a Neumann problem).
//!   [`zero_threshold`] gives the default tolerance from the operator's scale. Whether zero modes enter a sum is
//!   stated by each descriptor and echoed in its output.
//! - Per-vertex results are n × T matrices (vertices of the operator, rows; samples, columns).
//! - Every parameter a descriptor used, chosen or defaulted, is returned beside the values.

pub mod curvature;
pub mod global;
pub mod graph;
pub mod heat;
pub mod shape_dna;
pub mod signatures;
pub mod weyl;

use crate::operators::sparse::SparsePair;
use crate::spectrum::Spectrum;
use faer::MatRef;
use serde::Serialize;

/// A computed eigenbasis: the k smallest eigenpairs, ascending, M-orthonormal.
#[derive(Clone, Copy)]
pub struct Basis<'a> {
    pub values: &'a [f64],
    /// n × k.
    pub vectors: MatRef<'a, f64>,
    /// Eigenvalues at or below this are zero modes.
    pub zero_tol: f64,
}

impl<'a> Basis<'a> {
    pub fn new(values: &'a [f64], vectors: MatRef<'a, f64>, zero_tol: f64) -> Self {
        assert_eq!(values.len(), vectors.ncols(), "one eigenvector per eigenvalue");
        Basis { values, vectors, zero_tol }
    }
    /// The basis of a computed spectrum, with the default zero tolerance of its operator.
    pub fn of(spectrum: &'a Spectrum, pair: &SparsePair) -> Self {
        Basis::new(&spectrum.values, spectrum.vectors.as_ref(), zero_threshold(pair))
    }
    /// Vertices (rows).
    pub fn n(&self) -> usize {
        self.vectors.nrows()
    }
    /// Eigenpairs (columns).
    pub fn k(&self) -> usize {
        self.values.len()
    }
    pub fn is_zero(&self, i: usize) -> bool {
        self.values[i] <= self.zero_tol
    }
    /// Number of zero modes among the computed pairs.
    pub fn zero_modes(&self) -> usize {
        (0..self.k()).filter(|&i| self.is_zero(i)).count()
    }
    /// Index of the first eigenvalue above the zero tolerance.
    pub fn first_nonzero(&self) -> Option<usize> {
        (0..self.k()).find(|&i| !self.is_zero(i))
    }
    /// The largest computed eigenvalue.
    pub fn max_value(&self) -> f64 {
        self.values.last().copied().unwrap_or(0.0)
    }
}

/// Default zero-mode tolerance of an operator: 10⁻⁹ · mean_i(L_ii / M_ii).
///
/// mean(L_ii/M_ii) is the scale of the operator's largest eigenvalues (about 1/h² for a mesh of spacing h), so
/// the tolerance follows the units of the input; a computed zero mode is accurate to about 10⁻¹² of that scale
/// and the first non-zero eigenvalue of any shape kac takes sits far above it.
pub fn zero_threshold(pair: &SparsePair) -> f64 {
    let n = pair.n();
    if n == 0 {
        return 0.0;
    }
    let mut sum = 0.0;
    for j in 0..n {
        let d = pair.pattern.diag_pos(j);
        let m = pair.mass[d];
        if m > 0.0 {
            sum += pair.stiffness[d] / m;
        }
    }
    1e-9 * sum / n as f64
}

/// Why a descriptor cannot be computed.
#[derive(Debug, Clone, PartialEq, thiserror::Error, Serialize)]
#[serde(tag = "error", rename_all = "snake_case")]
pub enum DescriptorError {
    #[error("invalid parameter {name}: {message}")]
    InvalidParameter { name: &'static str, message: String },
    #[error("the spectrum has too few eigenpairs: {message}")]
    TooFewEigenpairs { message: String },
    #[error("{message}")]
    NotApplicable { message: String },
    #[error("the linear system could not be solved: {message}")]
    Solve { message: String },
    #[error(
        "the factor of the linear system would hold {values} values (the symbolic analysis' fill), above the limit of \
         {limit}"
    )]
    TooLarge { values: usize, limit: usize },
}

impl DescriptorError {
    /// Whether the request was at fault (it cannot succeed as given) rather than the computation.
    pub fn caller_fault(&self) -> bool {
        match self {
            DescriptorError::InvalidParameter { .. }
            | DescriptorError::TooFewEigenpairs { .. }
            | DescriptorError::NotApplicable { .. }
            | DescriptorError::TooLarge { .. } => true,
            DescriptorError::Solve { .. } => false,
        }
    }
    /// The symbolic analysis of a pattern, refused when its factor would exceed this thread's limit
    /// ([`crate::cholesky::factor::with_factor_limit`]).
    pub(crate) fn analyze(
        pattern: &std::sync::Arc<crate::operators::sparse::Pattern>,
    ) -> Result<crate::cholesky::factor::Symbolic, DescriptorError> {
        let sym = crate::cholesky::factor::Symbolic::analyze(pattern)
            .map_err(|message| DescriptorError::Solve { message })?;
        let (values, limit) = (sym.inner.len_val(), crate::cholesky::factor::factor_limit());
        if values > limit {
            return Err(DescriptorError::TooLarge { values, limit });
        }
        Ok(sym)
    }
    pub(crate) fn param(name: &'static str, message: impl Into<String>) -> Self {
        DescriptorError::InvalidParameter { name, message: message.into() }
    }
}

/// Coordinates of `u` in the basis, c_i = ⟨u, φ_i⟩_M, and the M-norm of the part of `u` outside it
/// (√(‖u‖²_M − Σc²), exact because the φ_i are M-orthonormal). `u` has one value per basis row.
pub fn m_project(basis: &Basis<'_>, pair: &SparsePair, u: &[f64]) -> (Vec<f64>, f64) {
    let n = basis.n();
    let mut mu = vec![0.0; n];
    crate::operators::sparse::matvec(&pair.pattern, &pair.mass, u, &mut mu);
    let phi = basis.vectors;
    let c: Vec<f64> = (0..basis.k()).map(|i| (0..n).map(|x| phi[(x, i)] * mu[x]).sum()).collect();
    let norm2: f64 = u.iter().zip(&mu).map(|(a, b)| a * b).sum();
    let captured: f64 = c.iter().map(|c| c * c).sum();
    (c, (norm2 - captured).max(0.0).sqrt())
}

/// `count` points log-spaced from `a` to `b` inclusive (natural log spacing; one point gives `a`).
pub fn log_space(a: f64, b: f64, count: usize) -> Vec<f64> {
    if count == 1 {
        return vec![a];
    }
    let (la, lb) = (a.ln(), b.ln());
    (0..count).map(|i| (la + (lb - la) * i as f64 / (count - 1) as f64).exp()).collect()
}

/// `count` points evenly spaced from `a` to `b` inclusive.
pub fn lin_space(a: f64, b: f64, count: usize) -> Vec<f64> {
    if count == 1 {
        return vec![a];
    }
    (0..count).map(|i| a + (b - a) * i as f64 / (count - 1) as f64).collect()
}

pub fn check_times(name: &'static str, times: &[f64]) -> Result<(), DescriptorError> {
    if times.is_empty() {
        return Err(DescriptorError::param(name, "no values given"));
    }
    if let Some(t) = times.iter().find(|t| !(**t > 0.0 && t.is_finite())) {
        return Err(DescriptorError::param(name, format!("{t} is not a positive finite number")));
    }
    Ok(())
}

/// Σ_i w_i(s) φ_i(x)² for every vertex x and every sample s: the n × S matrix (Φ∘Φ)·W for a k × S weight
/// matrix W. The shape of every kernel signature (HKS, WKS).
pub(crate) fn squared_basis_times(basis: &Basis<'_>, weights: MatRef<'_, f64>) -> faer::Mat<f64> {
    let phi = basis.vectors;
    let sq = faer::Mat::from_fn(phi.nrows(), phi.ncols(), |i, j| phi[(i, j)] * phi[(i, j)]);
    sq.as_ref() * weights
}
