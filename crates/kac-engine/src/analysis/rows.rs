//! Vertex numbering: requests and per-vertex outputs use the uploaded file's numbering; operators work on the
//! validated (welded, possibly Dirichlet-reduced) vertices.

use super::*;

/// Maps input vertex indices to validated ones.
pub(crate) fn map_vertices(v: &Validated, list: &[u32], what: &str) -> Result<Vec<usize>, AnalysisError> {
    list.iter()
        .map(|&i| match v.vertex_map.get(i as usize) {
            Some(&m) if m != u32::MAX => Ok(m as usize),
            Some(_) => Err(AnalysisError::invalid_parameter(format!("{what}: vertex {i} was dropped by validation"))),
            None => Err(AnalysisError::invalid_parameter(format!(
                "{what}: vertex {i} does not exist ({} vertices)",
                v.vertex_map.len()
            ))),
        })
        .collect()
}

/// Spreads an (operator rows × cols) matrix to the input numbering: Dirichlet vertices 0, dropped ones NaN.
pub fn to_input_rows(v: &Validated, op: &Operator, m: faer::MatRef<'_, f64>, name: &'static str) -> VertexArray {
    spread(v, m, name, |col| op.expand(col))
}

/// Spreads a (validated vertices × cols) matrix to the input numbering.
pub fn validated_to_input(v: &Validated, m: faer::MatRef<'_, f64>, name: &'static str) -> VertexArray {
    spread(v, m, name, |col| col.to_vec())
}

pub(crate) fn spread(
    v: &Validated,
    m: faer::MatRef<'_, f64>,
    name: &'static str,
    expand: impl Fn(&[f64]) -> Vec<f64>,
) -> VertexArray {
    let data = v.to_input_rows(m, expand);
    VertexArray { name, rows: v.vertex_map.len(), cols: m.ncols(), data, columns: None }
}

/// Validated vertex indices → rows of the (possibly Dirichlet-condensed) operator.
pub(crate) fn to_operator_rows(op: &Operator, list: &[usize]) -> Result<Vec<usize>, AnalysisError> {
    match &op.interior {
        None => Ok(list.to_vec()),
        Some(keep) => list
            .iter()
            .map(|&i| {
                keep.binary_search(&(i as u32)).map_err(|_| {
                    AnalysisError::invalid_parameter(if op.dirichlet() {
                        format!("vertex {i} is on the Dirichlet boundary")
                    } else {
                        format!("vertex {i} was dropped as an outlier")
                    })
                })
            })
            .collect(),
    }
}

/// Values given at validated vertices → `(operator row, value)` pairs. With P2 elements an edge unknown on the
/// shape's boundary whose two ends are both given gets their mean (the straight edge's interpolant: exact for
/// linear data, O(h²) otherwise), so that a condition given along the boundary holds between its vertices rather
/// than only at them; edges inside the shape stay free, even between two given vertices.
pub(crate) fn fixed_rows(
    shape: &Shape,
    op: &Operator,
    fixed: &[(usize, f64)],
) -> Result<Vec<(usize, f64)>, AnalysisError> {
    let mut unknowns: Vec<(usize, f64)> = fixed.to_vec();
    if let Some(edges) = &op.edge_unknowns {
        let boundary = operators::boundary::boundary_edges(shape);
        let mut given = vec![None; op.full_size];
        for &(i, x) in fixed {
            if let Some(slot) = given.get_mut(i) {
                *slot = Some(x);
            }
        }
        for (e, [a, b]) in edges.iter().enumerate() {
            if let (Some(x), Some(y)) = (given[*a as usize], given[*b as usize]) {
                if boundary.binary_search(&[(*a).min(*b), (*a).max(*b)]).is_ok() {
                    unknowns.push((op.full_size + e, 0.5 * (x + y)));
                }
            }
        }
    }
    let ids: Vec<usize> = unknowns.iter().map(|u| u.0).collect();
    let rows = to_operator_rows(op, &ids)?;
    Ok(rows.into_iter().zip(unknowns.into_iter().map(|u| u.1)).collect())
}

/// A per-vertex function in the input numbering → the validated numbering (welded vertices: the first value).
pub(crate) fn from_input_rows(v: &Validated, f: &[f64], what: &str) -> Result<Vec<f64>, AnalysisError> {
    if f.len() != v.vertex_map.len() {
        return Err(AnalysisError::invalid_parameter(format!(
            "{what}: {} values for {} input vertices",
            f.len(),
            v.vertex_map.len()
        )));
    }
    let mut out = vec![f64::NAN; v.shape.vertex_count()];
    for (i, &m) in v.vertex_map.iter().enumerate() {
        if m != u32::MAX && out[m as usize].is_nan() {
            out[m as usize] = f[i];
        }
    }
    if let Some(i) = out.iter().position(|x| !x.is_finite()) {
        return Err(AnalysisError::invalid_parameter(format!("{what}: vertex {i} has no finite value")));
    }
    Ok(out)
}

kac_core::object_only_serde!(OperatorSpec);

kac_core::object_only_serde!(SolverSpec);

#[cfg(test)]
mod tests {
    use super::*;

    /// With P2 elements and values given on every boundary vertex of a cube, exactly the boundary edges' midpoints
    /// are fixed: the cube's edges hold interior edges whose two ends are on the boundary (a diagonal from one face
    /// to the next), and those stay free.
    #[test]
    fn p2_values_fix_boundary_edges_only() {
        let shape = Shape::TetMesh(kac_core::geometry::generate::unit_cube_tets(6));
        let op = operators::build(&shape, &OperatorOptions { order: 2, ..Default::default() }).unwrap();
        let on_boundary = operators::boundary::boundary_vertices(&shape);
        let given: Vec<(usize, f64)> = (0..on_boundary.len()).filter(|&i| on_boundary[i]).map(|i| (i, 1.0)).collect();
        let rows = fixed_rows(&shape, &op, &given).unwrap();
        let edges = op.edge_unknowns.as_ref().unwrap();
        let both_ends = edges.iter().filter(|e| on_boundary[e[0] as usize] && on_boundary[e[1] as usize]).count();
        let boundary_edges = operators::boundary::boundary_edges(&shape).len();
        assert!(both_ends > boundary_edges, "the cube has interior edges between boundary vertices");
        assert_eq!(rows.len(), given.len() + boundary_edges);
    }
}
