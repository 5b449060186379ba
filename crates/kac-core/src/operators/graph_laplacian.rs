//! Graph Laplacians and the 1-D string.
//!
//! Graphs (W the symmetric weight matrix, D = diag(Σ_j w_ij)); every pair is symmetric, L positive semidefinite:
//! - `graph`: combinatorial L = D − W (= DᵀD with D the incidence matrix for unit weights), M = I;
//! - `graph-normalized`: L = I − D^{−1/2} W D^{−1/2}, M = I (isolated vertices: L_ii = 0);
//! - `graph-random-walk`: the random-walk Laplacian I − D⁻¹W, posed symmetrically as (D − W) φ = λ D φ, so
//!   M = D (isolated vertices get M_ii = 1 and eigenvalue 0).
//!
//! Units: those of the weights (dimensionless for unit weights).
//!
//! The string: P1 finite elements on a polyline with its real segment lengths h: L_ij = −1/h, L_ii = Σ 1/h;
//! `consistent` mass h/3 on the diagonal and h/6 off it per segment, `lumped` h/2 per end. On unit spacing with
//! lumped mass and Dirichlet ends this is exactly the matrix of eq. (9.3), tridiag(−1, 2, −1), whose eigenvalues
//! are 2 − 2cos(kπ/n).

use super::sparse::{assemble, Kernel, SparsePair};
use super::{Mass, OperatorError};
use crate::geometry::{vec3, Point};
use std::sync::Arc;

/// Which graph Laplacian.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum GraphKind {
    Combinatorial,
    Normalized,
    RandomWalk,
}

pub fn graph_pair(n: usize, edges: &[[u32; 2]], weights: &[f64], kind: GraphKind) -> SparsePair {
    let mut deg = vec![0.0; n];
    for (e, &w) in edges.iter().zip(weights) {
        deg[e[0] as usize] += w;
        deg[e[1] as usize] += w;
    }
    let off: Vec<(u32, u32, [f64; 2])> = edges
        .iter()
        .zip(weights)
        .map(|(e, &w)| {
            let l = match kind {
                GraphKind::Normalized => -w / (deg[e[0] as usize] * deg[e[1] as usize]).sqrt(),
                _ => -w,
            };
            (e[0], e[1], [l, 0.0])
        })
        .collect();
    let (dl, dm): (Vec<f64>, Vec<f64>) = deg
        .iter()
        .map(|&d| match kind {
            GraphKind::Combinatorial => (d, 1.0),
            GraphKind::Normalized => (if d > 0.0 { 1.0 } else { 0.0 }, 1.0),
            GraphKind::RandomWalk => (d, if d > 0.0 { d } else { 1.0 }),
        })
        .unzip();
    let (pattern, [stiffness, mass]) = assemble(n, &off, [&dl, &dm]);
    // D − W annihilates constants on each component; I − D^{−½}WD^{−½} annihilates D^{½} times them (an
    // isolated vertex, with L_ii = 0, its unit vector).
    let kernel = match kind {
        GraphKind::Normalized => Kernel::Components {
            weights: Some(Arc::new(deg.iter().map(|&d| if d > 0.0 { d.sqrt() } else { 1.0 }).collect())),
            anchored: None,
        },
        _ => Kernel::CONSTANTS,
    };
    SparsePair { pattern: Arc::new(pattern), stiffness, mass, mass_is_diagonal: true, dimension: None, kernel }
}

pub fn string_pair(v: &[Point], segments: &[[u32; 2]], mass: Mass) -> Result<SparsePair, OperatorError> {
    let n = v.len();
    let consistent = mass == Mass::Consistent;
    let (mut dl, mut dm) = (vec![0.0; n], vec![0.0; n]);
    let mut off = Vec::with_capacity(segments.len());
    for (si, s) in segments.iter().enumerate() {
        let h = vec3::norm(vec3::sub(v[s[0] as usize], v[s[1] as usize]));
        if !(h > 0.0) {
            return Err(OperatorError::DegenerateElement {
                element: "segment",
                index: si,
                message: "zero length".into(),
            });
        }
        let (m_diag, m_off) = super::mass::segment(mass, h);
        off.push((s[0], s[1], [-1.0 / h, m_off]));
        for &i in s {
            dl[i as usize] += 1.0 / h;
            dm[i as usize] += m_diag;
        }
    }
    let (pattern, [stiffness, m]) = assemble(n, &off, [&dl, &dm]);
    Ok(SparsePair {
        pattern: Arc::new(pattern),
        stiffness,
        mass: m,
        mass_is_diagonal: !consistent,
        dimension: Some(1),
        kernel: Kernel::CONSTANTS,
    })
}
