//! The cotangent Laplacian of a triangle mesh (P1 finite elements), built from edge lengths so that intrinsic
//! input (edge lengths without positions) works too, with three mass matrices.
//!
//! Shapes: L and M are #V × #V. Sign: L is positive semidefinite, the stiffness matrix of eq. (9.35):
//! `L_ij = −½ (cot α_ij + cot β_ij)` for an edge ij (α, β the angles opposite it), `L_ii = −Σ_j L_ij`
//! (libigl's `cotmatrix` is −L). Units: L is dimensionless on a surface (length⁰), M has units of area, so the
//! eigenvalues of L φ = λ M φ have units of 1/length².
//!
//! Masses: `consistent` (9.36): A/6 on the diagonal and A/12 off it for each triangle of area A;
//! `lumped` (barycentric): A/3 to each corner; `voronoi` (mixed Voronoi areas of Meyer, Desbrun, Schröder & Barr
//! 2003): the circumcentric Voronoi area of each corner, with A/2 to an obtuse corner and A/4 to the others in
//! obtuse triangles.

use super::sparse::{assemble, SparsePair};
use super::{Mass, OperatorError};
use crate::geometry::{vec3, Point};
use rayon::prelude::*;
use std::sync::Arc;

/// Area of a triangle from its edge lengths, by Kahan's stable form of Heron's formula; NaN if the lengths break
/// the triangle inequality.
pub fn area_from_lengths(l: [f64; 3]) -> f64 {
    let mut s = l;
    s.sort_by(|a, b| b.total_cmp(a));
    let [a, b, c] = s;
    let p = (a + (b + c)) * (c - (a - b)) * (c + (a - b)) * (a + (b - c));
    if p < 0.0 {
        f64::NAN
    } else {
        0.25 * p.sqrt()
    }
}

/// Cotangents of the three corners of a triangle with edge lengths `l` (l[k] opposite corner k), and its area.
#[inline]
pub fn corner_cotangents(l: [f64; 3]) -> ([f64; 3], f64) {
    let area = area_from_lengths(l);
    let q = [l[0] * l[0], l[1] * l[1], l[2] * l[2]];
    let cot = [0, 1, 2].map(|k| (q[(k + 1) % 3] + q[(k + 2) % 3] - q[k]) / (4.0 * area));
    (cot, area)
}

/// Edge lengths of face `f` from positions: l[k] = |p[f[k+1]] − p[f[k+2]]|.
#[inline]
pub fn face_lengths(v: &[Point], f: &[u32; 3]) -> [f64; 3] {
    [0, 1, 2].map(|k| vec3::norm(vec3::sub(v[f[(k + 1) % 3] as usize], v[f[(k + 2) % 3] as usize])))
}

/// Per-corner mass for the `lumped` and `voronoi` masses of one triangle.
fn corner_masses(mass: Mass, l: [f64; 3], cot: [f64; 3], area: f64) -> [f64; 3] {
    match mass {
        Mass::Voronoi => {
            let obtuse = (0..3).find(|&k| cot[k] < 0.0);
            match obtuse {
                Some(o) => [0, 1, 2].map(|k| if k == o { area / 2.0 } else { area / 4.0 }),
                None => [0, 1, 2].map(|k| {
                    let (a, b) = ((k + 1) % 3, (k + 2) % 3);
                    (l[a] * l[a] * cot[a] + l[b] * l[b] * cot[b]) / 8.0
                }),
            }
        }
        _ => [area / 3.0; 3],
    }
}

/// The cotangent pair (L, M) of `n` vertices and `faces`, with `lengths(face)` giving the edge lengths.
pub fn cotan_pair(
    n: usize,
    faces: &[[u32; 3]],
    lengths: impl Fn(usize) -> [f64; 3] + Sync,
    mass: Mass,
) -> Result<SparsePair, OperatorError> {
    let consistent = mass == Mass::Consistent;
    // One parallel pass: each face emits its three edges (L and M values) and its three corner masses.
    type FaceOut = ([(u32, u32, [f64; 2]); 3], [f64; 3], bool);
    let per_face: Vec<FaceOut> = (0..faces.len())
        .into_par_iter()
        .map(|f| {
            let face = &faces[f];
            let l = lengths(f);
            let (cot, area) = corner_cotangents(l);
            let ok = area > 0.0 && cot.iter().all(|x| x.is_finite());
            let edges = [0, 1, 2].map(|k| {
                (face[(k + 1) % 3], face[(k + 2) % 3], [-0.5 * cot[k], if consistent { area / 12.0 } else { 0.0 }])
            });
            let cm = if consistent { [area / 6.0; 3] } else { corner_masses(mass, l, cot, area) };
            (edges, cm, ok)
        })
        .collect();
    if let Some(f) = per_face.iter().position(|x| !x.2) {
        return Err(OperatorError::DegenerateElement {
            element: "face",
            index: f,
            message: "zero or undefined area: cotangent weights are infinite (drop it in validation, or use the 'robust' operator)".into(),
        });
    }
    let mut off: Vec<(u32, u32, [f64; 2])> = Vec::with_capacity(3 * faces.len());
    let mut dl = vec![0.0; n];
    let mut dm = vec![0.0; n];
    for (face, (edges, cm, _)) in faces.iter().zip(&per_face) {
        for &(i, j, v) in edges {
            if i == j {
                continue; // a self-edge of an intrinsic triangulation: f_i − f_i = 0, no contribution
            }
            off.push((i, j, v));
            dl[i as usize] -= v[0];
            dl[j as usize] -= v[0];
        }
        for k in 0..3 {
            dm[face[k] as usize] += cm[k];
        }
    }
    drop(per_face);
    let (pattern, [stiffness, mass_values]) = assemble(n, &off, [&dl, &dm]);
    Ok(SparsePair { pattern: Arc::new(pattern), stiffness, mass: mass_values, mass_is_diagonal: !consistent })
}
