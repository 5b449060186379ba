//! Continuum spectra with error bars: the `spectrum` request's `extrapolate` solves again on uniformly refined
//! copies of the mesh (each triangle into four, each tetrahedron into eight) and extrapolates every eigenvalue
//! (`kac_core::spectrum::extrapolate`), reporting the order it observed. Uniform refinement keeps straight edges
//! straight, so the limit is the spectrum of the domain as meshed: exact for polygons and polyhedra (flat
//! triangle meshes, tet meshes); a curved surface's facets would stay flat, so it is refused there. On flat
//! triangle meshes every level is graded toward the re-entrant corners (`kac_core::geometry::grading`), which
//! restores the nominal order that their singular eigenfunctions take from uniform levels.

use super::*;
use kac_core::geometry::{grading, refine};
use kac_core::spectrum::extrapolate::richardson;

/// The `extrapolation` block: the eigenvalues on the input and on `refinements` uniform refinements, and the
/// extrapolated values with their error estimates and observed orders.
pub(crate) fn extrapolation(
    v: &Validated,
    spec: &OperatorSpec,
    solver: &SolverSpec,
    k: usize,
    refinements: usize,
    grading: bool,
    hooks: Hooks<'_>,
) -> Result<Value, AnalysisError> {
    if !(1..=3).contains(&refinements) {
        return Err(AnalysisError::invalid_parameter(format!("refinements = {refinements}: give 1, 2 or 3")));
    }
    if spec.operator == Some(OperatorKind::Polygon) {
        return Err(AnalysisError::invalid_parameter(
            "extrapolation refines the triangles; the polygon operator's polygons do not refine with them (use cotan)",
        ));
    }
    if spec.dirichlet_vertices.is_some() {
        return Err(AnalysisError::invalid_parameter(
            "extrapolation refines the mesh; give the boundary condition as `boundary`, not as vertices",
        ));
    }
    let (factor, domain) = match &v.shape {
        Shape::TriangleMesh(m) if refine::is_planar(m) => (4usize, "the plane polygon as meshed (uniform refinement keeps its straight edges)"),
        Shape::TetMesh(_) => (8, "the polyhedron as meshed (uniform refinement keeps its flat faces)"),
        Shape::TriangleMesh(_) => {
            return Err(AnalysisError::not_applicable(
                "extrapolation refines the mesh uniformly, which keeps a curved surface's facets flat: the limit \\
                 would be the polyhedron's spectrum, not the surface's; it applies to flat triangle meshes and tet meshes",
            ))
        }
        other => {
            return Err(AnalysisError::not_applicable(format!(
                "extrapolation applies to flat triangle meshes and tet meshes, not a {}",
                other.kind().as_str()
            )))
        }
    };
    let mut options = operator_options(v, spec)?;
    // Refinement splits the straight edges: the input's curved edge nodes would fit its first level only.
    let curved = options.edge_nodes.take().map(|n| n.len());
    // The levels' meshes: uniform refinements of the input, each graded toward the re-entrant corners of a flat
    // domain when asked (the same map on every level, so the size parameter still halves).
    let mut meshes = vec![v.shape.clone()];
    for _ in 0..refinements {
        meshes.push(match meshes.last() {
            Some(Shape::TriangleMesh(m)) => Shape::TriangleMesh(refine::refine_triangles(m)),
            Some(Shape::TetMesh(m)) => Shape::TetMesh(refine::refine_tets(m)),
            _ => unreachable!("checked above"),
        });
    }
    let grading_report = match (&v.shape, grading) {
        (Shape::TriangleMesh(m), true) => match grading::reentrant_corners(m, u32::from(spec.order)) {
            Ok(corners) if corners.is_empty() => json!({ "graded": false, "reason": "no re-entrant corners" }),
            Ok(corners) => {
                let graded: Option<Vec<Shape>> = meshes
                    .iter()
                    .map(|s| match s {
                        Shape::TriangleMesh(m) => grading::grade(m, &corners).map(Shape::TriangleMesh),
                        _ => None,
                    })
                    .collect();
                match graded {
                    Some(g) => {
                        meshes = g;
                        json!({ "graded": true, "corners": corners })
                    }
                    None => json!({
                        "graded": false,
                        "reason": "the grading map would fold a triangle of the input near a corner (too coarse there): \
                                   levels left uniform",
                        "corners": corners,
                    }),
                }
            }
            Err(why) => json!({ "graded": false, "reason": why }),
        },
        (Shape::TriangleMesh(_), false) => json!({ "graded": false, "reason": "grading: false" }),
        _ => json!({ "graded": false, "reason": "tet meshes are refined uniformly (re-entrant edges are not graded)" }),
    };
    // What the finest level holds: its unknowns times the Krylov basis (about 3k columns).
    let coarse = operators::build(&meshes[0], &options)?;
    let finest = coarse.pair.n().saturating_mul(factor.pow(refinements as u32));
    let held = finest.saturating_mul(3 * k + 16);
    if held > hooks.limits.max_values {
        return Err(AnalysisError::TooLarge(format!(
            "{refinements} refinement(s) make about {finest} unknowns, whose eigensolve holds about {held} values, \
             above the limit of {} (--max-output-values); ask for fewer refinements or a coarser mesh",
            hooks.limits.max_values
        )));
    }
    let mut levels = vec![];
    let mut values: Vec<Vec<f64>> = vec![];
    for (level, shape) in meshes.iter().enumerate() {
        hooks.control.check()?;
        let t = std::time::Instant::now();
        let op = if level == 0 { coarse.clone() } else { operators::build(shape, &options)? };
        let s = spectrum::eigs(&op.pair, &solver.eigen_options(k, hooks.threads), None, hooks.control)?;
        levels.push(json!({
            "unknowns": op.pair.n(),
            "eigenvalues": s.values,
            "completeness": s.stats.completeness,
            "seconds": t.elapsed().as_secs_f64(),
        }));
        values.push(s.values);
    }
    let nominal = 2.0 * f64::from(spec.order);
    let e = richardson(&values, nominal);
    Ok(json!({
        "refinements": refinements,
        "domain": domain,
        "nominal_order": nominal,
        "eigenvalues": e.iter().map(|x| x.value).collect::<Vec<_>>(),
        "error_estimate": e.iter().map(|x| x.error_estimate).collect::<Vec<_>>(),
        "observed_order": e.iter().map(|x| x.observed_order).collect::<Vec<_>>(),
        "order_used": e.iter().map(|x| x.order_used).collect::<Vec<_>>(),
        "levels": levels,
        "grading": grading_report,
        "curved_edges_ignored": curved,
        "method": "Richardson extrapolation at the order observed on the last three levels (mesh sizes h, h/2, h/4), \\
                   clamped to [0.5, 2 × nominal]; the nominal order with two levels or where the differences do not \\
                   shrink monotonically. error_estimate: the larger of the gap to the extrapolation at the nominal \\
                   order and a tenth of the correction",
    }))
}
