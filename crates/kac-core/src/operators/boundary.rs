//! Dirichlet boundary conditions by elimination: the rows and columns of boundary vertices are removed from L
//! and M (the principal submatrix on interior vertices), never replaced by identity rows, which would add
//! spurious eigenvalues. The kept indices let vectors be put back with zeros on the boundary.

use super::sparse::{submatrix, Kernel, SparsePair};
use super::{Boundary, OperatorError};
use crate::geometry::{topology, Shape};
use std::sync::Arc;

/// Boundary vertices of a shape: mesh boundary loops, tet boundary faces, polyline ends; none for clouds and
/// graphs (give vertices explicitly).
pub fn boundary_vertices(shape: &Shape) -> Vec<bool> {
    match shape {
        Shape::TriangleMesh(m) => topology::boundary_vertices(m),
        Shape::TetMesh(m) => {
            let (faces, _) = topology::tet_boundary(&m.tets);
            let mut b = vec![false; m.vertices.len()];
            faces.iter().flatten().for_each(|&v| b[v as usize] = true);
            b
        }
        Shape::Polyline(p) => {
            let mut deg = vec![0u32; p.vertices.len()];
            for s in &p.segments {
                deg[s[0] as usize] += 1;
                deg[s[1] as usize] += 1;
            }
            deg.iter().map(|&d| d == 1).collect()
        }
        _ => vec![false; shape.vertex_count()],
    }
}

/// The edges on a shape's boundary, each as [low, high], sorted: a surface's edges of one triangle, the edges of
/// a solid's boundary faces; none on other shapes.
pub fn boundary_edges(shape: &Shape) -> Vec<[u32; 2]> {
    match shape {
        Shape::TriangleMesh(m) => {
            let topo = topology::EdgeTopology::new(&m.faces);
            let mut b: Vec<[u32; 2]> = topo
                .edges
                .iter()
                .enumerate()
                .filter(|&(e, _)| topo.valence(e) == 1)
                .map(|(_, &e)| [e[0].min(e[1]), e[0].max(e[1])])
                .collect();
            b.sort_unstable();
            b
        }
        // The edges of the boundary faces.
        Shape::TetMesh(m) => topology::triangle_edges(&topology::tet_boundary(&m.tets).0),
        _ => vec![],
    }
}

pub fn apply(
    shape: &Shape,
    pair: SparsePair,
    boundary: &Boundary,
) -> Result<(SparsePair, Option<Vec<u32>>), OperatorError> {
    match fixed_vertices(shape, pair.n(), boundary)? {
        None => Ok((pair, None)),
        Some(fixed) => eliminate(pair, &fixed),
    }
}

/// The P2 version of [`apply`]: besides the vertices, the edge unknowns (after the `n_vertices` vertex ones,
/// `edges` their endpoints) of boundary edges (a surface's boundary edges, edges on a solid's boundary faces), or
/// with given vertices, of edges between two of them.
pub fn apply_p2(
    shape: &Shape,
    pair: SparsePair,
    edges: &[[u32; 2]],
    boundary: &Boundary,
) -> Result<(SparsePair, Option<Vec<u32>>), OperatorError> {
    let nv = shape.vertex_count();
    let Some(mut fixed) = fixed_vertices(shape, nv, boundary)? else { return Ok((pair, None)) };
    let on_boundary: Vec<[u32; 2]> = match boundary {
        Boundary::DirichletVertices(_) => {
            edges.iter().copied().filter(|e| fixed[e[0] as usize] && fixed[e[1] as usize]).collect()
        }
        _ => boundary_edges(shape),
    };
    fixed.resize(nv + edges.len(), false);
    for e in on_boundary {
        if let Ok(k) = edges.binary_search(&e) {
            fixed[nv + k] = true;
        }
    }
    eliminate(pair, &fixed)
}

/// The vertices a boundary condition fixes (`None`: Neumann, nothing fixed).
fn fixed_vertices(shape: &Shape, n: usize, boundary: &Boundary) -> Result<Option<Vec<bool>>, OperatorError> {
    let fixed: Vec<bool> = match boundary {
        Boundary::Neumann => return Ok(None),
        Boundary::Dirichlet => {
            let b = boundary_vertices(shape);
            if !b.iter().any(|&x| x) {
                return Err(OperatorError::Boundary {
                    message: format!("the {} has no boundary; give the vertices to fix", shape.kind().as_str()),
                });
            }
            b
        }
        Boundary::DirichletVertices(list) => {
            let mut b = vec![false; n];
            for &v in list {
                if v as usize >= n {
                    return Err(OperatorError::Boundary {
                        message: format!("vertex {v} does not exist (the shape has {n})"),
                    });
                }
                b[v as usize] = true;
            }
            b
        }
    };
    Ok(Some(fixed))
}

/// The principal submatrix on the unknowns not `fixed`, with the kept indices.
pub fn eliminate(pair: SparsePair, fixed: &[bool]) -> Result<(SparsePair, Option<Vec<u32>>), OperatorError> {
    let n = pair.n();
    let keep: Vec<usize> = (0..n).filter(|&i| !fixed[i]).collect();
    if keep.is_empty() {
        return Err(OperatorError::Boundary { message: "every vertex is on the boundary; nothing is left".into() });
    }
    let (pattern, mut vals) = submatrix(&pair.pattern, &[&pair.stiffness, &pair.mass], &keep);
    let mass = vals.pop().unwrap_or_default();
    let stiffness = vals.pop().unwrap_or_default();
    // A kept vertex coupled to an eliminated one is anchored: its component's constant (weighted) vector is no
    // longer in the kernel, the part of it that was on the boundary being held at zero.
    let kernel = match &pair.kernel {
        Kernel::Unknown => Kernel::Unknown,
        Kernel::Components { weights, anchored } => {
            let p = &pair.pattern;
            let anchored_by = |j: usize| {
                anchored.as_ref().is_some_and(|a| a[j])
                    || (p.col_ptr[j]..p.col_ptr[j + 1]).any(|pos| fixed[p.row_idx[pos]] && pair.stiffness[pos] != 0.0)
            };
            Kernel::Components {
                weights: weights.as_ref().map(|w| Arc::new(keep.iter().map(|&i| w[i]).collect())),
                anchored: Some(Arc::new(keep.iter().map(|&j| anchored_by(j)).collect())),
            }
        }
    };
    let kept = keep.iter().map(|&i| i as u32).collect();
    Ok((
        SparsePair {
            pattern: Arc::new(pattern),
            stiffness,
            mass,
            mass_is_diagonal: pair.mass_is_diagonal,
            dimension: pair.dimension,
            kernel,
        },
        Some(kept),
    ))
}
