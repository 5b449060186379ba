//! The polygon Laplacian of Bunge, Herholz, Kazhdan & Botsch ("Polygon Laplacian Made Simple", Computer
//! Graphics Forum 39(2), 2020): meshes with quads and general polygons, planar or not, convex or not, without
//! triangulating them first. Each polygon with corners x₁…x_n gets a virtual vertex x_f = Σ w_i x_i, the point
//! minimizing the sum of squared areas of the fan triangles (x_i, x_{i+1}, x_f), with w the least-norm affine
//! weights that reproduce it; the fan is a small triangle mesh whose cotan stiffness S and mass M are restricted
//! to the polygon's corners by the prolongation P (identity on the corners, wᵀ for the virtual vertex):
//! L_f = Pᵀ S P, M_f = Pᵀ M P (consistent; `lumped`: its row sums). The result is symmetric, positive
//! semidefinite, has the constants in its kernel, and has linear precision on planar polygons (P maps a linear
//! function to a linear function on the fan, where the cotan Laplacian reproduces it). A triangle gives exactly the
//! cotan Laplacian. Sign: L positive semidefinite.

use super::sparse::{assemble, Kernel, SparsePair};
use super::{Mass, OperatorError};
use crate::geometry::{vec3, Point, Polygons};
use std::sync::Arc;

/// Corners a polygon may have: each polygon's local matrices are dense (n²) and its assembly n³.
pub const MAX_CORNERS: usize = 256;

/// The virtual vertex's affine weights for a polygon (see the module documentation).
pub fn virtual_weights(x: &[Point]) -> Vec<f64> {
    let n = x.len();
    // Σ ‖c_i + [e_i]× p‖² over the fan: (Σ [e_i]×ᵀ[e_i]×) p = −Σ [e_i]×ᵀ c_i, with c_i = x_i × x_{i+1}.
    let skew = |e: Point| [[0.0, -e[2], e[1]], [e[2], 0.0, -e[0]], [-e[1], e[0], 0.0]];
    let (mut a, mut b) = ([[0.0; 3]; 3], [0.0; 3]);
    for i in 0..n {
        let (p, q) = (x[i], x[(i + 1) % n]);
        let s = skew(vec3::sub(q, p));
        let c = vec3::cross(p, q);
        for r in 0..3 {
            for col in 0..3 {
                a[r][col] += (0..3).map(|k| s[k][r] * s[k][col]).sum::<f64>();
            }
            b[r] -= (0..3).map(|k| s[k][r] * c[k]).sum::<f64>();
        }
    }
    // Solve in the least-squares sense (a is singular along the normal of a planar polygon): a small ridge
    // toward the centroid picks the minimizer nearest to it.
    let centroid = vec3::scale(x.iter().fold([0.0; 3], |s, &p| vec3::add(s, p)), 1.0 / n as f64);
    let scale = (0..3).map(|i| a[i][i]).sum::<f64>().max(f64::MIN_POSITIVE);
    let ridge = 1e-10 * scale;
    for i in 0..3 {
        a[i][i] += ridge;
        b[i] += ridge * centroid[i];
    }
    let p = solve3(a, b).unwrap_or(centroid);
    // Least-norm affine weights: minimize ‖w‖² subject to Σ w_i x_i = p, Σ w_i = 1, i.e. w = Aᵀ(AAᵀ)⁺[p; 1]
    // with A = [x_i; 1] (4 × n); AAᵀ is singular for planar polygons, so with a small ridge again.
    let mut g = [[0.0; 4]; 4];
    let col = |i: usize| [x[i][0], x[i][1], x[i][2], 1.0];
    for i in 0..n {
        let c = col(i);
        for r in 0..4 {
            for s in 0..4 {
                g[r][s] += c[r] * c[s];
            }
        }
    }
    let gs = (0..4).map(|i| g[i][i]).sum::<f64>().max(f64::MIN_POSITIVE);
    for (i, row) in g.iter_mut().enumerate() {
        row[i] += 1e-12 * gs;
    }
    let rhs = [p[0], p[1], p[2], 1.0];
    let y = solve4(g, rhs).unwrap_or([0.0, 0.0, 0.0, 1.0 / n as f64]);
    let mut w: Vec<f64> = (0..n).map(|i| (0..4).map(|r| col(i)[r] * y[r]).sum()).collect();
    // Exactly affine (the ridge leaves a rounding-level defect).
    let total: f64 = w.iter().sum();
    w.iter_mut().for_each(|v| *v /= total);
    w
}

fn solve3(a: [[f64; 3]; 3], b: [f64; 3]) -> Option<Point> {
    let det = vec3::dot(a[0], vec3::cross(a[1], a[2]));
    if det.abs() < 1e-300 {
        return None;
    }
    let col = |j: usize| [a[0][j], a[1][j], a[2][j]];
    let (c0, c1, c2) = (col(0), col(1), col(2));
    Some([
        vec3::dot(b, vec3::cross(c1, c2)) / det,
        vec3::dot(c0, vec3::cross(b, c2)) / det,
        vec3::dot(c0, vec3::cross(c1, b)) / det,
    ])
}

fn solve4(mut a: [[f64; 4]; 4], mut b: [f64; 4]) -> Option<[f64; 4]> {
    for c in 0..4 {
        let p = (c..4).max_by(|&i, &j| a[i][c].abs().total_cmp(&a[j][c].abs()))?;
        if a[p][c].abs() < 1e-300 {
            return None;
        }
        a.swap(c, p);
        b.swap(c, p);
        for r in c + 1..4 {
            let f = a[r][c] / a[c][c];
            for k in c..4 {
                a[r][k] -= f * a[c][k];
            }
            b[r] -= f * b[c];
        }
    }
    let mut x = [0.0; 4];
    for r in (0..4).rev() {
        x[r] = (b[r] - (r + 1..4).map(|k| a[r][k] * x[k]).sum::<f64>()) / a[r][r];
    }
    Some(x)
}

