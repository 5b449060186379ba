//! Gradient and divergence of P1 finite elements (the chapter's Prop. 9.2 and Def. 9.1): the gradient of a
//! per-vertex function is constant on each triangle or tetrahedron, ∇u|_f = Σ_i u_i ∇φ_i; the divergence of a
//! per-element vector field is taken in the weak (integrated) form the Laplacian uses,
//! (div X)_i = −∫ X·∇φ_i = −Σ_f |f| X_f·∇φ_i, so that div ∇u = −L u exactly (L the cotan / tet stiffness,
//! Δ = −∇·∇ positive semidefinite). Dividing by the lumped mass gives the pointwise divergence.
//!
//! Hat-function gradients: on a triangle, ∇φ_i = N × e_i / (2A) with e_i the edge opposite corner i (counter-
//! clockwise) and N the unit normal; on a tetrahedron, ∇φ_i = −n_i / (3V)·|F_i| with n_i the outward unit normal
//! of the face opposite corner i and |F_i| its area, i.e. the area vector of that face over 3V pointing inward.

use super::PdeError;
use crate::geometry::{vec3, Point, Shape};

/// One element: its corners, the gradients of their hat functions on it, and its measure (area or volume).
type Element = (Vec<usize>, Vec<Point>, f64);

/// The element gradients of the hat functions, and each element's measure (area or volume); `None` for a
/// degenerate element (zero measure), which then contributes nothing.
fn hat_gradients(shape: &Shape) -> Result<Vec<Option<Element>>, PdeError> {
    match shape {
        Shape::TriangleMesh(m) => Ok(m
            .faces
            .iter()
            .map(|t| {
                let p = [m.vertices[t[0] as usize], m.vertices[t[1] as usize], m.vertices[t[2] as usize]];
                let nrm = vec3::cross(vec3::sub(p[1], p[0]), vec3::sub(p[2], p[0]));
                let a2 = vec3::norm(nrm);
                if !(a2 > 0.0) {
                    return None;
                }
                let nu = vec3::scale(nrm, 1.0 / a2);
                let g = (0..3)
                    .map(|i| vec3::scale(vec3::cross(nu, vec3::sub(p[(i + 2) % 3], p[(i + 1) % 3])), 1.0 / a2))
                    .collect();
                Some((t.iter().map(|&i| i as usize).collect(), g, 0.5 * a2))
            })
            .collect()),
        Shape::TetMesh(m) => Ok(m
            .tets
            .iter()
            .map(|t| {
                let p: Vec<Point> = t.iter().map(|&i| m.vertices[i as usize]).collect();
                let (e1, e2, e3) = (vec3::sub(p[1], p[0]), vec3::sub(p[2], p[0]), vec3::sub(p[3], p[0]));
                let six_v = vec3::dot(e1, vec3::cross(e2, e3));
                if six_v == 0.0 || !six_v.is_finite() {
                    return None;
                }
                // ∇φ_i solves ∇φ_i · (p_j − p_i) = δ_ij − 0; the rows of the inverse edge matrix give them for
                // corners 1..3, and ∇φ_0 = −Σ the others.
                let g1 = vec3::scale(vec3::cross(e2, e3), 1.0 / six_v);
                let g2 = vec3::scale(vec3::cross(e3, e1), 1.0 / six_v);
                let g3 = vec3::scale(vec3::cross(e1, e2), 1.0 / six_v);
                let g0 = vec3::scale(vec3::add(vec3::add(g1, g2), g3), -1.0);
                Some((t.iter().map(|&i| i as usize).collect(), vec![g0, g1, g2, g3], six_v.abs() / 6.0))
            })
            .collect()),
        other => Err(PdeError::NotApplicable {
            message: format!(
                "gradient and divergence are taken on triangle and tet meshes' elements, not a {}",
                other.kind().as_str()
            ),
        }),
    }
}

/// The gradient of a per-vertex function on each element (triangle or tetrahedron): one 3-vector per element,
/// in the element order of the mesh; NaN for a degenerate element.
pub fn gradient(shape: &Shape, u: &[f64]) -> Result<Vec<Point>, PdeError> {
    let n = shape.vertex_count();
    if u.len() != n {
        return Err(PdeError::param("function", format!("{} values for {n} vertices", u.len())));
    }
    Ok(hat_gradients(shape)?
        .into_iter()
        .map(|e| match e {
            Some((corners, g, _)) => {
                corners.iter().zip(&g).fold([0.0; 3], |acc, (&i, gi)| vec3::add(acc, vec3::scale(*gi, u[i])))
            }
            None => [f64::NAN; 3],
        })
        .collect())
}

/// The integrated divergence of a per-element vector field, per vertex: (div X)_i = −Σ_f |f| X_f·∇φ_i (see the
/// module's documentation); elements with a non-finite vector are refused.
pub fn divergence(shape: &Shape, field: &[Point]) -> Result<Vec<f64>, PdeError> {
    let elements = hat_gradients(shape)?;
    if field.len() != elements.len() {
        return Err(PdeError::param(
            "field",
            format!("{} vectors for {} elements (one per triangle or tetrahedron)", field.len(), elements.len()),
        ));
    }
    if let Some(f) = field.iter().position(|x| x.iter().any(|c| !c.is_finite())) {
        return Err(PdeError::param("field", format!("element {f}'s vector is not finite")));
    }
    let mut div = vec![0.0; shape.vertex_count()];
    for (e, x) in elements.iter().zip(field) {
        if let Some((corners, g, measure)) = e {
            for (&i, gi) in corners.iter().zip(g) {
                div[i] -= measure * vec3::dot(*x, *gi);
            }
        }
    }
    Ok(div)
}
