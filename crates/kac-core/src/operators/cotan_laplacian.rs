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

use super::sparse::SparsePair;
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

/// Cotangents of the three corners of a triangle with edge lengths `l` (`l[k]` opposite corner k), and its area.
#[inline]
pub fn corner_cotangents(l: [f64; 3]) -> ([f64; 3], f64) {
    let area = area_from_lengths(l);
    let q = [l[0] * l[0], l[1] * l[1], l[2] * l[2]];
    let cot = [0, 1, 2].map(|k| (q[(k + 1) % 3] + q[(k + 2) % 3] - q[k]) / (4.0 * area));
    (cot, area)
}

/// Edge lengths of face `f` from positions: `l[k] = |p[f[k+1]] − p[f[k+2]]|`.
#[inline]
pub fn face_lengths(v: &[Point], f: &[u32; 3]) -> [f64; 3] {
    [0, 1, 2].map(|k| vec3::norm(vec3::sub(v[f[(k + 1) % 3] as usize], v[f[(k + 2) % 3] as usize])))
}

/// The cotangent pair (L, M) of `n` vertices and `faces`, with `lengths(face)` giving the edge lengths.
pub fn cotan_pair(
    n: usize,
    faces: &[[u32; 3]],
    lengths: impl Fn(usize) -> [f64; 3] + Sync,
    mass: Mass,
) -> Result<SparsePair, OperatorError> {
    let consistent = mass == Mass::Consistent;
    // Per face: corner cotangents, area and corner masses (parallel).
    let per_face: Vec<([f64; 3], f64, [f64; 3])> = (0..faces.len())
        .into_par_iter()
        .map(|f| {
            let l = lengths(f);
            let (cot, area) = corner_cotangents(l);
            let cm = super::mass::triangle_corners(mass, l, cot, area);
            (cot, area, cm)
        })
        .collect();
    if let Some(f) = per_face.iter().position(|(c, a, _)| !(*a > 0.0) || !c.iter().all(|x| x.is_finite())) {
        return Err(OperatorError::DegenerateElement {
            element: "face",
            index: f,
            message: "zero or undefined area: cotangent weights are infinite (drop it in validation, or use the 'robust' operator)".into(),
        });
    }
    // Vertex → (face, corner) adjacency.
    let mut vf_ptr = vec![0u32; n + 1];
    for face in faces {
        for &v in face {
            vf_ptr[v as usize + 1] += 1;
        }
    }
    for j in 0..n {
        vf_ptr[j + 1] += vf_ptr[j];
    }
    let mut fill = vf_ptr.clone();
    let mut vf = vec![0u32; 3 * faces.len()];
    for (f, face) in faces.iter().enumerate() {
        for (c, &v) in face.iter().enumerate() {
            vf[fill[v as usize] as usize] = (3 * f + c) as u32;
            fill[v as usize] += 1;
        }
    }
    drop(fill);
    // Column j gathers, from each face at its corner c, the edges to the two other corners: the edge to
    // corner c+1 is opposite corner c+2 and vice versa. Entries: (row, L value, M value), merged by row.
    let column = |j: usize, buf: &mut Vec<(u32, f64, f64)>| -> (f64, f64) {
        buf.clear();
        let (mut dl, mut dm) = (0.0, 0.0);
        for &fc in &vf[vf_ptr[j] as usize..vf_ptr[j + 1] as usize] {
            let (f, c) = (fc as usize / 3, fc as usize % 3);
            let (cot, area, cm) = &per_face[f];
            dm += cm[c];
            for (other, opposite) in [((c + 1) % 3, (c + 2) % 3), ((c + 2) % 3, (c + 1) % 3)] {
                let i = faces[f][other];
                if i as usize == j {
                    continue; // a self-edge of an intrinsic triangulation contributes nothing
                }
                let w = 0.5 * cot[opposite];
                dl += w;
                buf.push((i, -w, super::mass::triangle_off(mass, *area)));
            }
        }
        buf.sort_unstable_by_key(|e| e.0);
        let mut k = 0;
        for r in 0..buf.len() {
            if k > 0 && buf[k - 1].0 == buf[r].0 {
                buf[k - 1].1 += buf[r].1;
                buf[k - 1].2 += buf[r].2;
            } else {
                buf[k] = buf[r];
                k += 1;
            }
        }
        buf.truncate(k);
        (dl, dm)
    };
    const CHUNK: usize = 2048;
    let counts: Vec<usize> = (0..n)
        .into_par_iter()
        .with_min_len(CHUNK)
        .map_init(Vec::new, |ids: &mut Vec<u32>, j| {
            // Only the distinct neighbours are needed here: ids, no values.
            ids.clear();
            for &fc in &vf[vf_ptr[j] as usize..vf_ptr[j + 1] as usize] {
                let (f, c) = (fc as usize / 3, fc as usize % 3);
                for other in [(c + 1) % 3, (c + 2) % 3] {
                    let i = faces[f][other];
                    if i as usize != j {
                        ids.push(i);
                    }
                }
            }
            ids.sort_unstable();
            ids.dedup();
            ids.len() + 1
        })
        .collect();
    let mut col_ptr = vec![0usize; n + 1];
    for j in 0..n {
        col_ptr[j + 1] = col_ptr[j] + counts[j];
    }
    let nnz = col_ptr[n];
    let mut row_idx = vec![0usize; nnz];
    let mut lv = vec![0.0f64; nnz];
    let mut mv = vec![0.0f64; nnz];
    // Split the output arrays into per-chunk pieces and fill them in parallel.
    let mut pieces = Vec::new();
    {
        let (mut r, mut l, mut m) = (&mut row_idx[..], &mut lv[..], &mut mv[..]);
        let mut j0 = 0;
        while j0 < n {
            let j1 = (j0 + CHUNK).min(n);
            let len = col_ptr[j1] - col_ptr[j0];
            let (ra, rb) = r.split_at_mut(len);
            let (la, lb) = l.split_at_mut(len);
            let (ma, mb) = m.split_at_mut(len);
            pieces.push((j0, j1, ra, la, ma));
            (r, l, m) = (rb, lb, mb);
            j0 = j1;
        }
    }
    pieces.into_par_iter().for_each(|(j0, j1, rows, ls, ms)| {
        let mut buf = Vec::new();
        let mut w = 0;
        for j in j0..j1 {
            let (dl, dm) = column(j, &mut buf);
            let mut placed = false;
            for &(i, l, m) in buf.iter() {
                if !placed && i as usize > j {
                    (rows[w], ls[w], ms[w]) = (j, dl, dm);
                    w += 1;
                    placed = true;
                }
                (rows[w], ls[w], ms[w]) = (i as usize, l, m);
                w += 1;
            }
            if !placed {
                (rows[w], ls[w], ms[w]) = (j, dl, dm);
                w += 1;
            }
        }
    });
    let pattern = super::sparse::Pattern { n, col_ptr, row_idx };
    let (stiffness, mass_values) = (lv, mv);
    Ok(SparsePair {
        pattern: Arc::new(pattern),
        stiffness,
        mass: mass_values,
        mass_is_diagonal: !consistent,
        dimension: Some(2),
        kernel: super::sparse::Kernel::CONSTANTS,
    })
}
