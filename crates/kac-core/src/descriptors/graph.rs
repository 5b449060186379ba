//! Spectral facts of graphs (and of any operator's sparsity graph): spanning-tree counts by Kirchhoff's
//! theorem, connected components, the Fiedler vector with a spectral bisection, and Laplacian-eigenmap
//! embeddings.

use super::{Basis, DescriptorError};
use crate::cholesky::factor::Cholesky;
use crate::operators::graph_laplacian::{graph_pair, GraphKind};
use crate::operators::sparse::{submatrix, Pattern, SparsePair};
use faer::Mat;
use serde::Serialize;
use std::sync::Arc;

/// Connected components of the graph of non-zero off-diagonal entries of L: label per vertex and count. For a
/// Laplacian with non-negative weights, the count is the multiplicity of the eigenvalue 0.
pub fn components(pair: &SparsePair) -> (Vec<u32>, usize) {
    pair.components()
}

/// The number of spanning trees (for weighted graphs: the sum over spanning trees of the product of their
/// weights), by Kirchhoff's matrix-tree theorem: the determinant of the Laplacian with one row and column
/// removed.
#[derive(Debug, Clone, Serialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct TreeCount {
    pub vertices: usize,
    pub edges: usize,
    pub components: usize,
    /// Natural log of the count (absent when the graph is disconnected: the count is 0).
    pub log_count: Option<f64>,
    pub log10_count: Option<f64>,
    /// The exact count as a decimal string, when every weight is an integer and fraction-free elimination in
    /// 128-bit integers does not overflow (the count can exceed what a JSON number holds exactly).
    pub count: Option<String>,
    /// How `log_count` was computed: sparse Cholesky of the reduced Laplacian (2 Σ log L_jj).
    pub method: &'static str,
    pub exact_method: Option<&'static str>,
    pub weighted: bool,
}

/// Largest reduced size for which the exact (fraction-free, O(n³)) count is attempted.
pub const EXACT_TREE_COUNT_MAX_VERTICES: usize = 400;

pub fn spanning_trees(n: usize, edges: &[[u32; 2]], weights: &[f64]) -> Result<TreeCount, DescriptorError> {
    if n == 0 {
        return Err(DescriptorError::param("graph", "the graph has no vertices"));
    }
    if edges.len() != weights.len() {
        return Err(DescriptorError::param("weights", "one weight per edge"));
    }
    if let Some((e, w)) = weights.iter().enumerate().find(|(_, w)| !(**w > 0.0 && w.is_finite())) {
        return Err(DescriptorError::param("weights", format!("edge {e} has weight {w}; weights must be positive")));
    }
    let pair = graph_pair(n, edges, weights, GraphKind::Combinatorial);
    let (_, comps) = components(&pair);
    let weighted = weights.iter().any(|&w| w != 1.0);
    let mut out = TreeCount {
        vertices: n,
        edges: edges.len(),
        components: comps,
        log_count: None,
        log10_count: None,
        count: None,
        method: "sparse Cholesky of the reduced Laplacian",
        exact_method: None,
        weighted,
    };
    if comps > 1 {
        out.count = Some("0".into());
        return Ok(out);
    }
    if n == 1 {
        out.log_count = Some(0.0);
        out.log10_count = Some(0.0);
        out.count = Some("1".into());
        return Ok(out);
    }
    let keep: Vec<usize> = (0..n - 1).collect();
    let (pattern, vals) = submatrix(&pair.pattern, &[&pair.stiffness], &keep);
    let pattern = Arc::new(pattern);
    let sym = crate::descriptors::DescriptorError::analyze(&pattern)?;
    let chol =
        Cholesky::factor(&sym, &vals[0], faer::Par::Seq).map_err(|message| DescriptorError::Solve { message })?;
    let log = chol.log_det();
    out.log_count = Some(log);
    out.log10_count = Some(log / std::f64::consts::LN_10);
    let integral = weights.iter().all(|w| w.fract() == 0.0 && *w < 2f64.powi(31));
    if integral && n - 1 <= EXACT_TREE_COUNT_MAX_VERTICES {
        if let Some(det) = bareiss_determinant(&pattern, &vals[0]) {
            out.count = Some(det.to_string());
            out.exact_method = Some("fraction-free (Bareiss) elimination in 128-bit integers");
        }
    }
    Ok(out)
}

