//! Tangent frames (PCA of each point's neighbourhood) and local areas (the Voronoi cell among the neighbours
//! projected to the tangent plane): the area each point stands for, the quadrature weight of a point-cloud
//! Laplacian.

use super::Neighbourhoods;
use crate::geometry::{vec3, Point};
use rayon::prelude::*;

/// Eigen-decomposition of a symmetric 3×3 matrix by Jacobi rotations: eigenvalues ascending with unit vectors.
pub(crate) fn eigen3(mut a: [[f64; 3]; 3]) -> ([f64; 3], [Point; 3]) {
    let mut v = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    for _ in 0..50 {
        let (mut p, mut q, mut best) = (0, 1, 0.0);
        for (i, j) in [(0, 1), (0, 2), (1, 2)] {
            if a[i][j].abs() > best {
                best = a[i][j].abs();
                p = i;
                q = j;
            }
        }
        let scale = a[0][0].abs() + a[1][1].abs() + a[2][2].abs();
        if best <= 1e-15 * scale || best < 1e-300 {
            break;
        }
        let theta = (a[q][q] - a[p][p]) / (2.0 * a[p][q]);
        let t = if theta == 0.0 { 1.0 } else { theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt()) };
        let (c, s) = (1.0 / (t * t + 1.0).sqrt(), t / (t * t + 1.0).sqrt());
        let mut b = a;
        for k in 0..3 {
            b[k][p] = c * a[k][p] - s * a[k][q];
            b[k][q] = s * a[k][p] + c * a[k][q];
        }
        a = b;
        for k in 0..3 {
            b[p][k] = c * a[p][k] - s * a[q][k];
            b[q][k] = s * a[p][k] + c * a[q][k];
        }
        a = b;
        for row in v.iter_mut() {
            let (x, y) = (row[p], row[q]);
            row[p] = c * x - s * y;
            row[q] = s * x + c * y;
        }
    }
    let mut order = [0, 1, 2];
    order.sort_by(|&i, &j| a[i][i].total_cmp(&a[j][j]));
    let vals = order.map(|i| a[i][i]);
    let vecs = order.map(|i| [v[0][i], v[1][i], v[2][i]]);
    (vals, vecs)
}

/// An orthonormal tangent frame (u, v) and normal n at each point, from the covariance of its neighbourhood.
pub fn local_frames(points: &[Point], nb: &Neighbourhoods) -> Vec<[Point; 3]> {
    (0..points.len())
        .into_par_iter()
        .map(|i| {
            let mut c = [[0.0; 3]; 3];
            let p = points[i];
            for &j in nb.of(i) {
                let d = vec3::sub(points[j as usize], p);
                for a in 0..3 {
                    for b in 0..3 {
                        c[a][b] += d[a] * d[b];
                    }
                }
            }
            // The eigenvector of the smallest eigenvalue of the neighbourhood's covariance.
            let n = eigen3(c).1[0];
            let helper = if n[0].abs() < 0.9 { [1.0, 0.0, 0.0] } else { [0.0, 1.0, 0.0] };
            let u = vec3::cross(n, helper);
            let u = vec3::scale(u, 1.0 / vec3::norm(u));
            let v = vec3::cross(n, u);
            [u, v, n]
        })
        .collect()
}

/// The Voronoi cell of a point among its projected neighbours: its area and, in angular order, the neighbour
/// behind each cell edge (`u32::MAX` for an edge of the bounding square, i.e. an open side of the cell).
pub struct Cell {
    pub area: f64,
    pub edges: Vec<u32>,
}

pub fn voronoi_cell(points: &[Point], nb: &Neighbourhoods, frames: &[[Point; 3]], i: usize) -> Cell {
    let [u, v, _] = frames[i];
    let p = points[i];
    let q: Vec<(f64, f64, u32)> = nb
        .of(i)
        .iter()
        .map(|&j| {
            let d = vec3::sub(points[j as usize], p);
            (vec3::dot(d, u), vec3::dot(d, v), j)
        })
        .filter(|&(x, y, _)| x * x + y * y > 0.0)
        .collect();
    let r = q.iter().map(|&(x, y, _)| (x * x + y * y).sqrt()).fold(0.0, f64::max).max(f64::MIN_POSITIVE);
    // The cell is clipped to the square of half-size r (the farthest neighbour): a bound for open cells.
    let mut poly: Vec<([f64; 2], u32)> =
        vec![([-r, -r], u32::MAX), ([r, -r], u32::MAX), ([r, r], u32::MAX), ([-r, r], u32::MAX)];
    // poly[k].1 labels the edge from vertex k to vertex k+1.
    for &(qx, qy, j) in &q {
        let c = 0.5 * (qx * qx + qy * qy);
        let side = |x: [f64; 2]| x[0] * qx + x[1] * qy - c; // ≤ 0 inside
        let mut out: Vec<([f64; 2], u32)> = Vec::with_capacity(poly.len() + 1);
        for k in 0..poly.len() {
            let (a, la) = poly[k];
            let (b, _) = poly[(k + 1) % poly.len()];
            let (sa, sb) = (side(a), side(b));
            if sa <= 0.0 {
                out.push((a, la));
            }
            if (sa <= 0.0) != (sb <= 0.0) {
                let t = sa / (sa - sb);
                let x = [a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])];
                // Entering the inside: the new edge continues the old one; leaving: the new edge is j's.
                out.push((x, if sa <= 0.0 { j } else { la }));
            }
        }
        poly = out;
        if poly.is_empty() {
            break;
        }
    }
    let mut area = 0.0;
    for k in 0..poly.len() {
        let (a, b) = (poly[k].0, poly[(k + 1) % poly.len()].0);
        area += a[0] * b[1] - a[1] * b[0];
    }
    Cell { area: 0.5 * area.abs(), edges: poly.iter().map(|e| e.1).collect() }
}

/// Local areas of all points (Voronoi cells in the tangent planes).
pub fn local_areas(points: &[Point], nb: &Neighbourhoods, frames: &[[Point; 3]]) -> Vec<f64> {
    (0..points.len()).into_par_iter().map(|i| voronoi_cell(points, nb, frames, i).area).collect()
}
