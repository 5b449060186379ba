//! Operators out: the `operator` analysis (L and M as upper-triangle triplets the service serves as Matrix Market
//! and SciPy `.npz`, the vertex of each unknown, the property report), and the counting function N(λ) beside
//! Weyl's law that `spectrum` adds on request.

use super::*;
use kac_core::operators::properties;
use kac_core::spectrum::weyl_law::weyl_count;

/// Names of the arrays that are not per-vertex: the matrices (rows: non-zeros of the upper triangle; columns:
/// row, column, value) and the vertex of each unknown (rows: unknowns). They have no coloured PLY.
pub const MATRIX_ARRAYS: &[&str] = &["stiffness", "mass"];
pub const UNKNOWN_ARRAYS: &[&str] = &["unknown_vertices"];

/// Whether an array has one row per vertex of the upload (and so can colour the shape).
/// Arrays with a row per element (triangle or tetrahedron), not per vertex: no coloured PLY for them.
pub const ELEMENT_ARRAYS: &[&str] = &["gradient"];
/// Arrays of a correspondence: per vertex of one of its two shapes (the result's shape is the source), so no
/// coloured PLY of either.
pub const PAIR_ARRAYS: &[&str] = &["source_to_target", "target_to_source", "source_cost", "target_cost", "transferred"];

pub fn is_per_vertex(name: &str) -> bool {
    !MATRIX_ARRAYS.contains(&name)
        && !UNKNOWN_ARRAYS.contains(&name)
        && !ELEMENT_ARRAYS.contains(&name)
        && !PAIR_ARRAYS.contains(&name)
}

/// For each unknown of the operator, its vertex in the upload's numbering (the first input vertex welded into
/// it): the interior map under Dirichlet conditions, and the inverse of validation's renumbering. With P2
/// elements each unknown has two: a vertex unknown its vertex twice, an edge unknown the edge's endpoints.
pub fn unknown_vertices(v: &Validated, op: &Operator) -> Vec<[u32; 2]> {
    let mut first = vec![u32::MAX; v.shape.vertex_count()];
    for (input, &w) in v.vertex_map.iter().enumerate() {
        if w != u32::MAX && first[w as usize] == u32::MAX {
            first[w as usize] = input as u32;
        }
    }
    let mut all: Vec<[u32; 2]> = first.iter().map(|&i| [i, i]).collect();
    if let Some(edges) = &op.edge_unknowns {
        all.extend(edges.iter().map(|e| [first[e[0] as usize], first[e[1] as usize]]));
    }
    match &op.interior {
        Some(keep) => keep.iter().map(|&u| all[u as usize]).collect(),
        None => all,
    }
}

pub(crate) fn operator_output(
    v: &Validated,
    spec: &OperatorSpec,
    report: bool,
    matrices: bool,
    hooks: Hooks<'_>,
) -> Result<Part, AnalysisError> {
    let t = std::time::Instant::now();
    let op = build_operator(v, spec)?;
    let assembly_s = t.elapsed().as_secs_f64();
    let mut summary = OperatorSummary {
        kind: v.shape.kind(),
        vertices: op.full_size,
        unknowns: op.pair.n(),
        nonzeros: op.pair.nnz(),
        mass_is_diagonal: op.pair.mass_is_diagonal,
        sign: "L is positive semidefinite (stiffness); the eigenproblem is L φ = λ M φ",
        timings: AssemblyTimings { assembly_s },
        properties: None,
        matrices: None,
        operator: OperatorUsed::of(&op),
    };
    if report {
        hooks.control.check()?;
        summary.properties = Some(properties::report(&v.shape, &op));
    }
    let mut arrays = vec![];
    if matrices {
        let triplets = |values: &[f64]| kac_core::io::matrix::upper_triplets(&op.pair.pattern, values);
        let (l, m) = (triplets(&op.pair.stiffness), triplets(&op.pair.mass));
        let values = l.len().saturating_add(m.len());
        if values > hooks.limits.max_values {
            return Err(AnalysisError::TooLarge(format!(
                "L and M have {} and {} non-zeros in their upper triangles ({values} values as triplets), above \
                 the limit of {} (--max-output-values)",
                l.len() / 3,
                m.len() / 3,
                hooks.limits.max_values
            )));
        }
        let cols = if op.edge_unknowns.is_some() { 2 } else { 1 };
        let map: Vec<f64> =
            unknown_vertices(v, &op).iter().flat_map(|p| p[..cols].to_vec()).map(|i| i as f64).collect();
        summary.matrices = Some(MatricesInfo {
            numbering: "rows and columns are the operator's unknowns, 0-based; unknown_vertices gives each \
                        unknown's vertex in the upload's numbering (the interior map under Dirichlet conditions; \
                        with order 2 two columns: a vertex twice, or an edge unknown's endpoints)",
            stiffness: MatrixInfo { name: "L", nonzeros_upper: l.len() / 3 },
            mass: MatrixInfo { name: "M", nonzeros_upper: m.len() / 3 },
            triplets: "row, column, value of the upper triangle (row ≤ column), explicit zeros left out",
        });
        for (name, data) in [("stiffness", l), ("mass", m)] {
            arrays.push(VertexArray { name, rows: data.len() / 3, cols: 3, data, columns: None });
        }
        arrays.push(VertexArray { name: "unknown_vertices", rows: map.len() / cols, cols, data: map, columns: None });
    }
    Ok(Part::new(Summary::Operator(summary), arrays))
}