/// Exact determinant of an integer matrix by Bareiss' fraction-free elimination; `None` on overflow.
fn bareiss_determinant(p: &Pattern, values: &[f64]) -> Option<i128> {
    let n = p.n;
    let mut a = vec![0i128; n * n];
    for j in 0..n {
        for pos in p.col_ptr[j]..p.col_ptr[j + 1] {
            a[p.row_idx[pos] * n + j] = values[pos].round() as i128;
        }
    }
    let mut sign = 1i128;
    let mut prev = 1i128;
    for k in 0..n {
        if a[k * n + k] == 0 {
            let r = (k + 1..n).find(|&r| a[r * n + k] != 0)?;
            for c in 0..n {
                a.swap(k * n + c, r * n + c);
            }
            sign = -sign;
        }
        let pivot = a[k * n + k];
        for i in k + 1..n {
            let aik = a[i * n + k];
            for j in k + 1..n {
                let v = a[i * n + j].checked_mul(pivot)?.checked_sub(aik.checked_mul(a[k * n + j])?)?;
                a[i * n + j] = v / prev; // exact by Sylvester's identity
            }
            a[i * n + k] = 0;
        }
        prev = pivot;
    }
    Some(sign * a[n * n - 1])
}

/// The Fiedler vector (Fiedler 1973): the eigenvector of the first non-zero eigenvalue of a connected shape
/// (λ₁, its algebraic connectivity), and the bisection by its sign.
#[derive(Debug, Clone, Serialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct Fiedler {
    pub algebraic_connectivity: f64,
    #[serde(skip)]
    pub vector: Vec<f64>,
    /// Vertex sides: true where the Fiedler vector is ≥ the split value.
    #[serde(skip)]
    pub side: Vec<bool>,
    /// "sign" (split at 0) or "median" (equal halves).
    pub split: &'static str,
    pub split_value: f64,
    pub sizes: [usize; 2],
    /// Off-diagonal entries of L joining the two sides: their count and their total weight −Σ L_ij.
    pub cut_edges: usize,
    pub cut_weight: f64,
}

pub fn fiedler(basis: &Basis<'_>, pair: &SparsePair, median: bool) -> Result<Fiedler, DescriptorError> {
    let zeros = basis.zero_modes();
    if zeros > 1 {
        return Err(DescriptorError::NotApplicable {
            message: format!("the shape has {zeros} components (zero modes); the Fiedler vector needs a connected one"),
        });
    }
    let i1 = basis.first_nonzero().ok_or_else(|| DescriptorError::TooFewEigenpairs {
        message: "the Fiedler vector needs the first non-zero eigenpair".into(),
    })?;
    let v: Vec<f64> = basis.vectors.col(i1).iter().copied().collect();
    let split_value = if median {
        let mut s = v.clone();
        s.sort_by(f64::total_cmp);
        s[s.len() / 2]
    } else {
        0.0
    };
    let side: Vec<bool> = v.iter().map(|&x| x >= split_value).collect();
    let a = side.iter().filter(|&&s| s).count();
    let p = &pair.pattern;
    let (mut cut_edges, mut cut_weight) = (0, 0.0);
    for j in 0..p.n {
        for pos in p.col_ptr[j]..p.col_ptr[j + 1] {
            let i = p.row_idx[pos];
            if i < j && side[i] != side[j] && pair.stiffness[pos] != 0.0 {
                cut_edges += 1;
                cut_weight -= pair.stiffness[pos];
            }
        }
    }
    Ok(Fiedler {
        algebraic_connectivity: basis.values[i1],
        vector: v,
        side,
        split: if median { "median" } else { "sign" },
        split_value,
        sizes: [a, p.n - a],
        cut_edges,
        cut_weight,
    })
}

/// Laplacian eigenmap (Belkin & Niyogi 2003): the first `dimensions` non-zero eigenvectors as coordinates; with
/// `scaled`, each divided by √λ (the GPS coordinates of Rustamov 2007).
pub fn eigenmap(basis: &Basis<'_>, dimensions: usize, scaled: bool) -> Result<(Mat<f64>, Vec<f64>), DescriptorError> {
    let i1 = basis.first_nonzero().ok_or_else(|| DescriptorError::TooFewEigenpairs {
        message: "an embedding needs non-zero eigenpairs".into(),
    })?;
    if dimensions == 0 || i1 + dimensions > basis.k() {
        return Err(DescriptorError::TooFewEigenpairs {
            message: format!("{dimensions} dimensions asked, {} non-zero eigenpairs computed", basis.k() - i1),
        });
    }
    let phi = basis.vectors;
    let vals = basis.values[i1..i1 + dimensions].to_vec();
    let coords = Mat::from_fn(basis.n(), dimensions, |x, j| {
        let v = phi[(x, i1 + j)];
        if scaled {
            v / vals[j].sqrt()
        } else {
            v
        }
    });
    Ok((coords, vals))
}
