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

/// Values given at validated vertices → `(operator row, value)` pairs. With P2 elements an edge unknown whose two
/// ends are both given gets their mean (the straight edge's interpolant: exact for linear data, O(h²) otherwise),
/// so that a condition given at vertices holds along the edges between them rather than only at their ends.
pub(crate) fn fixed_rows(op: &Operator, fixed: &[(usize, f64)]) -> Result<Vec<(usize, f64)>, AnalysisError> {
    let mut unknowns: Vec<(usize, f64)> = fixed.to_vec();
    if let Some(edges) = &op.edge_unknowns {
        let mut given = vec![None; op.full_size];
        for &(i, x) in fixed {
            if let Some(slot) = given.get_mut(i) {
                *slot = Some(x);
            }
        }
        for (e, [a, b]) in edges.iter().enumerate() {
            if let (Some(x), Some(y)) = (given[*a as usize], given[*b as usize]) {
                unknowns.push((op.full_size + e, 0.5 * (x + y)));
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