/// N(λ) at each returned eigenvalue (the number of eigenvalues at or below it, counting those a band left out)
/// beside Weyl's law for the shape's measure, with the boundary's second term where the shape has a boundary of
/// known measure and its condition is the shape's own (Neumann or Dirichlet on the whole boundary).
/// Eigenvalues closer than this, relative, are counted as one cluster: far above the solver's error for a
/// converged pair (its relative residual tolerance is 1e-10 by default, the eigenvalue's error about its square),
/// far below any separation a mesh gives two distinct eigenvalues.
pub const CLUSTER_REL: f64 = 1e-8;

pub(crate) fn counting(v: &Validated, e: &Eigen, values: &[f64], spec: &OperatorSpec) -> Counting {
    let offset = e.spectrum.stats.below_band.unwrap_or(0);
    // N(λ_i) counts a cluster together: values within the solver's accuracy of λ_i (relative CLUSTER_REL, with a
    // floor for the zero modes) are one eigenvalue of multiplicity, not a staircase of rounding (K4's triple 4 came
    // back as 3.9999999999999996, 4, 4 and counted 2, 4, 4).
    let scale = values.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    let count: Vec<usize> = values
        .iter()
        .map(|&l| {
            let within = CLUSTER_REL * (l.abs() + 1e-6 * scale);
            offset + values.iter().filter(|&&x| x <= l + within).count()
        })
        .collect();
    let m = measures(v, Some(&e.operator));
    let dimension = (!matches!(v.shape, Shape::Graph(_)) && m.dimension > 0).then_some(m.dimension);
    let measure = dimension.and(m.measure());
    let dirichlet = e.operator.dirichlet();
    let boundary = match (spec.dirichlet_vertices.is_some(), kac_core::geometry::topology::boundary_measure(&v.shape)) {
        (false, Some(b)) if b > 0.0 => Some(b),
        _ => None,
    };
    let weyl: Option<Vec<f64>> = match (dimension, measure) {
        (Some(d), Some(mu)) => {
            Some(values.iter().map(|&l| weyl_count(d, mu, l, boundary.map(|b| (b, dirichlet)))).collect())
        }
        _ => None,
    };
    Counting {
        lambda: values.to_vec(),
        count,
        cluster_tolerance: CLUSTER_REL,
        dimension,
        measure,
        boundary_measure: boundary,
        terms: match (&weyl, boundary) {
            (None, _) if matches!(v.shape, Shape::Graph(_)) => "none: a graph has no Weyl law",
            (None, _) => "none: the operator's intrinsic dimension is above 3 (Weyl's law is written here for 1 to 3)",
            (Some(_), Some(_)) if dirichlet => {
                "two: ω_d|Ω|λ^{d/2}/(2π)^d − ω_{d−1}|∂Ω|λ^{(d−1)/2}/(4(2π)^{d−1}) (Dirichlet)"
            }
            (Some(_), Some(_)) => "two: ω_d|Ω|λ^{d/2}/(2π)^d + ω_{d−1}|∂Ω|λ^{(d−1)/2}/(4(2π)^{d−1}) (Neumann)",
            (Some(_), None) => "one: ω_d|Ω|λ^{d/2}/(2π)^d",
        },
        weyl,
    }
}