/// The cotan stiffness and consistent mass of one triangle (local 3 × 3, row-major).
fn triangle(p: [Point; 3]) -> Option<([f64; 9], [f64; 9])> {
    let area2 = vec3::norm(vec3::cross(vec3::sub(p[1], p[0]), vec3::sub(p[2], p[0])));
    if !(area2 > 0.0) {
        return None;
    }
    let area = 0.5 * area2;
    let (mut k, mut m) = ([0.0; 9], [0.0; 9]);
    for i in 0..3 {
        let (j, l) = ((i + 1) % 3, (i + 2) % 3);
        // The angle at corner i is opposite edge (j, l): weight ½ cot on that edge.
        let (u, v) = (vec3::sub(p[j], p[i]), vec3::sub(p[l], p[i]));
        let cot = vec3::dot(u, v) / area2;
        k[j * 3 + l] -= 0.5 * cot;
        k[l * 3 + j] -= 0.5 * cot;
        k[j * 3 + j] += 0.5 * cot;
        k[l * 3 + l] += 0.5 * cot;
        for c in 0..3 {
            m[i * 3 + c] = if i == c { area / 6.0 } else { area / 12.0 };
        }
    }
    Some((k, m))
}

/// The polygon Laplacian pair of a polygon mesh on `vertices`.
pub fn polygon_pair(vertices: &[Point], polygons: &Polygons, mass: Mass) -> Result<SparsePair, OperatorError> {
    let nv = vertices.len();
    let mut off: Vec<(u32, u32, [f64; 2])> = Vec::new();
    let (mut dl, mut dm) = (vec![0.0; nv], vec![0.0; nv]);
    for (fi, poly) in polygons.iter().enumerate() {
        let n = poly.len();
        if n > MAX_CORNERS {
            return Err(OperatorError::InvalidParameter {
                name: "operator",
                message: format!(
                    "polygon {fi} has {n} corners; the polygon operator takes at most {MAX_CORNERS} (its local matrices are dense)"
                ),
            });
        }
        let x: Vec<Point> = poly.iter().map(|&v| vertices[v as usize]).collect();
        // Local (n × n) matrices on the corners.
        let (mut lk, mut lm) = (vec![0.0; n * n], vec![0.0; n * n]);
        let degenerate = || OperatorError::DegenerateElement {
            element: "polygon",
            index: fi,
            message: "a triangle of its virtual refinement has zero area".into(),
        };
        if n == 3 {
            let (k, m) = triangle([x[0], x[1], x[2]]).ok_or_else(degenerate)?;
            lk.copy_from_slice(&k);
            lm.copy_from_slice(&m);
        } else {
            let w = virtual_weights(&x);
            let xf = (0..n).fold([0.0; 3], |s, i| vec3::add(s, vec3::scale(x[i], w[i])));
            // Prolongation of fan-local index (corner i, or n for the virtual vertex) to corner weights.
            let prolong = |a: usize, corner: usize| if a == n { w[corner] } else { f64::from(u8::from(a == corner)) };
            for i in 0..n {
                let j = (i + 1) % n;
                let (k, m) = triangle([x[i], x[j], xf]).ok_or_else(degenerate)?;
                let fan = [i, j, n];
                for a in 0..3 {
                    for b in 0..3 {
                        let (kv, mv) = (k[a * 3 + b], m[a * 3 + b]);
                        for r in 0..n {
                            let pr = prolong(fan[a], r);
                            if pr == 0.0 {
                                continue;
                            }
                            for c in 0..n {
                                let pc = prolong(fan[b], c);
                                lk[r * n + c] += pr * kv * pc;
                                lm[r * n + c] += pr * mv * pc;
                            }
                        }
                    }
                }
            }
        }
        if mass == Mass::Lumped {
            for r in 0..n {
                let s: f64 = lm[r * n..(r + 1) * n].iter().sum();
                lm[r * n..(r + 1) * n].iter_mut().for_each(|v| *v = 0.0);
                lm[r * n + r] = s;
            }
        }
        for a in 0..n {
            dl[poly[a] as usize] += lk[a * n + a];
            dm[poly[a] as usize] += lm[a * n + a];
            for b in a + 1..n {
                off.push((poly[a], poly[b], [lk[a * n + b], lm[a * n + b]]));
            }
        }
    }
    let (pattern, [stiffness, mass_values]) = assemble(nv, &off, [&dl, &dm]);
    Ok(SparsePair {
        pattern: Arc::new(pattern),
        stiffness,
        mass: mass_values,
        mass_is_diagonal: mass == Mass::Lumped,
        dimension: Some(2),
        kernel: Kernel::CONSTANTS,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_square_gets_its_centre_and_a_regular_polygon_uniform_weights() {
        let sq = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]];
        let w = virtual_weights(&sq);
        assert!(w.iter().all(|&v| (v - 0.25).abs() < 1e-9), "{w:?}");
        let hex: Vec<Point> = (0..6)
            .map(|i| {
                let a = std::f64::consts::PI * i as f64 / 3.0;
                [a.cos(), a.sin(), 0.3]
            })
            .collect();
        let w = virtual_weights(&hex);
        assert!(w.iter().all(|&v| (v - 1.0 / 6.0).abs() < 1e-9), "{w:?}");
    }
}
