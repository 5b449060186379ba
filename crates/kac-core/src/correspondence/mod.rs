//! Which point of one shape is which point of another: functional maps (Ovsjanikov, Ben-Chen, Solomon, Butscher
//! & Guibas 2012, "Functional maps: a flexible representation of maps between shapes", ACM TOG 31(4)) refined
//! spectrally by ZoomOut (Melzi, Ren, Rodolà, Sharma, Wonka & Ovsjanikov 2019, "ZoomOut: spectral upsampling for
//! efficient shape correspondence", ACM TOG 38(6)).
//!
//! Conventions. The source S and the target T each have k M-orthonormal eigenfunctions (columns of Φ_S, Φ_T). A
//! functional map C (k_T × k_S) takes the coefficients a = Φ_Sᵀ M_S f of a function f on S to the coefficients C a
//! of its transfer to T. A vertex map π: T → S (each target vertex's match on the source) pulls functions back,
//! f ∘ π, and has the functional map C = Φ_Tᵀ M_T Φ_S[π, :].
//!
//! The map is fitted as the small dense problem it is (Nogneng & Ovsjanikov 2017, "Informative descriptor
//! preservation via commutativity for shape matching", Computer Graphics Forum 36(2), for the third term):
//!
//! E(C) = w_d ‖C A − B‖² + w_l Σ_ij (λ_i^T − λ_j^S)² C_ij² / ‖(λ^T − λ^S)²‖ + w_c Σ_f ‖C D_S^f − D_T^f C‖²
//!
//! with A, B the descriptors' coefficients (one column per descriptor function, each of unit M-norm), and
//! D^f = Φᵀ M diag(f) Φ the operator of multiplication by descriptor f. Without the third term the rows of C
//! decouple (k small systems); with it, E is one k_T·k_S system, solved densely.
//!
//! Vertex maps come from C by nearest neighbours in the spectral embedding: π(y) = argmin_x ‖Φ_S[x] Cᵀ − Φ_T[y]‖
//! (T → S), and σ(x) = argmin_y ‖Φ_T[y] C − Φ_S[x]‖ (S → T; Cᵀ inverts C for near-isometries, where C is nearly
//! orthogonal). The search goes through every row, by tiles of matrix products in single precision: a row within
//! single-precision rounding of the nearest may be chosen in its place (see [`nearest_rows`]).

mod fit;
mod nearest;
mod options;
mod orientation;
mod probes;
#[cfg(test)]
mod tests;
mod zoomout;

pub use nearest::nearest_rows;
pub use options::{CorrespondenceOptions, MAX_COUPLED_FIT_K, MAX_DESCRIPTORS, MAX_LANDMARKS, MAX_WEIGHT};
pub use zoomout::{correspond, map_of_vertices};

use crate::descriptors::{Basis, DescriptorError};
use crate::geometry::TriangleMesh;
use crate::operators::sparse::{matvec, SparsePair};
use crate::spectrum::EigenError;
use faer::linalg::matmul::matmul;
use faer::{Accum, Mat, MatRef, Par};

/// One side of a correspondence: its eigenpairs (M-orthonormal), its operator (for M) and, for a triangle mesh, the
/// surface (its faces orient the orientation term; vertices in the operator's numbering).
pub struct SpectralShape<'a> {
    pub basis: Basis<'a>,
    pub pair: &'a SparsePair,
    pub surface: Option<&'a TriangleMesh>,
}

impl SpectralShape<'_> {
    fn n(&self) -> usize {
        self.basis.n()
    }
    /// Φ[:, :k]ᵀ M F: the coefficients of the columns of F in the first k eigenfunctions.
    fn coefficients(&self, k: usize, f: MatRef<'_, f64>) -> Mat<f64> {
        let mf = mass_times(self.pair, f);
        let mut out = Mat::zeros(k, f.ncols());
        matmul(out.as_mut(), Accum::Replace, self.basis.vectors.subcols(0, k).transpose(), mf.as_ref(), 1.0, Par::Seq);
        out
    }
}

/// M F, column by column.
fn mass_times(pair: &SparsePair, f: MatRef<'_, f64>) -> Mat<f64> {
    let n = f.nrows();
    let mut out = Mat::zeros(n, f.ncols());
    let (mut x, mut y) = (vec![0.0; n], vec![0.0; n]);
    for j in 0..f.ncols() {
        for i in 0..n {
            x[i] = f[(i, j)];
        }
        matvec(&pair.pattern, &pair.mass, &x, &mut y);
        for i in 0..n {
            out[(i, j)] = y[i];
        }
    }
    out
}

/// A correspondence: the functional map and the vertex maps both ways, with the cost of each match.
#[derive(Debug, Clone)]
pub struct Correspondence {
    /// C (k_T × k_S) in the last basis size.
    pub c: Mat<f64>,
    /// For each target vertex, its match on the source.
    pub target_to_source: Vec<u32>,
    /// For each source vertex, its match on the target.
    pub source_to_target: Vec<u32>,
    /// ‖Φ_S[π(y)] Cᵀ − Φ_T[y]‖ per target vertex: how far its match is in the spectral embedding.
    pub target_cost: Vec<f64>,
    /// ‖Φ_T[σ(x)] C − Φ_S[x]‖ per source vertex.
    pub source_cost: Vec<f64>,
    /// The basis sizes of the refinement, first (the fit) to last.
    pub sizes: Vec<usize>,
    /// ‖CCᵀ − I‖_F / √k_T of the final map (0 for an exact isometry's, or a part's).
    pub orthogonality_defect: f64,
    /// Whether the orientation term was in the fit (a weight, and triangle meshes enclosing a volume on both sides).
    pub oriented: bool,
}

/// Why a correspondence cannot be computed: a parameter or descriptor, or a stop (cancel, timeout).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CorrespondenceError {
    #[error(transparent)]
    Descriptor(#[from] DescriptorError),
    #[error(transparent)]
    Stopped(#[from] EigenError),
}

/// A function on the source carried to the target by the functional map: its coefficients in the source's first
/// k_S eigenfunctions (Φ_Sᵀ M_S f), mapped by C, summed over the target's first k_T (so the band-limited part of f
/// travels; what lies above the basis is lost).
pub fn transfer_function(s: &SpectralShape<'_>, t: &SpectralShape<'_>, c: &Mat<f64>, f: &[f64]) -> Vec<f64> {
    let (kt, ks) = (c.nrows(), c.ncols());
    let col = Mat::from_fn(f.len(), 1, |i, _| f[i]);
    let a = s.coefficients(ks, col.as_ref());
    let mut b = Mat::zeros(kt, 1);
    matmul(b.as_mut(), Accum::Replace, c.as_ref(), a.as_ref(), 1.0, Par::Seq);
    let mut g = Mat::zeros(t.n(), 1);
    matmul(g.as_mut(), Accum::Replace, leading(t, kt), b.as_ref(), 1.0, Par::Seq);
    (0..t.n()).map(|i| g[(i, 0)]).collect()
}

/// The first k pairs of a basis.
fn truncated<'a>(b: &Basis<'a>, k: usize) -> Basis<'a> {
    Basis::new(&b.values[..k], b.vectors.subcols(0, k), b.zero_tol)
}

/// Φ[:, :k].
fn leading<'a>(side: &SpectralShape<'a>, k: usize) -> MatRef<'a, f64> {
    side.basis.vectors.subcols(0, k)
}
